"""The host daemon role (``swarmbed host``: a machine's router that starts agents for runs), and
stand-in hosts made of network namespaces for tests and benchmarks. Its clients (the launcher, ``swarmbed
hosts``) use ``swarmbed.launch.host_client``: hosts use the launcher's parts, never the reverse.
"""
