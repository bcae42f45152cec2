"""Conformance kit for allocators, like PettingZoo's ``api_test`` / ``seed_test``.

It runs allocators in-process on static instances: agents stand still, every round each agent
decides with what it sees and what reached it, and its messages go through the radio exactly as a
run's do (:class:`~swarmbed.netem.exchange.Exchange`, the proxy's and the in-process engine's
step, with its ledger and its seed stream), so loss, rate caps and queue limits behave as in a run.
Check any allocator, a user's own included:

    swarmbed check-allocator fcg
    swarmbed check-allocator my_algo.py:MyAllocator --set alpha=0.3

Generic checks: determinism (same seed, same decisions and message bytes), messages serializable
and bounded, keeps working under 30 % loss and under a tight rate cap, never keeps an agent on
a task that no longer exists, and runs (as deterministically) where every task needs a team.
"""

from __future__ import annotations

import dataclasses
import math
import tempfile
import types
import typing
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from swarmbed.extension import HALT, HOLD, Allocator, LocalView, Message, TaskInfo
from swarmbed.netem import Radio
from swarmbed.netem.exchange import Exchange
from swarmbed.plugins.registry import make, resolve, resolve_scenario
from swarmbed.schema.experiment import NetemSpec, NetworkSection
from swarmbed.wire.codec import TASK_DTYPE, AgentOut, WorldSample, delivered_in, unpack
from swarmbed.wire.observation import Observation
from swarmbed.wire.state import pack_state, unpack_state

DEFAULT_MAX_BYTES = 64 * 1024
CLEAN_NETWORK = NetworkSection()


class ConformanceError(AssertionError):
    """An allocator broke a rule of the kit; the message says which and how."""


@dataclass
class Instance:
    agents: list[tuple[float, float]]
    tasks: dict[int, tuple[float, float, float]]  # id -> (x, y, workload or lifetime)
    max_speed: float = 1.0
    work_rate: float = 1.0
    awareness_range: float = math.inf
    task_colors: dict[int, int] | None = None  # a task's colour where it has one (the table's color column)
    #: what else a standing agent's observation says, for scenarios whose observation has more
    #: fields than the generic ones: at every round (search and rescue: its reach, nothing inspected
    #: or rescued; MT-SR team tasks: ``coalitions``), per agent (search and rescue: its colour) and
    #: at the first round only (search and rescue: every robot's start, ``team``)
    observed: dict[str, Any] = field(default_factory=dict)
    observed_by_agent: list[dict[str, Any]] | None = None
    observed_first: dict[str, Any] = field(default_factory=dict)


def random_instance(
    seed: int,
    n_agents: int,
    n_tasks: int,
    size: float = 100.0,
    workload: tuple[float, float] = (6.0, 60.0),
    scenario: str = "mtsr",
) -> Instance:
    rng = np.random.default_rng(seed)
    agents = [(float(x), float(y)) for x, y in rng.uniform(0, size, (n_agents, 2))]
    tasks = {
        j: (float(x), float(y), float(w))
        for j, (x, y, w) in enumerate(
            zip(rng.uniform(0, size, n_tasks), rng.uniform(0, size, n_tasks), rng.uniform(*workload, n_tasks))
        )
    }
    if scenario != "sar":
        return Instance(agents, tasks)
    return Instance(
        agents,
        tasks,
        task_colors={j: int(rng.integers(3)) for j in tasks},
        observed={"reach": 5.0, "robots": [], "inspected": [], "rescued": [], "busy": 0},
        observed_by_agent=[{"color": i % 3} for i in range(n_agents)],
        observed_first={"team": [(i, x, y) for i, (x, y) in enumerate(agents)]},
    )


@dataclass
class Trace:
    allocators: list[Allocator]
    decisions: list[dict[int, int | None]] = field(default_factory=list)  # per round
    messages: list[list[tuple[int, str, bytes]]] = field(default_factory=list)  # per round
    radio: Radio | None = None  # the radio the rounds went through (its ledger: every copy's fate)


