"""The host daemon role (``swarmbed host``: a machine's router that starts agents for runs) and its
clients, and stand-in hosts made of network namespaces for tests and benchmarks.
"""
