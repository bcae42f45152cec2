"""Many runs: Monte Carlo sweeps (their claims and executors: local pool, Slurm, Dask) and soak tests
with injected faults.
"""