def empty_value(hint: Any) -> Any:
    """The empty value of a declared observation field's type (0, 0.0, False, "", [], (), {}, None
    for an optional one, a zero-length array, a fixed-length tuple of empties); a TypeError for a
    type the kit cannot make."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint is type(None) or (origin in (typing.Union, types.UnionType) and type(None) in args):
        return None
    if origin is tuple:
        return () if not args or args[-1] is Ellipsis else tuple(empty_value(a) for a in args)
    for kind, value in ((list, list), (dict, dict), (set, set), (frozenset, frozenset)):
        if origin is kind or hint is kind:
            return value()
    if hint is np.ndarray or origin is np.ndarray:
        return np.zeros(0)
    if hint in (bool, int, float, str, bytes):
        return hint()
    raise TypeError(f"no empty value of {hint}")


def _observation(
    cls: type[Observation], k: int, x: float, y: float, visible: dict[int, TaskInfo], known: dict[str, Any]
) -> Observation:
    """The scenario's observation of a standing agent; extra fields from ``known``, those the
    scenario leaves optional as None."""
    table = np.array([(t.id, t.x, t.y, t.remaining, t.color) for t in visible.values()], dtype=TASK_DTYPE)
    extras, missing = {}, []
    defaulted = {f.name for f in dataclasses.fields(cls) if f.default is not dataclasses.MISSING}
    defaulted |= {f.name for f in dataclasses.fields(cls) if f.default_factory is not dataclasses.MISSING}
    for field_name, hint in cls.extra_fields():
        if field_name in known:
            extras[field_name] = known[field_name]
        elif field_name not in defaulted:
            try:  # what the scenario declares, empty: an agent that has seen nothing of that kind yet
                extras[field_name] = empty_value(hint)
            except TypeError:
                missing.append(f"{field_name}: {hint}")
    if missing:
        raise ConformanceError(
            f"the kit cannot fill the observation fields {missing} of {cls.__name__}: give them defaults"
        )
    return cls(float(k), x, y, 0.0, 0.0, table, **extras)


def simulate(
    name: str,
    params: Mapping[str, Any],
    inst: Instance,
    rounds: int,
    seed: int = 0,
    network: NetworkSection = CLEAN_NETWORK,
    remove_at: Mapping[int, list[int]] | None = None,
    max_bytes: int = DEFAULT_MAX_BYTES,
    scenario: str | None = None,
    move_at: Sequence[int] = (),
) -> Trace:
    """Run ``rounds`` rounds. ``remove_at[k]``: tasks that disappear (are done) before round k.
    Each round every agent is shown its view (``observe``, then ``decide``), as in a run, and what
    it sent goes through the radio's :class:`~swarmbed.netem.exchange.Exchange` (seeded from
    ``seed`` as a run's radio is, its ledger balanced at the end)."""
    n = len(inst.agents)
    seeds = np.random.SeedSequence(seed).spawn(n)
    trace = Trace([make(name, params, i, np.random.default_rng(seeds[i]), seed, scenario) for i in range(n)])
    ids = list(range(n))
    xs, ys = [a[0] for a in inst.agents], [a[1] for a in inst.agents]
    tasks = dict(inst.tasks)
    inboxes: dict[int, bytes] = {}
    kinds = set(type(trace.allocators[0]).message_kinds)
    obs_cls = resolve_scenario(scenario).Observation if scenario else Observation
    declared = _declared_fields(scenario, n, seed) if scenario else [{} for _ in ids]
    with tempfile.TemporaryDirectory(prefix="swarmbed-kit-") as ledger_dir:
        exchange = Exchange(NetemSpec(seed=seed, dt=1.0, agents=n, network=network), Path(ledger_dir))
        trace.radio = exchange.radio
        for k in range(rounds):
            if k in move_at:  # every agent moves to a fresh instance through a snapshot, as a swap does
                trace.allocators = [_moved(a, name, params, i, seed, scenario) for i, a in enumerate(trace.allocators)]
            for t in (remove_at or {}).get(k, ()):
                tasks.pop(t, None)
            exchange.radio.confirm()  # the inboxes made for this round arrived
            outs, decisions, sent = {}, {}, []
            for i in ids:
                inbox = [Message(d.sender, d.kind, unpack(d.payload)) for d in delivered_in(inboxes.get(i))]
                view = _view(inst, obs_cls, tasks, i, k, inbox, declared[i])
                trace.allocators[i].observe(view)
                decision = trace.allocators[i].decide(view)
                if decision is not None and decision not in (HOLD, HALT) and decision not in tasks:
                    raise ConformanceError(
                        f"{name}: agent {i} chose task {decision!r} at round {k}, which does not exist"
                    )
                decisions[i] = decision
                encoded = [o.encode() for o in view.outbox]
                for m in encoded:
                    if len(m.payload) > max_bytes:
                        raise ConformanceError(
                            f"{name}: agent {i} sent a {len(m.payload)}-byte {m.kind!r} message "
                            f"at round {k} (limit {max_bytes})"
                        )
                    if kinds and m.kind not in kinds:
                        raise ConformanceError(f"{name}: message kind {m.kind!r} not in message_kinds {sorted(kinds)}")
                    unpack(m.payload)  # serializable both ways
                    sent.append((i, m.kind, m.payload))
                outs[i] = AgentOut(k, i, [], encoded, {})
            inboxes = exchange.route(WorldSample(k, ids, xs, ys, ids, {}), outs).inboxes
            trace.decisions.append(decisions)
            trace.messages.append(sent)
        exchange.finish(rounds - 1, malformed=0)
    return trace


