"""One agent-tick, warm, stage by stage: the agent's Python alone, with no process and no Zenoh.

    python benchmarks/agent_tick.py             # no-op allocator messaging 5 peers, N = 50
    python benchmarks/agent_tick.py --profile   # and cProfile's top functions

Builds the lock-step benchmark's agent 0 (``benchmarks/lockstep.py``'s case), makes the tick sample
the hub would send it (an observation and an inbox with its five neighbours' messages) and times
decoding it, stepping the agent and encoding its answer, 20,000 times each. A live agent wakes with
cold caches and pays several times these figures (docs/benchmarks.md, "the tick diet, second
cut"); use this to see what a change to the agent's Python costs before measuring it live with
``benchmarks/profile_tick.py`` and ``benchmarks/lockstep.py``.
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time
from collections.abc import Callable
from pathlib import Path

from swarmbed import config as cfg
from swarmbed.agent_runtime.runtime import AgentRuntime
from swarmbed.config import resolve_experiment
from swarmbed.schema.experiment import agent_spec
from swarmbed.wire.codec import EMPTY_INBOX, encode_agent_out, encode_inbox, encode_tick
from swarmbed.wire.observation import empty_tasks
from swarmbed.wire.tickdecode import TickDecoder

ROOT = Path(__file__).resolve().parent.parent
TIMES = 20_000


def _timed(name: str, fn: Callable[[], object]) -> None:
    fn()
    start = time.perf_counter()
    for _ in range(TIMES):
        fn()
    print(f"  {name:<24} {1e6 * (time.perf_counter() - start) / TIMES:7.2f} us")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=50)
    ap.add_argument("--profile", action="store_true", help="cProfile the whole tick, top 25 functions")
    args = ap.parse_args()
    exp = cfg.load(
        ROOT / "experiments" / "quickstart.yaml",
        [f"agents.count={args.n}", "allocator={name: noop, peers: 5}", "scenario.initial_tasks=0"],
    )
    spec = agent_spec(exp, resolve_experiment(exp).targets)
    runtime = AgentRuntime(spec, 0)
    obs_cls = runtime.scenario.Observation
    obs = obs_cls(1.0, 10.0, 20.0, 0.5, 1.0, empty_tasks())
    heard = []  # what the five agents before agent 0 send it
    for sender in range(args.n - 5, args.n):
        _, messages, _ = AgentRuntime(spec, sender).step(0, obs, EMPTY_INBOX)
        heard += [[sender, m.kind, m.payload] for m in messages]
    sample = encode_tick(5, obs.to_wire(), encode_inbox(heard))
    decoder = TickDecoder(obs_cls)
    tick = decoder.decode(sample)
    action, messages, events = runtime.step(tick.tick, tick.obs, tick.inbox)

    def whole() -> None:
        msg = decoder.decode(sample)
        a, m, e = runtime.step(msg.tick, msg.obs, msg.inbox, msg.decision)
        encode_agent_out(msg.tick, 0, a, m, e)

    print(f"agent 0 of {args.n}, a {len(sample)}-byte tick sample with {len(heard)} messages; per call:")
    _timed("decode the tick sample", lambda: decoder.decode(sample))
    _timed("the inbox", lambda: runtime._inbox(tick.inbox))
    _timed("step (view, tree, plugin)", lambda: runtime.step(tick.tick, tick.obs, tick.inbox))
    _timed("encode the answer", lambda: encode_agent_out(5, 0, action, messages, events))
    _timed("the whole tick", whole)
    if args.profile:
        profile = cProfile.Profile()
        profile.runcall(lambda: [whole() for _ in range(TIMES)])
        pstats.Stats(profile).sort_stats("tottime").print_stats(25)


if __name__ == "__main__":
    main()
