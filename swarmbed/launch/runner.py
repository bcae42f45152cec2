"""``swarmbed run``: one experiment, end to end, on this machine.

Opens the run's Zenoh hub (the coordinator listens on a free loopback port, multicast scouting off),
launches the netem proxy and one process per agent as clients of it, waits until all of them hold a
liveliness token, runs the lock-step loop, stops everyone and writes the results.
"""

from __future__ import annotations

import os
import secrets
import time
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import zenoh
from tqdm import tqdm

from swarmbed.config import Experiment, Resolved, resolve_experiment, to_yaml
from swarmbed.coordinator.zenoh_transport import ZenohTransport
from swarmbed.engine import Session, TickHook, results
from swarmbed.engine.run_errors import RunError
from swarmbed.files import safefiles
from swarmbed.launch.access import RunAccess
from swarmbed.launch.host_client import HostError, host_info, wait_for_hosts
from swarmbed.launch.hub import LOOPBACK_ONLY, HubOptions, open_hub
from swarmbed.launch.launcher import (
    ChildExited,
    Children,
    ForkServerError,
    own_cpu_s,
    peak_rss_mb,
    reset_peak_rss,
    wakeups,
    zenoh_env,
)
from swarmbed.launch.placement import AgentPlacement
from swarmbed.launch.provenance import FILE as PROVENANCE
from swarmbed.launch.provenance import provenance
from swarmbed.netem import radio_split
from swarmbed.records.rowfile import PARTIAL_PREFIX, TableWriteError, keep_partial
from swarmbed.records.run_folder import BT, DEPLOYMENT, RESULT_FILES
from swarmbed.schema.experiment import LOCAL, carriers, hosts_of
from swarmbed.wire.control import HostInfo
from swarmbed.wire.keys import Keys, proxy_name


@dataclass
class LiveRun:
    """A run under way, as an observer sees it (soak monitors and chaos): the coordinator (read
    its counters, ask it to stop), the local child processes, the hub session and the keys."""

    exp: Experiment
    out_dir: Path
    coordinator: ZenohTransport
    children: Children
    session: zenoh.Session
    keys: Keys
    hosts: dict[str, HostInfo | None]  # host name -> what its daemon said of itself (cores, memory, pid)


#: what makes, from a run's session, a hook that shows the run as it goes
View = Callable[[Session], TickHook]


class RunObserver(Protocol):
    def start(self, run: LiveRun) -> None: ...

    def stop(self) -> None:
        """The ticks are over (or the run failed): finish, undo anything done to the processes."""


@dataclass
class RunResult:
    out_dir: Path
    summary: dict  # summary.json's document (RunDir(out_dir).summary() reads it typed)
    timings: dict


@dataclass(frozen=True)
class RunPlan:
    """What a run is, decided before any process starts: the experiment with the classes its names
    resolved to, the run's keys (a fresh run id), where every agent runs, and how its hub is
    reached. A bad plugin name or placement fails here, with nothing started and no file touched."""

    exp: Experiment
    resolved: Resolved
    out_dir: Path
    keys: Keys
    where: dict[int, str]  # agent id -> host name, LOCAL for this machine
    hub: HubOptions

    @property
    def remote_hosts(self) -> list[str]:
        return sorted({h for h in self.where.values() if h != LOCAL})


def plan_run(exp: Experiment, out_dir: Path, hub: HubOptions = LOOPBACK_ONLY) -> RunPlan:
    """The plan of a validated experiment (:func:`swarmbed.config.load` checked
    its placement and names)."""
    where = hosts_of(exp.placement, exp.agents.count)
    plan = RunPlan(exp, resolve_experiment(exp), out_dir, Keys(secrets.token_hex(6)), where, hub)
    admitted = {i.host_name for i in hub.admit if i.role == "host"}
    refused = [h for h in plan.remote_hosts if hub.auth and h not in admitted]
    if refused:  # it could be up and would still never get in: say so now, not "not reachable" later
        raise RunError(
            f"placement names host(s) {', '.join(refused)}, which this run does not admit: give swarmbed run "
            "--admit FILE with each host's credentials file (swarmbed credentials FILE --user NAME --role host)"
        )
    return plan