def _declared_fields(scenario: str, n: int, seed: int) -> list[dict[str, Any]]:
    """Each agent's extra observation fields as the scenario itself fills them at its first tick
    (its default parameters, ``n`` agents), for the fields the kit's instance does not set: a
    scenario of one's own is checked with the values its world gives (an item carried: -1), not
    with made-up ones. Empty where the scenario's world cannot be built here."""
    from swarmbed.schema.experiment import AgentsSection

    try:
        cls = resolve_scenario(scenario)
        world = cls(cls.Params(), AgentsSection(count=n), 1.0).make_world(np.random.default_rng(seed))
        observed = world.observations()
        return [
            {name: getattr(observed[i], name) for name, _ in cls.Observation.extra_fields()} if i in observed else {}
            for i in range(n)
        ]
    except Exception:  # a scenario whose world needs more than its defaults: empty values instead
        return [{} for _ in range(n)]


def _view(
    inst: Instance,
    obs_cls: type[Observation],
    tasks: dict[int, tuple[float, float, float]],
    i: int,
    k: int,
    inbox,
    declared: dict[str, Any] | None = None,
) -> LocalView:
    """What standing agent ``i`` sees at round ``k``: the tasks in its range and the instance's
    observed fields (every round's, its own, the first round's), then those its scenario's world
    gave it (``declared``) for the fields the instance leaves out."""
    x, y = inst.agents[i]
    colors = inst.task_colors or {}
    visible = {
        t: TaskInfo(t, tx, ty, w, colors.get(t, -1))
        for t, (tx, ty, w) in tasks.items()
        if math.hypot(tx - x, ty - y) <= inst.awareness_range
    }
    known = {**(declared or {}), **inst.observed}
    if inst.observed_by_agent is not None:
        known.update(inst.observed_by_agent[i])
    if k == 0:
        known.update(inst.observed_first)
    obs = _observation(obs_cls, k, x, y, visible, known)
    n = len(inst.agents)
    return LocalView(
        i, n, k, float(k), x, y, 0.0, 0.0, inst.work_rate, visible, inbox, inst.max_speed, inst.awareness_range, obs=obs
    )


def _moved(
    allocator: Allocator, name: str, params: Mapping[str, Any], agent_id: int, seed: int, scenario: str | None
) -> Allocator:
    """A fresh instance restored from ``allocator``'s snapshot through its bytes."""
    state = unpack_state(pack_state(allocator.snapshot()))
    fresh = make(name, params, agent_id, np.random.default_rng(12345), seed, scenario)  # rng from the snapshot
    fresh.restore(state)
    return fresh


# -- generic checks ---------------------------------------------------------------------------------


def check_determinism(
    name: str, params: Mapping[str, Any], scenario: str = "mtsr", seeds=(0, 1, 2), rounds: int = 30
) -> dict:
    for seed in seeds:
        inst = random_instance(seed, 5, 12, scenario=scenario)
        a = simulate(name, params, inst, rounds, seed=seed, scenario=scenario)
        b = simulate(name, params, inst, rounds, seed=seed, scenario=scenario)
        if a.decisions != b.decisions or a.messages != b.messages:
            raise ConformanceError(f"{name}: two runs with seed {seed} differ")
    return {"seeds": len(seeds)}


