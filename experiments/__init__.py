"""Experiment files and maps, shipped as package data: ``quickstart.yaml``, ``space_*.yaml``,
``sar/``, ``soak/``, ``radio/``, ``walls/``. No code: ``swarmbed run experiments/<file>.yaml`` runs one
(the command is ``swarmbed.cli``)."""
