"""Running one experiment: loading and checking its file (YAML read as hostile input), the runner, the
child processes and the agents' fork server, the run's identities and access rules, certificates
and the record of which code made a result.
"""