def check_messages(
    name: str, params: Mapping[str, Any], scenario: str = "mtsr", max_bytes: int = DEFAULT_MAX_BYTES
) -> dict:
    trace = simulate(
        name, params, random_instance(7, 8, 30, scenario=scenario), 40, max_bytes=max_bytes, scenario=scenario
    )
    sizes = [len(p) for rnd in trace.messages for _, _, p in rnd]
    return {"messages": len(sizes), "max_bytes": max(sizes, default=0)}


def _assigned(trace: Trace) -> int:
    return sum(1 for d in trace.decisions[-1].values() if d is not None)


def check_degraded_network(name: str, params: Mapping[str, Any], scenario: str = "mtsr") -> dict:
    """Keeps working under 30 % loss and under a tight rate cap with a short queue."""
    inst = random_instance(11, 6, 15, scenario=scenario)
    clean = _assigned(simulate(name, params, inst, 60, scenario=scenario))
    out = {"assigned_clean": clean}
    for label, net in (("loss", NetworkSection(loss=0.3)), ("rate", NetworkSection(rate=300.0, limit=3))):
        degraded = _assigned(simulate(name, params, inst, 60, network=net, scenario=scenario))
        if clean and not degraded:
            raise ConformanceError(f"{name}: assigns {clean} agents on a clean network but none under {label}")
        out[f"assigned_{label}"] = degraded
    return out


def check_vanishing_tasks(name: str, params: Mapping[str, Any], scenario: str = "mtsr", patience: int = 3) -> dict:
    """Tasks that disappear (done by someone) are dropped within ``patience`` rounds."""
    inst = random_instance(5, 6, 15, scenario=scenario)
    before = simulate(name, params, inst, 20, scenario=scenario)
    chosen = sorted({d for d in before.decisions[-1].values() if d is not None})
    trace = simulate(name, params, inst, 20 + patience + 10, remove_at={20: chosen}, scenario=scenario)
    for k in range(20 + patience, len(trace.decisions)):
        stuck = {i: d for i, d in trace.decisions[k].items() if d in chosen}
        if stuck:
            raise ConformanceError(f"{name}: at round {k}, agents still on vanished tasks: {stuck}")
    return {"vanished": len(chosen)}


def check_snapshot(name: str, params: Mapping[str, Any], scenario: str = "mtsr", rounds: int = 40) -> dict:
    """Snapshot, restore in a fresh instance and continue equals continuing: the same decisions
    and message bytes, with every agent moved at three points of the run."""
    if not resolve(name, scenario).snapshottable:
        return {"snapshottable": False}
    inst = random_instance(13, 6, 15, scenario=scenario)
    plain = simulate(name, params, inst, rounds, seed=4, scenario=scenario)
    moved = simulate(name, params, inst, rounds, seed=4, scenario=scenario, move_at=(1, 7, 23))
    for k, (a, b) in enumerate(zip(plain.decisions, moved.decisions)):
        if a != b or plain.messages[k] != moved.messages[k]:
            raise ConformanceError(f"{name}: after moving through a snapshot, round {k} differs (decisions {a} vs {b})")
    size = max(len(pack_state(a.snapshot())) for a in moved.allocators)
    return {"moves": 3, "snapshot_bytes_max": size}


def check_team_tasks(name: str, params: Mapping[str, Any], scenario: str = "mtsr") -> dict:
    """Where every task needs two robots (MT-SR's ``robots_needed``: the observation's
    ``coalitions``, which an allocator may read or ignore), it still runs, decides only on tasks
    that exist and decides the same on the same seed. A scenario whose observation has no such
    field shows none, and this is the plain check again."""
    inst = random_instance(17, 6, 9, scenario=scenario)
    inst.observed = {**inst.observed, "coalitions": [(j, 2, 0) for j in inst.tasks]}
    a = simulate(name, params, inst, 40, seed=3, scenario=scenario)
    b = simulate(name, params, inst, 40, seed=3, scenario=scenario)
    if a.decisions != b.decisions or a.messages != b.messages:
        raise ConformanceError(f"{name}: two runs of team tasks with seed 3 differ")
    return {"deciding_at_end": _assigned(a)}


GENERIC_CHECKS = (
    check_determinism,
    check_messages,
    check_degraded_network,
    check_vanishing_tasks,
    check_snapshot,
    check_team_tasks,
)


def run_all(name: str, params: Mapping[str, Any] | None = None, scenario: str = "mtsr") -> dict[str, dict]:
    resolve(name, scenario)
    return {check.__name__: check(name, params or {}, scenario) for check in GENERIC_CHECKS}
