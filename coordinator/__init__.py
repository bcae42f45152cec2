"""The coordinator role: the Zenoh transport of the engine's tick loop (``zenoh_transport.py``) and the
hooks it adds to a run over processes: the wall clock, the agents' lives (swaps, restarts,
checkpoints), live status, the recorder of the agents' trees, ROS 2 topics. The world and its tasks
live in ``swarmbed.scenarios``, the tick itself in ``swarmbed.engine``."""