def start_result_dir(plan: RunPlan) -> None:
    """The run's folder with its configuration and provenance, and no result of an earlier run in it:
    a stale summary must never vouch for a new, unfinished run."""
    out_dir, resolved = plan.out_dir, plan.resolved
    safefiles.make_folder(out_dir)
    for name in RESULT_FILES:
        safefiles.remove(out_dir / name)
        safefiles.remove(out_dir / (PARTIAL_PREFIX + name))
    safefiles.remove_tree(out_dir / BT)  # a link planted in a received folder is removed, never followed
    safefiles.make_dirs(out_dir, out_dir / "logs")
    results.write_atomic(out_dir / results.CONFIG, to_yaml(plan.exp))
    results.write_json(
        out_dir / PROVENANCE,
        provenance(
            resolved.scenario_cls, resolved.targets.scenario, resolved.allocator_cls, resolved.targets.allocator
        ),
    )


def run_experiment(
    exp: Experiment,
    out_dir: Path,
    progress: bool = True,
    on_ready: Callable[[Keys, str], None] | None = None,
    hub: HubOptions = LOOPBACK_ONLY,
    fork_agents: bool = True,
    observers: Sequence[RunObserver] = (),
    decider: Any = None,
    views: Sequence[View] = (),
) -> RunResult:
    """Run ``exp`` into ``out_dir``. ``on_ready(keys, endpoint)`` is called once everyone joined
    (tests use it to reach the run's keys from outside). ``hub``: where the hub listens and whom it
    admits (:class:`HubOptions`; by default loopback only, the run's own processes, each held to its
    own keys by :mod:`.access`). ``fork_agents``: local agents come from a fork server that imported
    everything once (:mod:`.forkserver`); without it each is a fresh interpreter. ``observers``
    are started once everyone joined and stopped when the ticks are over (:mod:`.soak`). ``decider``:
    for an allocator that takes its decisions from the launching process (``external``), what makes
    them each tick (:mod:`swarmbed.envs`). ``views``: each makes, from the run's session, a hook
    that shows the run as it goes (a live Foxglove server, :mod:`swarmbed.results.foxglove_live`)."""
    plan = plan_run(exp, out_dir, hub)
    with safefiles.rooted(out_dir):  # every file of the run reached from one handle on its folder
        start_result_dir(plan)
        return _execute(plan, progress, on_ready, fork_agents, observers, decider, views)


@dataclass
class _Setup:
    """What a run sets up before its processes start, each undone by ``_execute``'s ``finally``."""

    access: RunAccess | None
    children: Children
    session: zenoh.Session
    endpoint: str
    placement: AgentPlacement
    coord: ZenohTransport
    run: Session
    t_server: float  # when the fork server was up
    identity: Callable[[str], list[str]]  # a process's credentials arguments


def _set_up(plan: RunPlan, fork_agents: bool, decider: Any) -> _Setup:
    """The run's identities, its fork server, the hub's session and the coordinator; if a step
    fails, what the steps before it made is undone before the error leaves."""
    exp, options, keys = plan.exp, plan.hub, plan.keys
    listen = list(options.listen)
    with ExitStack() as undo:
        access = (
            RunAccess(
                keys,
                range(exp.agents.count),
                options.admit,
                carriers(exp),
                ros2_domain=exp.ros2.domain if exp.ros2 else None,
                proxies=exp.radio_split.shards,
            )
            if options.auth
            else None
        )
        if access:
            undo.callback(access.close)
        # the fork server first: it is spawned, never forked, but it needs no session of ours
        try:
            children = Children(plan.out_dir / "logs", fork_agents=fork_agents, env=zenoh_env(exp.run.zenoh_threads))
        except ForkServerError as exc:
            raise RunError(str(exc)) from None
        t_server = time.perf_counter()
        undo.callback(children.kill_all)
        # every agent connects at about the same moment (the fork server starts hundreds a second):
        # the hub must take that many handshakes at once, and that many sessions
        capacity = {
            "transport/unicast/accept_pending": max(100, exp.agents.count + 16),
            "transport/unicast/max_sessions": max(1000, exp.agents.count + 64),
        }
        session, endpoint = open_hub(
            listen, settings={**capacity, **(access.hub_settings() if access else {}), **(options.tls or {})}
        )
        undo.callback(session.close)
        logs = ["--log-max-mb", str(exp.run.log_max_mb), "--log-backups", str(exp.run.log_backups)]

        def identity(process: str) -> list[str]:
            return ["--credentials", access.credentials(process)] if access else []

        placement = AgentPlacement(
            children,
            session,
            keys,
            common=["--run-id", keys.run_id, "--connect", endpoint, *logs],
            log_rotation=(exp.run.log_max_mb, exp.run.log_backups),
            identity=identity,
            hub=listen[0] if listen else endpoint,
            auth=access is not None,
            join_timeout=exp.run.join_timeout,
        )
        resolved = plan.resolved
        scenario = resolved.scenario()
        run = Session(exp, scenario, resolved.allocator_cls, plan.out_dir)
        coord = ZenohTransport(
            exp,
            scenario,
            run.world,
            run.recorder,
            resolved.allocator_cls,
            resolved.targets,
            keys,
            session,
            plan.out_dir,
            plan.where,
            carriers(exp) if access else None,
            placement,
            decider,
            radio_split,
        )
        undo.pop_all()
    return _Setup(access, children, session, endpoint, placement, coord, run, t_server, identity)


