"""The launcher's side: everything a user runs, in four rooms, and the experiment files as data.

- ``launch/``: one run (loading and checking its file, the runner, child processes and the fork
  server, identities and access rules, certificates, provenance)
- ``hosts/``: the host daemon role and its clients; stand-in hosts of network namespaces
- ``campaigns/``: many runs (sweeps, their claims and executors; soak tests and chaos)
- ``views/``: reading results (analysis, statistics, reports, replay, watch)
- ``cli.py``: the ``swarmbed`` command

The experiment schema itself lives below every process, in ``swarmbed.wire.schema``; the YAML files
(``quickstart.yaml``, ``space_*.yaml``, ``sar/``, ``soak/``) are package data.
"""
