"""Reading results, never making them: the files of sweep and soak folders (``campaign_folders``),
analysis and statistics of sweeps, HTML reports, replays and recordings, the live ``watch`` and
Foxglove views, the Groot2 gateway, and the colours they share. A run folder is read through
``swarmbed.records.run_folder.RunDir``.
"""