def _start_processes(plan: RunPlan, setup: _Setup) -> dict[str, Any]:
    """The proxy and the local agents started, the remote hosts waited for and given their agents;
    returns each remote host's information."""
    exp, children, placement = plan.exp, setup.children, setup.placement
    try:
        shards = exp.radio_split.shards
        for shard in range(shards):  # a split radio's proxy i>0 logs to logs/netem-i.log
            args = [*placement.common, *setup.identity(proxy_name(shard)), "--out", str(plan.out_dir.resolve())]
            args += ["--shard", str(shard)]
            if shards > 1 and plan.hub.remote_proxy is not None:
                children.adopt(proxy_name(shard), plan.hub.remote_proxy(shard, args))
            else:
                children.spawn(proxy_name(shard), "swarmbed.netem", args)
        for i in range(exp.agents.count):
            if plan.where[i] == LOCAL:
                placement.first(i)
    except ForkServerError as exc:
        raise RunError(str(exc)) from None
    hosts: dict[str, HostInfo | None] = {}
    if plan.remote_hosts:
        try:
            wait_for_hosts(
                setup.session, plan.remote_hosts, exp.run.join_timeout, placement.hub, auth=setup.access is not None
            )
            for host in plan.remote_hosts:
                hosts[host] = host_info(setup.session, host)
                placement.on_host(host, [i for i, h in plan.where.items() if h == host])
        except HostError as exc:
            raise RunError(str(exc)) from None
    return hosts


def progress_bar(exp: Experiment, progress: bool) -> tuple[Any, Callable[[int, float], None]]:
    """A bar of simulated seconds and the tick callback that moves it (every 1/200 of the run). With
    ``run.stop_when_done`` the run may end before ``run.duration``: the bar says so, since it counts
    to the duration (the quick start's world is done at 234 of 2000 s)."""
    sooner = " (at most: ends when the world is done)" if exp.run.stop_when_done else ""
    bar = tqdm(
        total=exp.run.duration,
        unit="sim s",
        desc=exp.name,
        disable=not progress,
        leave=False,
        bar_format="{l_bar}{bar}| {n:.0f}/{total:.0f} sim s" + sooner + " [{elapsed}<{remaining}]",
    )
    shown = [0.0]

    def on_tick(_tick: int, sim_time: float) -> None:
        if sim_time - shown[0] >= exp.run.duration / 200:
            bar.update(sim_time - shown[0])
            shown[0] = sim_time

    return bar, on_tick


def _host_documents(hosts: dict[str, HostInfo | None]) -> dict[str, dict[str, Any] | None]:
    """deployment.json's ``hosts``: what each host said of itself, as it said it."""
    return {h: info.model_dump() if info is not None else None for h, info in hosts.items()}


def _record_swaps(plan: RunPlan, setup: _Setup, deployment: dict[str, Any], hosts: dict[str, HostInfo | None]) -> None:
    """After a run whose agents moved: where each ran at the end, and what each host ran then."""
    agents = setup.coord.agents
    for host in sorted({h for h in agents.hosts.values() if h != LOCAL}):
        hosts[host] = host_info(setup.session, host) or hosts.get(host)
    results.write_json(
        plan.out_dir / DEPLOYMENT,
        {
            **deployment,
            "hosts": _host_documents(hosts),
            "placement_at_end": {str(i): agents.hosts.get(i, LOCAL) for i in range(plan.exp.agents.count)},
        },
    )


