"""A conformance checker for scenarios, in the spirit of Gymnasium's ``check_env``.

It drives a scenario's world in-process (no network) with the scenario's own random actions and
checks what the rest of swarmbed relies on:

- determinism: the same seed gives the same observations, rows, summary and per-agent columns;
- observations: each is the scenario's ``Observation``, survives the wire (msgpack and the
  shape-checking decoder) unchanged, and goes to exactly the live agents;
- results: the time-series row has the same keys every tick, the summary holds every declared
  ``summary_keys`` and ``outcome_metrics`` and is JSON, ``per_agent`` has one entry per agent;
- conservation: the world's ``invariants()`` hold after every tick;
- actions: every action ``random_action`` gives is one ``Scenario.actions`` declares;
- robustness: malformed actions, handed to the world as the coordinator hands them (``["invalid"]``
  for any shape the scenario does not declare, well-shaped ones naming what does not exist as
  they are), are refused without raising, and a killed agent stops being observed and positioned.

    swarmbed check-scenario sar
    swarmbed check-scenario my_world.py:MyScenario
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import msgpack
import numpy as np

from swarmbed.extension.actions import admit, conforms
from swarmbed.extension.scenario import Scenario, World
from swarmbed.schema.experiment import AgentsSection
from swarmbed.wire.codec import pack, unpack

GARBAGE_ACTIONS: tuple[Any, ...] = (
    [],
    ["fly"],
    ["goto_task"],
    ["goto_task", "x"],
    ["goto", 1],
    ["goto", "a", "b"],
    ["stop", 1],
    [7],
    ["inspect", -5],
    ["goto_task", 10**9],
    ["goto", float("nan"), 1.0],
    ["goto", float("inf"), 0.0],
)


class ScenarioCheckError(AssertionError):
    """A scenario broke a rule the rest of swarmbed relies on; the message says which."""


def _build(cls: type[Scenario], params: Mapping[str, Any], agents: Mapping[str, Any], dt: float) -> Scenario:
    return cls(cls.Params.model_validate(dict(params)), AgentsSection.model_validate(dict(agents)), dt)


def _trace(scenario: Scenario, seed: int, ticks: int) -> tuple[list[bytes], dict[str, Any]]:
    """Drive a world for ``ticks`` ticks; every observation's bytes and the end results."""
    cls = type(scenario)
    world = scenario.make_world(np.random.default_rng(seed))
    action_rng = np.random.default_rng([seed, 1])
    seen: list[bytes] = []
    columns: list[str] | None = None
    for k in range(ticks):
        ids, xs, ys = world.positions()
        if not (len(ids) == len(xs) == len(ys)) or ids != sorted(ids):
            raise ScenarioCheckError(f"tick {k}: positions() must give ids in order with one x and y each")
        observations = world.observations()
        if sorted(observations) != ids:
            raise ScenarioCheckError(f"tick {k}: observations for agents {sorted(observations)}, live agents {ids}")
        actions = {}
        for i, obs in sorted(observations.items()):
            if not isinstance(obs, cls.Observation):
                raise ScenarioCheckError(
                    f"tick {k}: agent {i}'s observation is a {type(obs).__name__}, "
                    f"not the scenario's {cls.Observation.__name__}"
                )
            wire = pack(obs.to_wire())
            back = cls.Observation.from_wire(unpack(wire))
            if pack(back.to_wire()) != wire:
                raise ScenarioCheckError(f"tick {k}: agent {i}'s observation changes when it crosses the wire")
            seen.append(wire)
            actions[i] = scenario.random_action(back, action_rng)
            if not conforms(actions[i], cls.actions):
                raise ScenarioCheckError(
                    f"tick {k}: random_action gave {actions[i]!r}, which {cls.__name__}.actions does not "
                    f"declare (declared: {', '.join(f'{n}{list(t)}' for n, t in cls.actions.items())})"
                )
        try:
            world.apply(actions)
        except Exception as exc:
            raise ScenarioCheckError(
                f"tick {k}: apply() raised {type(exc).__name__}: {exc} on the scenario's own actions {actions}"
            ) from exc
        row = world.row()
        if columns is None:
            columns = list(row)
        elif list(row) != columns:
            raise ScenarioCheckError(f"tick {k}: row keys {list(row)} differ from the first row's {columns}")
        broken = world.invariants()
        if broken:
            raise ScenarioCheckError(f"tick {k}: conservation broken: {'; '.join(broken)}")
        seen.append(pack(list(row.values())))
    return seen, {"summary": world.summary(), "per_agent": world.per_agent()}


def _check_results(cls: type[Scenario], results: dict[str, Any], agents: int) -> None:
    summary = results["summary"]
    declared = (*cls.summary_keys, *cls.outcome_metrics, *([cls.benefit_metric] if cls.benefit_metric else []))
    missing = [k for k in declared if k not in summary]
    if missing:
        raise ScenarioCheckError(f"summary() lacks the declared keys {missing}")
    try:
        json.dumps(summary, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise ScenarioCheckError(f"summary() is not plain JSON: {exc}") from None
    for name, column in results["per_agent"].items():
        if len(column) != agents:
            raise ScenarioCheckError(f"per_agent()[{name!r}] has {len(column)} entries for {agents} agents")


def _check_robustness(scenario: Scenario, seed: int) -> None:
    world: World = scenario.make_world(np.random.default_rng(seed))
    ids = world.positions()[0]
    for action in GARBAGE_ACTIONS:
        try:
            world.apply(dict.fromkeys(ids, admit(action, scenario.actions)))  # as the coordinator hands them
        except Exception as exc:
            raise ScenarioCheckError(
                f"apply() raised {type(exc).__name__} on the malformed action {action!r}; "
                "it must refuse (count) it instead"
            ) from None
    world.kill(ids[0])
    if ids[0] in world.positions()[0] or ids[0] in world.observations():
        raise ScenarioCheckError(f"agent {ids[0]} was killed but is still positioned or observed")
    world.apply({i: ["stop"] for i in ids[1:]})
    if world.invariants():
        raise ScenarioCheckError(f"conservation broken after malformed actions: {'; '.join(world.invariants())}")


def check_scenario(
    cls: type[Scenario],
    params: Mapping[str, Any] | None = None,
    agents: Mapping[str, Any] | None = None,
    ticks: int = 60,
    seeds: tuple[int, ...] = (0, 1),
    dt: float = 1.0,
) -> dict[str, Any]:
    """Run every check on scenario ``cls`` with ``params`` (its defaults where not given) and the
    ``agents`` section (4 agents unless given; give a speed at which things happen within
    ``ticks``); raise :class:`ScenarioCheckError` at the first broken rule, else return what was
    exercised."""
    agents = {"count": 4, **(agents or {})}
    n = int(agents["count"])
    scenario = _build(cls, params or {}, agents, dt)
    observations = 0
    for seed in seeds:
        first, results = _trace(scenario, seed, ticks)
        again, results_again = _trace(_build(cls, params or {}, agents, dt), seed, ticks)
        if first != again or msgpack.packb(results, default=str) != msgpack.packb(results_again, default=str):
            raise ScenarioCheckError(
                f"two runs with seed {seed} differ (a random source not drawn from the world's generator?)"
            )
        _check_results(cls, results, n)
        observations += len(first)
        _check_robustness(scenario, seed)
    return {"seeds": len(seeds), "ticks": ticks, "agents": n, "samples_checked": observations}
