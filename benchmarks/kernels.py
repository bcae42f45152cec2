"""The compiled kernels against the Python they replace, on the calls of a real run.

    python benchmarks/kernels.py                 # CBBA, 50 robots, 600 simulated s of MT-SR
    python benchmarks/kernels.py --agents 200 --duration 300

Runs one CBBA run of ``experiments/space_mtsr_code.yaml`` on the in-process engine and records what
its robots asked: every marginal-gain call (``swarmbed.kernels.path_gains``) and the first
``--receives`` consensus receives (each with the receiver's state before it). Then replays them,
interleaved round by round, through each way of computing them, and prints CPU microseconds per call
and each way's ratio to the compiled one measured in the same run:

- gains: the compiled kernel, its Python reference (what runs where no C compiler was found), and
  the numpy code the kernel replaced (numpy's exp and hypot: other bits on other CPUs);
- receive: compiled (the task part of a receive in C), Table 1 alone compiled (from 8 differing
  tasks), numpy masks (from 24, as without the kernels), and task by task in Python.

CPU time of this process only: the figures do not move with other work on the machine as much as
wall time would, but an idle machine gives the cleanest ones.
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from swarmbed import config as cfg
from swarmbed import kernels
from swarmbed.kernels import reference
from swarmbed.launch.inprocess import run_in_process
from swarmbed.plugins import consensus
from swarmbed.plugins.consensus import ConsensusState

ROOT = Path(__file__).resolve().parent.parent


def numpy_gains(x0, y0, v, rate, log_l, cx, cy, cr, px, py, pr, at_end):
    """The marginal gains as plugins/cbba.py computed them before the kernel (numpy's exp and hypot)."""
    nx, ny = np.concatenate([[x0], px]), np.concatenate([[y0], py])
    seg = np.hypot(np.diff(nx), np.diff(ny))
    work = pr / rate
    arrive = np.concatenate([[0.0], np.cumsum(seg / v + work) - work])
    finish = np.concatenate([[0.0], arrive[1:] + work])
    disc = np.exp(log_l * arrive[1:]) * pr
    suffix = np.concatenate([np.cumsum(disc[::-1])[::-1], [0.0]])
    d = np.hypot(cx[:, None] - nx[None, :], cy[:, None] - ny[None, :])
    tau = finish[None, :] + d / v
    delay = np.zeros_like(d)
    if len(pr):
        delay[:, :-1] = (d[:, :-1] + d[:, 1:] - seg[None, :]) / v + (cr / rate)[:, None]
    gain = np.exp(log_l * tau) * cr[:, None] + (np.exp(log_l * delay) - 1.0) * suffix[None, :]
    best, where = gain.max(axis=1), gain.argmax(axis=1)
    last = at_end.astype(bool)
    best[last], where[last] = gain[last, -1], len(pr)
    return best, where


def record(agents: int, duration: float, receives: int) -> tuple[list, list]:
    gains, received = [], []
    path_gains, receive = kernels.path_gains, ConsensusState.receive

    def recording_gains(*args):
        gains.append(tuple(np.copy(a) if isinstance(a, np.ndarray) else a for a in args))
        return path_gains(*args)

    def recording_receive(self, sender, data, ignore=(), within=None):
        if len(received) < receives:
            before = (self.agent_id, self.now, dict(self.z), dict(self.y), self.stamps.copy())
            received.append((before, sender, data, frozenset(ignore), within))
        return receive(self, sender, data, ignore, within)

    kernels.path_gains, ConsensusState.receive = recording_gains, recording_receive
    try:
        exp = cfg.load(
            ROOT / "experiments" / "space_mtsr_code.yaml",
            ["allocator.name=cbba", f"agents.count={agents}", f"run.duration={duration}"],
        )
        with tempfile.TemporaryDirectory() as tmp:
            run_in_process(exp, Path(tmp) / "run")
    finally:
        kernels.path_gains, ConsensusState.receive = path_gains, receive
    return gains, received


def time_gains(calls: list, fn) -> float:
    t = time.process_time()
    for args in calls:
        fn(*args)
    return (time.process_time() - t) / len(calls) * 1e6


def time_receives(calls: list, few: float, receive) -> float:
    spent = 0.0
    consensus.FEW_TASKS, kernels.receive = few, receive
    for (agent, now, z, y, stamps), sender, data, ignore, within in calls:
        st = ConsensusState(agent)
        st.now, st.z, st.y, st.stamps = now, dict(z), dict(y), stamps.copy()
        t = time.process_time()
        st.receive(sender, data, ignore, within)
        spent += time.process_time() - t
    return spent / len(calls) * 1e6


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--agents", type=int, default=50)
    ap.add_argument("--duration", type=float, default=600.0)
    ap.add_argument("--receives", type=int, default=20_000)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    if not kernels.COMPILED:
        raise SystemExit("the compiled kernels were not built: nothing to compare")
    gains, received = record(args.agents, args.duration, args.receives)
    print(f"recorded {len(gains)} gain calls, {len(received)} receives ({args.agents} robots, {args.duration:g} s)")
    compiled_receive, few = kernels.receive, consensus.FEW_TASKS
    ways_gains = {"compiled": kernels.path_gains, "python reference": reference.path_gains, "numpy before": numpy_gains}
    ways_receive = {
        "compiled": (few, compiled_receive),
        "numpy masks": (few, None),
        "task by task": (math.inf, None),
    }
    spent: dict[str, list[float]] = {}
    try:
        for _ in range(args.rounds):
            for name, fn in ways_gains.items():
                spent.setdefault(f"gains, {name}", []).append(time_gains(gains, fn))
            for name, (threshold, receive) in ways_receive.items():
                spent.setdefault(f"receive, {name}", []).append(time_receives(received, threshold, receive))
    finally:
        consensus.FEW_TASKS, kernels.receive = few, compiled_receive
    floors = {"gains": min(spent["gains, compiled"]), "receive": min(spent["receive, compiled"])}
    for name, values in spent.items():
        best = min(values)
        print(f"{name:<28} {best:8.1f} us a call (best of {len(values)})   x{best / floors[name.split(',')[0]]:.2f}")


if __name__ == "__main__":
    main()
