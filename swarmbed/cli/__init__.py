"""The ``swarmbed`` command: :mod:`swarmbed.cli.main` parses the verbs and hands each to the package
that does it (``launch`` for one run, ``campaigns`` for many, ``hosts``, ``results``, ``checks``)."""
