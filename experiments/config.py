"""The experiment schema, its loader, and ``--set dotted.key=value`` overrides.

Everything is validated before any process starts: an unknown key, a wrong type or an
out-of-range value is refused with the dotted key and the file it came from.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from swarmbed.plugins.registry import PluginError, validate_params


class ConfigError(ValueError):
    """A bad experiment file or override; the message names the file and the dotted key."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class RunSection(_Strict):
    seed: int = Field(0, ge=0, description="run seed; every random source derives from it")
    clock: Literal["lockstep"] = Field("lockstep", description="lockstep: ticks advance when everyone has acted")
    dt: float = Field(1.0, gt=0, description="simulated seconds per tick")
    duration: float = Field(3000.0, gt=0, description="simulated seconds before the run stops")
    tick_timeout: float = Field(60.0, gt=0, description="wall seconds a tick may wait for a silent process")
    join_timeout: float = Field(120.0, gt=0, description="wall seconds to wait for every process to join")
    allow_agent_failures: bool = Field(False, description="go on without an agent whose process dies")
    record_every: int = Field(1, ge=1, description="ticks between time-series rows")
    record_trajectories: bool = Field(False, description="also write trajectories.csv (tick, agent, x, y)")
    stop_when_done: bool = Field(True, description="end the run once every task there will be is done")


class Generations(_Strict):
    interval: float = Field(1000.0, gt=0, description="simulated seconds between task generations")
    count: int = Field(3, ge=0, description="how many generations")
    tasks: int = Field(50, ge=0, description="tasks per generation")


class MTSRScenario(_Strict):
    """The SPACE MT-SR workload scenario (SPACE paper, Table I)."""

    kind: Literal["mtsr"] = "mtsr"
    width: float = Field(1400.0, gt=0)
    height: float = Field(1000.0, gt=0)
    initial_tasks: int = Field(250, ge=0)
    workload: tuple[float, float] = Field((6.0, 60.0), description="task workload range [min, max]")
    arrival_radius: float = Field(10.0, gt=0, description="distance within which an agent works on a task")
    generations: Generations = Generations()
    agent_positions: list[tuple[float, float]] | None = Field(None, description="fixed start positions (else uniform)")
    task_positions: list[tuple[float, float]] | None = Field(None, description="fixed initial task positions")

    @model_validator(mode="after")
    def _check(self):
        lo, hi = self.workload
        if not 0 < lo <= hi:
            raise ValueError("workload must be [min, max] with 0 < min <= max")
        if self.task_positions is not None and len(self.task_positions) != self.initial_tasks:
            raise ValueError("task_positions needs one [x, y] per initial task")
        return self

    def random_point(self, rng) -> tuple[float, float]:
        return float(rng.uniform(0, self.width)), float(rng.uniform(0, self.height))


class SARScenario(_Strict):
    """Search and rescue (CBBA-ETC paper, Section 5.1 and Table 1)."""

    kind: Literal["sar"]
    arena_radius: float = Field(32.0, gt=0, description="radius of the circular arena (m)")
    victims: int = Field(100, ge=0, description="victims at any time (steady state) or in all (finite)")
    lifetime: float = Field(100.0, gt=0, description="seconds a victim lives before it expires")
    replace: bool = Field(True, description="steady state: a rescued or expired victim is replaced")
    colors: int = Field(3, ge=1, le=3, description="RED, GREEN, BLUE")
    vision_range: float = Field(12.0, gt=0, description="conical vision: range (m)")
    vision_angle: float = Field(math.pi / 2, gt=0, le=2 * math.pi, description="conical vision: full angle (rad)")
    inspect_range: float = Field(5.0, gt=0, description="distance within which a robot can inspect/rescue (m)")
    move_fail: float = Field(0.0, ge=0, le=1, description="probability that a move fails")
    inspect_fail: float = Field(0.0, ge=0, le=1, description="probability that an inspection fails")
    rescue_fail: float = Field(0.0, ge=0, le=1, description="probability that a rescue fails")
    move_penalty: float = Field(0.5, ge=0, description="seconds a robot is stuck after a failed move")
    inspect_time: float = Field(0.0, ge=0, description="extra seconds an inspection keeps the robot busy (0: one tick)")
    rescue_time: float = Field(0.0, ge=0, description="extra seconds a rescue keeps the robot busy (0: one tick)")
    agent_loss: float = Field(0.0, ge=0, le=1, description="probability per step that a robot is lost for good")
    agent_loss_grace: float = Field(500.0, ge=0, description="seconds before agent loss can happen")
    colors_for_bidding: Literal["auto", "always", "never"] = Field(
        "auto", description="show victims' colours to bidders (auto: when the allocator bids with colours)")

    def random_point(self, rng) -> tuple[float, float]:
        r = self.arena_radius * math.sqrt(float(rng.random()))
        a = float(rng.uniform(-math.pi, math.pi))
        return r * math.cos(a), r * math.sin(a)


