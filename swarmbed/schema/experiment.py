"""The experiment schema: pure pydantic models, shared by every process and importing no plugin.

An experiment has five sections. ``run``, ``agents`` and ``network`` are checked here in full.
``scenario`` and ``allocator`` are a name (``kind`` / ``name``) plus the parameters of the code
that name resolves to; only ``swarmbed.config``, before anything is launched, resolves names and
checks those parameters against the plugin's own ``Params`` model, and it writes them back fully
resolved, so that every process reads complete sections.

Each process is handed only what it needs: the netem proxy a :class:`NetemSpec` (its radio
parameters), an agent an :class:`AgentSpec` (its sections and the code to load). Both travel as
JSON from the coordinator's queryables and are validated again on arrival.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from typing import Any, ClassVar, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    PrivateAttr,
    SerializerFunctionWrapHandler,
    model_serializer,
    model_validator,
)

from swarmbed.schema.obstacles import ObstaclesSection
from swarmbed.schema.radio_sections import NetworkSection, WallsSection

#: a name that becomes a folder (experiments, sweeps, their scenarios): no path separators, no ``..``
SAFE_NAME = r"^[A-Za-z0-9_][A-Za-z0-9_.+=-]{0,99}$"

#: the most ticks one run may have (duration / dt): checked before anything is built
MAX_TICKS = 100_000_000
#: the most agents a run has (each is an OS process); views bound what they draw by it
MAX_AGENT_COUNT = 1000
#: the most tasks (MT-SR tasks in all, initial and generated; search-and-rescue victims) a run may
#: have: every agent's allocator keeps a row per task, so memory grows with agents x tasks
MAX_TASKS = 100_000


class Strict(BaseModel):
    """A section whose unknown keys, infinite and NaN numbers are refused."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class QuietDefaults(BaseModel):
    """A model whose keys in ``QUIET`` are left out of its dump (config.yaml, a sweep's digests) at
    the value given there: keys added after runs were made that, at that value, change nothing, so
    that those runs' files and a sweep resumed over them stay as they were. Loading fills them in."""

    QUIET: ClassVar[dict[str, Any]] = {}

    @model_serializer(mode="wrap")
    def _quiet_defaults_stay_out(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        data = handler(self)
        for key, value in self.QUIET.items():
            if key in data and data[key] == value:
                del data[key]
        return data


class RunSection(Strict):
    seed: int = Field(0, ge=0, description="run seed; every random source derives from it")
    clock: Literal["lockstep", "realtime"] = Field(
        "lockstep", description="lockstep: a tick ends when every agent has acted; realtime: ticks follow the wall"
    )
    speed: float = Field(1.0, gt=0, description="realtime: simulated seconds per wall second")
    deadline: float = Field(0.8, gt=0, le=1, description="realtime: part of a tick an agent has to answer in")
    on_late: Literal["stop", "hold"] = Field(
        "stop", description="realtime: a late agent's robot stops for that tick, or holds its last command"
    )
    dt: float = Field(1.0, gt=0, description="simulated seconds per tick")
    duration: float = Field(3000.0, gt=0, description="simulated seconds before the run stops")
    tick_timeout: float = Field(60.0, gt=0, description="wall seconds a tick may wait for a silent process")
    join_timeout: float = Field(120.0, gt=0, description="wall seconds to wait for every process to join")
    allow_agent_failures: bool = Field(False, description="the same as on_agent_loss: continue (kept for old files)")
    on_agent_loss: Literal["fail", "continue", "restart"] = Field(
        "fail",
        description="when an agent's process dies: stop the run, go on without it, or start it again "
        "under its id (from its last checkpoint where there is one)",
    )
    snapshot_every: int = Field(
        0, ge=0, description="restart: ticks between the agents' checkpoints (0: none, a restarted agent starts fresh)"
    )
    restart_attempts: int = Field(
        3,
        ge=1,
        description="restart: tries to start a lost agent before it counts as lost (its host may be away for a while)",
    )
    restart_backoff: float = Field(
        2.0,
        gt=0,
        description="restart: wall seconds before the second try, doubling "
        "after each failed one; ticks go on meanwhile",
    )
    log_max_mb: int = Field(20, ge=1, description="each process's log file is rotated at this size (MB)")
    log_backups: int = Field(2, ge=0, description="rotated log files kept per process (name.log.1, ...)")
    record_every: int = Field(1, ge=1, description="ticks between time-series rows")
    record_trajectories: bool = Field(False, description="write trajectories.csv and markers.csv (for swarmbed replay)")
    zenoh_threads: Literal["default", "single", "zenoh"] = Field(
        "default",
        description="Zenoh's threads in the agents and the proxy this machine starts: default (one worker receives "
        "and agents answer ticks in its callback, one more transmits, so keep-alives flow during a long tick), "
        "single (every runtime on one worker: the fewest wake-ups, but such agents take a 60 s lease: the hub "
        "waits up to a minute for a frozen or cut-off agent, and one that wakes sooner mostly finds the hub's 10 s "
        "lease expired on its side and is lost then, or else answers on), or zenoh (Zenoh's own layout); results "
        "are the same with each "
        "(docs/benchmarks.md)",
    )
    record_bt: bool = Field(
        False,
        description="write bt/agent_<id>.btlog, each agent's behavior tree run as Groot2 replays it "
        "(BehaviorTree.CPP's file-logger format, stamped in simulated time)",
    )
    stop_when_done: bool = Field(True, description="end the run once every task there will be is done")

    @property
    def agent_loss(self) -> Literal["fail", "continue", "restart"]:
        """``on_agent_loss``, with the older ``allow_agent_failures: true`` read as ``continue``."""
        return "continue" if self.allow_agent_failures and self.on_agent_loss == "fail" else self.on_agent_loss


class AgentsSection(Strict):
    count: int = Field(10, ge=1, le=MAX_AGENT_COUNT, description="number of agents, one OS process each")
    max_speed: float = Field(0.25, gt=0, description="v_max, units per second")
    max_accel: float = Field(0.01, gt=0, description="a_max, units per second^2 (MT-SR kinematics)")
    max_turn_rate: float = Field(0.25, gt=0, description="omega_max, radians per second (MT-SR kinematics)")
    work_rate: float = Field(1.0, gt=0, description="workload done per second (MT-SR)")
    awareness_range: float = Field(300.0, gt=0, description="tasks within this distance are observed (MT-SR)")
    exploration_duration: float = Field(1000.0, gt=0, description="seconds spent exploring toward one waypoint")
    behavior_tree: str = Field(
        "default", description="'default' (the allocator's or scenario's tree) or a path to BT.CPP v4 XML"
    )


class ScenarioSection(BaseModel):
    """``kind`` (a registered scenario or ``module:Class``) plus that scenario's own parameters."""

    model_config = ConfigDict(extra="allow")
    kind: str = Field("mtsr", description="registered scenario name or module:Class")

    def params(self) -> dict[str, Any]:
        return dict(self.model_extra or {})


class AllocatorSection(BaseModel):
    """``name`` (a registered allocator or ``module:Class``) plus the plugin's own parameters."""

    model_config = ConfigDict(extra="allow")
    name: str = Field("fcg", description="registered allocator name or module:Class")

    def params(self) -> dict[str, Any]:
        return dict(self.model_extra or {})


HOST_NAME = r"^[A-Za-z0-9_][A-Za-z0-9_.-]{0,56}$"  # credentials.check_host_name's: <host>-agents is a user name
LOCAL = "local"  # the launching machine's name in a placement


class SwapEntry(Strict):
    """One scripted swap: agent ``agent`` moves to host ``to`` before tick ``tick``."""

    agent: int = Field(ge=0)
    tick: int = Field(ge=1)
    to: str = Field(pattern=HOST_NAME)


def hosts_of(placement: dict[str, str | int | list[int]], n_agents: int) -> dict[int, str]:
    """Host of every agent id (``local`` unless placed); raises ValueError on a bad placement."""
    where = dict.fromkeys(range(n_agents), LOCAL)
    placed: dict[int, str] = {}
    for host, ids in placement.items():
        if not re.match(HOST_NAME, host):
            raise ValueError(f"placement: {host!r} is not a host name (letters, digits, _ . -)")
        for i in parse_ids(ids, n_agents, f"placement.{host}"):
            if i in placed:
                raise ValueError(f"placement: agent {i} is placed on both {placed[i]} and {host}")
            placed[i] = where[i] = host
    return where


def carriers(exp: Experiment) -> dict[str, frozenset[int]]:
    """Agent ids each host other than ``local`` may carry during the run: those placed on it, those
    scripted swaps move to it and those in ``may_carry``. The hub's access rules hold each host's
    identity to these, and a swap to a host that may not carry the agent is refused."""
    out: dict[str, set[int]] = {}
    for i, host in hosts_of(exp.placement, exp.agents.count).items():
        out.setdefault(host, set()).add(i)
    for entry in exp.swaps:
        out.setdefault(entry.to, set()).add(entry.agent)
    for host, ids in exp.may_carry.items():
        if not re.match(HOST_NAME, host):
            raise ValueError(f"may_carry: {host!r} is not a host name (letters, digits, _ . -)")
        for i in parse_ids(ids, exp.agents.count, f"may_carry.{host}"):
            out.setdefault(host, set()).add(i)
    out.pop(LOCAL, None)
    return {host: frozenset(ids) for host, ids in sorted(out.items())}


def parse_ids(ids: str | int | list[int], n_agents: int, where: str = "placement") -> list[int]:
    """``"0-9,12"``, ``7`` or ``[1, 2]`` as a list of ids, each checked to lie in ``0..n_agents-1``
    before any range is built (``0-1000000000`` is refused, not materialised)."""

    def bounded(i: int) -> int:
        if not 0 <= i < n_agents:
            raise ValueError(f"{where}: agent {i} is outside 0..{n_agents - 1}")
        return i

    if isinstance(ids, bool):
        raise ValueError(f"{where}: {ids!r} is not a list of ids like '0-9,12'")
    if isinstance(ids, int):
        return [bounded(ids)]
    if isinstance(ids, list):
        if not all(isinstance(i, int) and not isinstance(i, bool) for i in ids):
            raise ValueError(f"{where}: {ids!r} is not a list of ids like '0-9,12'")
        return [bounded(i) for i in ids]
    out: list[int] = []
    for part in str(ids).replace(" ", "").split(","):
        lo, dash, hi = part.partition("-")
        if not lo.isdigit() or (dash and not hi.isdigit()) or len(part) > 20:
            raise ValueError(f"{where}: {ids!r} is not a list of ids like '0-9,12'")
        first, last = bounded(int(lo)), bounded(int(hi)) if dash else int(lo)
        out += list(range(first, last + 1))
    return out


class Ros2Section(Strict):
    """Publish the run as ROS 2 topics on rmw_zenoh's keys (docs/ros2.md). What a ROS 2 machine
    sees is not part of the results: config.yaml leaves this out, deployment.json records it."""

    domain: int = Field(0, ge=0, le=232, description="ROS_DOMAIN_ID: the first chunk of every topic key")
    frame_id: str = Field("map", pattern=r"^[A-Za-z_][A-Za-z0-9_/]{0,63}$", description="frame of poses and markers")
    every: int = Field(1, ge=1, description="ticks between poses, task markers and inboxes (/clock: every tick)")
    path: int = Field(
        0,
        ge=0,
        le=10_000,
        description="publish /robot_<i>/path (nav_msgs/Path): each robot's last this many published poses (0: off)",
    )
    command_timeout: float = Field(
        10.0,
        gt=0,
        le=3600,
        description="allocator ros2, lock-step: wall seconds a tick waits for every robot's command (at most 3600)",
    )
    distro: Literal["humble", "jazzy", "kilted", "lyrical", "rolling"] = Field(
        "jazzy",
        description="the ROS 2 distribution whose message definitions and type hashes the keys carry (rosbags' "
        "store of it; rolling: rosbags' latest); humble's keys carry rmw_zenoh's TypeHashNotSupported",
    )


class RadioSplit(Strict):
    """The radio decided by several netem proxies (docs/machines.md, "A radio split by region").
    Where the copies are decided is not part of the results: config.yaml leaves this out."""

    shards: int = Field(1, ge=1, le=64, description="netem proxies; each decides the copies its region's agents send")
    regions: Literal["bands", "strips"] = Field(
        "bands",
        description="bands: at every tick, proxy j owns the j-th of K bands across x holding an equal share of the "
        "agents; strips: strips strip_width wide across x, dealt to the proxies in turn (strip j: proxy j mod shards)",
    )
    strip_width: float = Field(50.0, gt=0, description="the width of a strip (regions: strips)")


#: what a radio split over proxies cannot do yet, each with why (refused before any process starts)
SPLIT_REFUSES = {
    "network.draws: sequential": "one stream of loss draws in copy order cannot be split; set network.draws: per_copy",
    "network.propagation": "its shadowing and fading streams advance over every link at once",
    "network.burst": "its burst states advance over every link at once",
    "network.delay": "its jitter stream is drawn in copy order over the whole tick",
    "network.channel": "a receiver's airtime is shared by copies from every region",
    "network.ledger: per_receiver": "the receivers' Parquet ledger is not merged across proxies",
    "run.clock: realtime": "late answers are booked by the one proxy that routed the tick",
    "ros2": "the radio topics are published by one proxy",
}


class Experiment(Strict, QuietDefaults):
    #: a world without obstacles writes the config.yaml it wrote before they existed
    QUIET: ClassVar[dict[str, Any]] = {"obstacles": None}

    name: str = Field(
        "experiment",
        pattern=SAFE_NAME,
        description="names the run directory and the progress bar (letters, digits, _ . + = -)",
    )
    # Where agents run: not part of the results (config.yaml leaves these out, deployment.json
    # records them), so the same experiment gives the same files wherever its agents run.
    placement: dict[str, str | int | list[int]] = Field(
        default_factory=dict,
        exclude=True,
        description="host name -> agent ids ('0-9,12', 7 or [1, 2]); the others run on the launching machine",
    )
    swaps: list[SwapEntry] = Field(
        default_factory=list, exclude=True, description="scripted moves of agents between hosts before given ticks"
    )
    may_carry: dict[str, str | int | list[int]] = Field(
        default_factory=dict,
        exclude=True,
        description="host name -> more agent ids ('0-9,12') that a swap asked for during the run may move to it; "
        "a host identity may carry only these, the agents placed on it and those scripted swaps move to it",
    )
    run: RunSection = RunSection()
    scenario: ScenarioSection = ScenarioSection()
    agents: AgentsSection = AgentsSection()
    allocator: AllocatorSection = AllocatorSection()
    network: NetworkSection = NetworkSection()
    ros2: Ros2Section | None = Field(
        None, exclude=True, description="publish poses, tasks, inboxes and /clock as ROS 2 topics; null: off"
    )
    radio_split: RadioSplit = Field(
        RadioSplit(), exclude=True, description="the radio decided by several netem proxies, by region of the arena"
    )
    obstacles: ObstaclesSection | None = Field(
        None, description="walls and polygons that block motion, sight and the radio (docs/walls.md); null: open ground"
    )
    #: what the launcher resolved the scenario and allocator names to when it checked this experiment
    #: (``swarmbed.config.resolve_experiment`` reads it; never serialised)
    _resolved: Any = PrivateAttr(default=None)

    @property
    def ticks(self) -> int:
        return int(round(self.run.duration / self.run.dt))

    @model_validator(mode="after")
    def _materials_known(self) -> Experiment:
        if self.obstacles is not None:
            table = (self.network.walls or WallsSection()).loss_db
            for material in self.obstacles.materials():
                if material not in table:
                    raise ValueError(
                        f"obstacles: material {material!r} has no loss in network.walls.loss_db "
                        f"(known: {', '.join(sorted(table)) or 'none'})"
                    )
        return self

    @model_validator(mode="after")
    def _splittable(self) -> Experiment:
        if self.radio_split.shards == 1:
            return self
        n = self.network
        present = {
            "network.draws: sequential": n.draws == "sequential",
            "network.propagation": n.propagation is not None,
            "network.burst": n.burst is not None,
            "network.delay": n.delay is not None,
            "network.channel": n.channel is not None,
            "network.ledger: per_receiver": n.ledger == "per_receiver",
            "run.clock: realtime": self.run.clock == "realtime",
            "ros2": self.ros2 is not None,
        }
        for what, why in SPLIT_REFUSES.items():
            if present[what]:
                raise ValueError(f"a radio split over {self.radio_split.shards} proxies cannot go with {what} ({why})")
        return self

    @model_validator(mode="after")
    def _bounded(self) -> Experiment:
        if self.run.duration / self.run.dt > MAX_TICKS:
            raise ValueError(
                f"run.duration / run.dt is {self.run.duration / self.run.dt:.3g} ticks, more than the "
                f"{MAX_TICKS:,} a run may have"
            )
        if self.ticks < 1:
            raise ValueError(
                f"run.duration {self.run.duration:g} s with run.dt {self.run.dt:g} s makes 0 ticks: "
                "a run needs a duration of at least one tick"
            )
        return self


class Targets(Strict):
    """The code a run's names resolved to, as ``module:Class`` (or ``path/file.py:Class``)."""

    scenario: str
    allocator: str
    #: file -> sha256 of its bytes as the launcher checked it, for every ``path/file.py`` target: a
    #: process elsewhere (a host daemon's agent) refuses a file of that path that differs
    digests: dict[str, str] = Field(default_factory=dict)


class AgentSpec(Strict):
    """Everything an agent process needs, and nothing else."""

    seed: int
    dt: float
    agents: AgentsSection
    scenario: ScenarioSection
    allocator: AllocatorSection
    targets: Targets
    record_bt: bool = False  # hand the coordinator every tick's tree status changes


class NetemSpec(Strict):
    """Everything the netem proxy needs: its radio parameters, the run's size and seed, and, on the
    real-time clock, how long after a tick starts it stops waiting for agents (wall seconds)."""

    seed: int
    dt: float
    agents: int
    network: NetworkSection
    answer_within: float | None = None
    ros2: Ros2Section | None = None  # publish what each robot sent as ROS 2 topics
    obstacles: ObstaclesSection | None = None  # the walls the radio's copies may cross
    split: RadioSplit = RadioSplit()  # the proxies the radio is split over (each is told its own index)
    # host -> the agents whose outputs its relay may send on (the hub's access rules hold the host
    # to them); None: the run has no access control, and any host may send any agent's
    carriers: dict[str, list[int]] | None = None


def agent_spec(exp: Experiment, targets: Targets) -> AgentSpec:
    return AgentSpec(
        seed=exp.run.seed,
        dt=exp.run.dt,
        agents=exp.agents,
        scenario=exp.scenario,
        allocator=exp.allocator,
        targets=targets,
        record_bt=exp.run.record_bt,
    )


def netem_spec(exp: Experiment, carried: Mapping[str, Iterable[int]] | None = None) -> NetemSpec:
    """``carried``: the hosts' :func:`carriers`, in a run with access control."""
    r = exp.run
    within = r.deadline * r.dt / r.speed if r.clock == "realtime" else None
    return NetemSpec(
        seed=r.seed,
        dt=r.dt,
        agents=exp.agents.count,
        network=exp.network,
        answer_within=within,
        ros2=exp.ros2,
        obstacles=exp.obstacles,
        split=exp.radio_split,
        carriers=None if carried is None else {host: sorted(ids) for host, ids in carried.items()},
    )
