"""Reading results: analysis and statistics of sweeps, HTML reports, replays, the live ``watch`` view
and the colours they share.
"""
