"""Reading results, never making them: a run folder as its readers see it (``run_folder``), the files
of sweep and soak folders (``folders``), analysis and statistics of sweeps, HTML reports, replays and
recordings, the live ``watch`` and Foxglove views, the Groot2 gateway, and the colours they share.
"""