def _execute(
    plan: RunPlan,
    progress: bool,
    on_ready: Callable[[Keys, str], None] | None,
    fork_agents: bool,
    observers: Sequence[RunObserver],
    decider: Any = None,
    views: Sequence[View] = (),
) -> RunResult:
    exp, out_dir, keys = plan.exp, plan.out_dir, plan.keys
    t_start = time.perf_counter()
    hub_cpu_before = own_cpu_s()  # a sweep's pool worker hosts one run after another: count this one's
    reset_peak_rss()
    setup = _set_up(plan, fork_agents, decider)
    access, children, session, endpoint, coord = (
        setup.access,
        setup.children,
        setup.session,
        setup.endpoint,
        setup.coord,
    )
    try:
        coord.declare()
        hosts = _start_processes(plan, setup)
        t_spawned = time.perf_counter()
        deployment = {
            "run_id": keys.run_id,
            "hub": [endpoint, *plan.hub.listen],
            "placement": {str(i): h for i, h in plan.where.items()},
            "hosts": _host_documents(hosts),
            **({"ros2": exp.ros2.model_dump(mode="json")} if exp.ros2 else {}),
            **({"radio_split": exp.radio_split.model_dump()} if exp.radio_split.shards > 1 else {}),
        }
        results.write_json(out_dir / DEPLOYMENT, deployment)
        try:
            coord.wait_for_members(children.check)
        except ChildExited as exc:
            raise RunError(str(exc)) from None
        t_joined = time.perf_counter()
        if on_ready:
            on_ready(keys, endpoint)

        bar, on_tick = progress_bar(exp, progress)
        live = LiveRun(exp, out_dir, coord, children, session, keys, hosts)
        running: list[RunObserver] = []
        try:
            for observer in observers:
                observer.start(live)
                running.append(observer)
            loop_start = _tick_costs(children)
            shown = [view(setup.run) for view in views]
            setup.run.connect(coord, coord.agents, coord.hooks() + shown, coord.stages)
            setup.run.run(on_tick)
            loop_end = _tick_costs(children)
            if coord.agents.swap_log:
                _record_swaps(plan, setup, deployment, hosts)
        finally:
            bar.close()
            for observer in reversed(running):
                observer.stop()
        marks = {"start": t_start, "server": setup.t_server, "spawned": t_spawned, "joined": t_joined}
        usage = _usage(children)  # read while the agents still run
        coord.stop_and_collect()
        exit_codes = children.wait(timeout=15.0)
        timings = _timings(usage, coord, marks, hub_cpu_before, children.forked, exit_codes)
        timings.update(run_id=keys.run_id, endpoint=endpoint, auth=access is not None)
        if coord.decision_source == "ros2":  # robot-ticks without a ROS 2 decision in time: not reproducible
            timings["ros2_command_timeouts"] = coord.commands.timeouts
        timings["per_agent_tick"] = _per_agent_tick(loop_start, loop_end, exp.agents.count, coord.last_tick + 1)
        return RunResult(out_dir, coord.write_results(setup.run, timings).document, timings)
    except TableWriteError as exc:  # a full disk: one line, the first error, not what clean-up meets next
        raise RunError(str(exc)) from None
    finally:
        setup.placement.stop_all()
        children.kill_all()
        coord.close()
        session.close()
        if access:
            access.close()
        _keep_no_torn_result(coord, out_dir)


def _tick_costs(children: Children) -> dict[str, dict[str, float]]:
    """Wake-ups and CPU seconds so far by process kind (agents, netem, hub: the coordinator's own
    process, which holds the hub's router), to be differenced over the tick loop."""
    kinds: dict[str, dict[str, float]] = {k: {"wakeups": 0.0, "cpu_s": 0.0} for k in ("agents", "netem", "hub")}
    cpu, woke = children.cpu_s(), children.wakeups()
    for name in set(cpu) | set(woke):
        kind = "netem" if name.split("-")[0] == "netem" else "agents" if name.startswith("agent_") else None
        if kind:
            kinds[kind]["wakeups"] += woke.get(name, 0)
            kinds[kind]["cpu_s"] += cpu.get(name, 0.0)
    kinds["hub"] = {"wakeups": float(wakeups(os.getpid())), "cpu_s": own_cpu_s()}
    return kinds


