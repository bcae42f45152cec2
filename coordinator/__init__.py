"""The coordinator: simulated time, the world, tasks, faults and metrics."""