class AgentsSection(_Strict):
    count: int = Field(10, ge=1, le=1000)
    max_speed: float = Field(0.25, gt=0, description="v_max, units per second")
    max_accel: float = Field(0.01, gt=0, description="a_max, units per second^2")
    max_turn_rate: float = Field(0.25, gt=0, description="omega_max, radians per second")
    work_rate: float = Field(1.0, gt=0, description="workload done per second")
    awareness_range: float = Field(300.0, gt=0, description="tasks within this distance are observed")
    exploration_duration: float = Field(1000.0, gt=0, description="seconds spent exploring toward one waypoint")
    behavior_tree: str = Field("default", description="'default' (the SPACE tree) or a path to BT.CPP v4 XML")


class AllocatorSection(BaseModel):
    """``name`` plus the plugin's own parameters, checked by the plugin's ``Params`` model."""

    model_config = ConfigDict(extra="allow")
    name: str = "fcg"

    def params(self) -> dict[str, Any]:
        return dict(self.model_extra or {})


class NetworkSection(_Strict):
    range: float | None = Field(None, ge=0, description="communication range; null = unlimited")
    loss: float = Field(0.0, ge=0, le=1, description="probability a copy is lost")
    rate: float | None = Field(None, gt=0, description="per-sender cap in bytes per simulated second")
    limit: int | None = Field(None, ge=1, description="messages that may wait behind the rate cap")
    latency: int = Field(0, ge=0, description="extra ticks of delay")


class Experiment(_Strict):
    name: str = "experiment"
    run: RunSection = RunSection()
    scenario: Annotated[MTSRScenario | SARScenario, Field(discriminator="kind")] = MTSRScenario()
    agents: AgentsSection = AgentsSection()
    allocator: AllocatorSection = AllocatorSection()
    network: NetworkSection = NetworkSection()

    @property
    def ticks(self) -> int:
        return int(round(self.run.duration / self.run.dt))


@dataclass(frozen=True)
class Sensing:
    range: float
    angle: float
    max_speed: float


def scenario_sensing(exp: Experiment) -> Sensing:
    """What an agent's sensors cover, by scenario."""
    sc = exp.scenario
    if isinstance(sc, SARScenario):
        return Sensing(sc.vision_range, sc.vision_angle, exp.agents.max_speed)
    return Sensing(exp.agents.awareness_range, 2 * math.pi, exp.agents.max_speed)


def _set_dotted(data: dict, dotted: str, value: Any, where: str) -> None:
    keys = dotted.split(".")
    node = data
    for k in keys[:-1]:
        nxt = node.setdefault(k, {})
        if not isinstance(nxt, dict):
            raise ConfigError(f"{where}: --set {dotted}: '{k}' is not a section")
        node = nxt
    node[keys[-1]] = value


def apply_overrides(data: dict, pairs: list[tuple[str, Any]], where: str) -> None:
    """Set each dotted key. Naming another allocator drops the file's parameters of the old one
    (they belong to that plugin); parameters given alongside the new name are kept."""
    alloc = data.get("allocator")
    old_name = alloc.get("name", "fcg") if isinstance(alloc, dict) else None
    new_name = dict(pairs).get("allocator.name")
    if new_name is not None and new_name != old_name:
        data["allocator"] = {"name": new_name}
    for key, value in pairs:
        _set_dotted(data, key, value, where)