def _per_agent_tick(start: dict, end: dict, agents: int, ticks: int) -> dict:
    """What one agent-tick cost over the tick loop, by process kind and in all: wake-ups (voluntary
    context switches of every thread) and CPU microseconds. Agents that left or joined during the
    loop (loss, swaps) make the differences approximate; the run's other figures are exact."""
    n = max(1, agents * ticks)
    out: dict[str, dict[str, float]] = {"wakeups": {}, "cpu_us": {}}
    for kind in ("agents", "netem", "hub"):
        out["wakeups"][kind] = (end[kind]["wakeups"] - start[kind]["wakeups"]) / n
        out["cpu_us"][kind] = (end[kind]["cpu_s"] - start[kind]["cpu_s"]) * 1e6 / n
    for figure in out.values():
        figure["total"] = sum(figure.values())
    return out


def _usage(children: Children) -> dict[str, dict]:
    """Memory and CPU of every child process (and the coordinator's peak), by process name."""
    peak = children.peak_rss_mb()
    peak["coordinator"] = peak_rss_mb(os.getpid())
    return {"rss": children.rss_mb(), "shared": children.shared_mb(), "peak": peak, "cpu": children.cpu_s()}


def _timings(
    usage: dict[str, dict],
    coord: ZenohTransport,
    marks: dict[str, float],
    hub_cpu_before: float,
    forked: bool,
    exit_codes: dict[str, int | None],
) -> dict:
    """What the run cost: wall time by phase, memory and CPU by process kind (timings.json)."""
    rss, peak, cpu = usage["rss"], usage["peak"], usage["cpu"]
    shared = {k: v for k, v in usage["shared"].items() if k.startswith("agent_")}
    agent_cpu = [v for k, v in cpu.items() if k.startswith("agent_")]
    agent_rss = [v for k, v in rss.items() if k.startswith("agent_")]
    proxy_cpu = [v for k, v in cpu.items() if k.split("-")[0] == "netem"]  # netem, netem-1, ...: a split radio
    run_s = coord.wall["run_s"]
    return {
        "run_s": run_s,
        "ticks_per_s": (coord.last_tick + 1) / run_s if run_s > 0 else None,
        "startup_s": marks["joined"] - marks["start"],
        "total_s": time.perf_counter() - marks["start"],
        "rss_mb": rss,
        "peak_rss_mb": peak,
        "cpu_s": {
            "coordinator": own_cpu_s() - hub_cpu_before,
            "netem": sum(proxy_cpu) if proxy_cpu else None,
            **({"netem_max": max(proxy_cpu)} if len(proxy_cpu) > 1 else {}),
            "agents_total": sum(agent_cpu),
            "agent_max": max(agent_cpu, default=None),
        },
        "agent_rss_mb_mean": sum(agent_rss) / len(agent_rss) if agent_rss else None,
        "agent_pss_mb_mean": sum(p for p, _ in shared.values()) / len(shared) if shared else None,
        "agent_uss_mb_mean": sum(u for _, u in shared.values()) / len(shared) if shared else None,
        "startup": {
            "fork_server_s": marks["server"] - marks["start"] if forked else None,
            "spawn_s": marks["spawned"] - marks["server"],
            "join_s": marks["joined"] - marks["spawned"],
        },
        "exit_codes": exit_codes,
    }


def _keep_no_torn_result(coord: ZenohTransport, out_dir: Path) -> None:
    """A run that did not complete leaves no half-written file under a result's name: the rows it
    streamed are kept as partial_<name> once ticks ran (readable, for a post-mortem)."""
    coord.abandon_tables()
    for partial in out_dir.glob("*.part"):
        if coord.last_tick >= 0:
            keep_partial(partial)
        else:
            safefiles.remove(partial)
    if not (out_dir / results.SUMMARY).exists():  # results written before a failure at the very end
        for name in RESULT_FILES:
            if name != DEPLOYMENT and (out_dir / name).exists():
                safefiles.rename(out_dir / name, out_dir / (PARTIAL_PREFIX + name))
