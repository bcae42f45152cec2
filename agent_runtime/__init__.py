"""Agent processes: a behavior tree and an allocator plugin per agent, one OS process each."""