def parse_override(text: str) -> tuple[str, Any]:
    """``a.b=value`` with ``value`` read as YAML (so numbers, booleans, lists and null work)."""
    key, sep, raw = text.partition("=")
    if not sep or not key.strip():
        raise ConfigError(f"--set {text!r}: expected dotted.key=value")
    try:
        value = yaml.safe_load(raw) if raw.strip() else ""
    except yaml.YAMLError as exc:
        raise ConfigError(f"--set {text!r}: value is not valid YAML: {exc}") from None
    return key.strip(), value


def validate(data: dict, where: str) -> Experiment:
    if isinstance(data.get("scenario"), dict) and "kind" not in data["scenario"]:
        data = {**data, "scenario": {"kind": "mtsr", **data["scenario"]}}
    try:
        exp = Experiment.model_validate(data)
    except ValidationError as exc:
        lines = []
        for e in exc.errors():
            parts = [str(p) for p in e["loc"]]
            if parts[:1] == ["scenario"] and parts[1:2] in (["mtsr"], ["sar"]):
                del parts[1]  # the discriminator's tag is not a key the user wrote
            loc = ".".join(parts)
            msg = "unknown key" if e["type"] == "extra_forbidden" else e["msg"]
            lines.append(f"{where}: {loc}: {msg}")
        raise ConfigError("\n".join(lines)) from None
    try:
        validate_params(exp.allocator.name, exp.allocator.params(), exp.scenario.kind)
    except PluginError as exc:
        raise ConfigError(f"{where}: {exc}") from None
    positions = getattr(exp.scenario, "agent_positions", None)
    if positions is not None and len(positions) != exp.agents.count:
        raise ConfigError(f"{where}: scenario.agent_positions: needs one [x, y] per agent ({exp.agents.count})")
    if exp.agents.behavior_tree != "default" and not Path(exp.agents.behavior_tree).is_file():
        raise ConfigError(f"{where}: agents.behavior_tree: file {exp.agents.behavior_tree} does not exist")
    return exp


def load(path: str | Path, overrides: list[str] = (), seed: int | None = None) -> Experiment:
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML: {exc}") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: the top level must be a mapping of sections")
    if "base" in data and "run" not in data:
        raise ConfigError(f"{path}: this is a sweep file (it names a base experiment): "
                          f"run it with `swarmbed sweep {path}`")
    apply_overrides(data, [parse_override(text) for text in overrides], str(path))
    if seed is not None:
        _set_dotted(data, "run.seed", seed, str(path))
    bt = data.get("agents", {}).get("behavior_tree") if isinstance(data.get("agents"), dict) else None
    if isinstance(bt, str) and bt != "default" and not Path(bt).is_absolute():
        data["agents"]["behavior_tree"] = str((path.parent / bt).resolve())
    return validate(data, str(path))


def to_yaml(exp: Experiment) -> str:
    return yaml.safe_dump(exp.model_dump(mode="json"), sort_keys=False)


def from_yaml(text: str, where: str = "<resolved config>") -> Experiment:
    return validate(yaml.safe_load(text), where)


def describe_keys() -> list[tuple[str, str, str]]:
    """(dotted key, default, description) for every key: what ``swarmbed run --help`` lists."""
    rows: list[tuple[str, str, str]] = []

    def walk(model: type[BaseModel], prefix: str) -> None:
        for name, field in model.model_fields.items():
            ann = field.annotation
            if name == "scenario":
                walk(MTSRScenario, "scenario.")
                walk(SARScenario, "scenario.")
            elif isinstance(ann, type) and issubclass(ann, BaseModel) and ann is not AllocatorSection:
                walk(ann, f"{prefix}{name}.")
            else:
                rows.append((f"{prefix}{name}", repr(field.default), field.description or ""))

    walk(Experiment, "")
    rows.append(("allocator.<param>", "", "the allocator's own parameters (see its Params)"))
    return rows
