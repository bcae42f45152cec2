"""Running one resolved experiment (``swarmbed.config`` resolves it): the plan, the runner, the
in-process engine, the child processes and the agents' fork server, the run's identities and access
rules, certificates and the record of which code made a result.
"""
