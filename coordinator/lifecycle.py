"""The lives of a run's agent processes, as the coordinator keeps them: which agents are up, down
(their process died and a restart is due) or lost; moving an agent to another host (a swap);
starting a dead one again, from its last checkpoint or fresh (``run.on_agent_loss: restart``);
and asking for the checkpoints.

A process is one *incarnation* of an agent: the first is 0, each swap or restart try makes the
next. State is accepted only when the coordinator asked for it (:mod:`.tickets`). Processes are
started and stopped through the :class:`~swarmbed.coordinator.process_control.Placement` the launcher
gives; as a hook of the engine's tick loop it swaps, restarts and checkpoints before each tick.
"""

from __future__ import annotations

import logging
import queue
import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
import zenoh

from swarmbed.coordinator.events import CONSUMED, EventQueue
from swarmbed.coordinator.process_control import Placement
from swarmbed.coordinator.tickets import Tickets
from swarmbed.engine.hooks import TickHook
from swarmbed.engine.run_errors import RunError
from swarmbed.extension.scenario import World
from swarmbed.schema.experiment import LOCAL, Experiment
from swarmbed.wire.child_process import process_name
from swarmbed.wire.codec import (
    TAG_CHECKPOINT,
    TAG_RESUME,
    TAG_RETIRE,
    TAG_SNAPSHOT,
    WireError,
    decode_handover,
    encode_control,
    encode_stop,
)
from swarmbed.wire.control import (
    AgentReport,
    Checkpoint,
    Fatal,
    RestartRecord,
    SwapAnswer,
    SwapPending,
    SwapQuery,
    SwapQueued,
    SwapRecord,
    SwapRefused,
    decode_swap,
    encode_swap_answer,
)
from swarmbed.wire.keys import Keys, agent_id_of, incarnation_of

log = logging.getLogger("swarmbed.coordinator")


#: swap requests an operator may have waiting at once, and in one run (a flood is refused, not queued)
MAX_QUEUED_SWAPS = 16
MAX_SWAPS_PER_RUN = 10_000


class AgentLifecycle(TickHook):
    """Which agents are up, down or lost, and the swaps, restarts and checkpoints that move them:
    the run's :class:`~swarmbed.engine.Membership` over processes, and the hook that swaps,
    restarts and checkpoints before a tick's world sample."""

    def __init__(
        self,
        exp: Experiment,
        keys: Keys,
        world: World,
        events: EventQueue,
        hosts: dict[int, str],
        carriers: Mapping[str, frozenset[int]] | None,
        placement: Placement | None,
        decode_report: Callable[[str, bytes], AgentReport | None],
        malformed: Callable[[str, Exception], None],
    ) -> None:
        self.exp = exp
        self.keys = keys
        self.world = world
        self.events = events
        self.n = exp.agents.count
        self.hosts = hosts  # agent -> host it runs on, where not on this machine
        # host -> agents the hub lets it carry (wire.schema.carriers); None: no access control
        self.carriers = carriers
        self.placement = placement
        self.decode_report = decode_report
        self.malformed = malformed
        self.agent_pubs: list[zenoh.Publisher] = []  # set once the coordinator declared them
        self.lost: dict[int, int] = {}  # agent -> tick at which it was lost
        self.retired: set[int] = set()  # lost by the scenario (agent loss), not by a crash
        self.fatal: dict[int, Fatal] = {}  # agent -> the report of the exception its plugin raised
        # moving agents between processes (swaps)
        self.incarnation: dict[int, int] = {}  # agent -> its current process, where not the first (0)
        self.snapshots: dict[int, bytes] = {}  # agent -> the snapshot its old process handed over
        self.tickets = Tickets()  # what state the coordinator asked for, and of whom
        self.swaps_due: dict[int, list[tuple[int, str]]] = {}  # tick -> (agent, host), scripted
        for entry in exp.swaps:
            self.swaps_due.setdefault(entry.tick, []).append((entry.agent, entry.to))
        self.swap_requests: queue.SimpleQueue[tuple[int, str, int]] = queue.SimpleQueue()  # (agent, host, number)
        self.swap_log: list[SwapRecord] = []
        self.requested_swaps: dict[int, SwapRecord | None] = {}  # number -> its record once done
        # agents whose process died, started again (run.on_agent_loss: restart)
        self.down: dict[int, int] = {}  # agent -> tick its process was found dead, until it is restarted
        self.restart_tries: dict[int, tuple[int, float]] = {}  # agent down -> (failed tries, next try, monotonic s)
        self.checkpoints: dict[int, tuple[int, bytes]] = {}  # agent -> (tick, state) of its last checkpoint
        self.checkpoint_tick = -1
        self.restart_log: list[RestartRecord] = []

    # -- what the tick loop asks ------------------------------------------------------------------
    def before_world(self, k: int) -> None:
        self.due(k)

    def incarnations(self) -> dict[int, int]:
        return {a: i for a, i in self.incarnation.items() if i}

    def gone(self, agent: int, k: int) -> None:
        self.lose(agent, k, self.how_it_ended(agent))

    def how_it_ended(self, agent: int) -> str:
        """Why agent ``agent``'s process is gone, as precisely as this machine can tell (a process on
        another host: only that it exited)."""
        if agent in self.fatal or self.placement is None or self.hosts.get(agent, LOCAL) != LOCAL:
            return "its process exited"
        how = self.placement.exit_status(self.process_name(agent)).split(";", 1)[0]
        return f"its process {how.split(' ', 1)[1]}" if how else "its process exited"

    def due(self, k: int) -> None:
        """Before tick ``k``: the swaps due, the restarts due and, every ``run.snapshot_every``
        ticks of a run that restarts its agents, the checkpoints."""
        r = self.exp.run
        self._swap_due(k)
        self._restart_due(k)
        if r.snapshot_every and k % r.snapshot_every == 0 and r.agent_loss == "restart":
            self._ask_checkpoints(k)

    def process_name(self, agent: int) -> str:
        return process_name(agent, self.incarnation.get(agent, 0))

    def log_of(self, agent: int) -> str:
        host = self.hosts.get(agent, "local")
        if host == "local":
            return f"logs/agent_{agent}.log"
        return f"agent_{agent}.log in the logs of host {host} (run {self.keys.run_id})"

    def lose(self, agent: int, tick: int, why: str) -> None:
        """Agent ``agent``'s process stopped at ``tick`` because ``why``: end the run, mark it down
        for a restart, or lose it, as ``run.on_agent_loss`` says."""
        if agent in self.lost or agent in self.down:
            return
        fatal = self.fatal.get(agent)
        detail = f"\n{fatal.error}\n{fatal.traceback}" if fatal else ""
        policy = self.exp.run.agent_loss
        if policy == "fail":
            # a plugin that raised would raise again: restarting it is not offered
            hint = "continue to go on without it" if fatal else "continue or restart to go on"
            raise RunError(
                f"agent {agent} stopped at tick {tick} because {why}; see {self.log_of(agent)}"
                f" (set run.on_agent_loss to {hint}){detail}"
            )
        if policy == "restart" and fatal is None and self.placement is not None:
            # a crashed process is started again at the next tick; a plugin that raised would raise again
            log.warning("coordinator: agent %d lost at tick %d (%s); restarting it", agent, tick, why)
            self.down[agent] = tick
            return
        self.lost[agent] = tick
        self.world.kill(agent)

    def retire(self, agent: int, tick: int) -> None:
        """Scheduled agent loss: the robot is gone from ``tick`` on and its process is stopped."""
        self.lost[agent] = tick
        self.retired.add(agent)
        self.world.kill(agent)
        self.agent_pubs[agent].put(encode_stop("agent lost"))

    def end(self) -> None:
        """The ticks are over: an agent still down died in the last tick and is never restarted."""
        for agent, tick in sorted(self.down.items()):
            self.lost[agent] = tick
        self.down.clear()

    def on_checkpoint(self, agent: int, rep: Checkpoint) -> None:
        if not self.tickets.redeem("checkpoint", agent, rep.ticket):
            # late (a newer checkpoint was asked since) or not asked for at all: never kept
            log.warning("coordinator: refused a checkpoint of agent %d that was not asked for", agent)
        elif rep.incarnation == self.incarnation.get(agent, 0):
            self.checkpoints[agent] = (self.checkpoint_tick, rep.state)

    # -- Zenoh callbacks (they only put events) ------------------------------------------------------
    def on_snapshot_query(self, query: zenoh.Query) -> None:
        """An old process hands its snapshot over (payload), or the new one fetches it (none)."""
        try:
            agent = agent_id_of(str(query.key_expr))
        except ValueError:
            query.reply_err("no agent in the key")
            return
        if query.payload is not None:
            try:
                ticket, state = decode_handover(query.payload.to_bytes())
            except WireError as exc:
                self.malformed(str(query.key_expr), exc)
                query.reply_err(f"malformed snapshot handover: {exc}")
                return
            if not self.tickets.redeem("snapshot", agent, ticket):
                log.warning("coordinator: refused a snapshot of agent %d that was not asked for", agent)
                query.reply_err(f"no snapshot of agent {agent} was asked for")
                return
            self.snapshots[agent] = state
            query.reply(query.key_expr, b"ok")
            self.events.put(("snapshot", agent))
        elif agent in self.snapshots:
            query.reply(query.key_expr, self.snapshots[agent])
        else:
            query.reply_err(f"no snapshot of agent {agent} is held")

    def on_swap_query(self, query: zenoh.Query) -> None:
        """``{"agent": I, "to": HOST}`` queues a swap before the next tick and answers its number;
        ``{"swap": N}`` answers swap N's record once it is done (``{"pending": true}`` before)."""
        try:
            req = decode_swap(query.payload.to_bytes() if query.payload is not None else None)
            answer: SwapAnswer
            if isinstance(req, SwapQuery):
                record = self.requested_swaps.get(req.swap)
                answer = record if record is not None else SwapPending(pending=True)
            elif req.agent < self.n:
                self._check_carrier(req.agent, req.to)
                if self.swap_requests.qsize() >= MAX_QUEUED_SWAPS:
                    raise WireError(f"{MAX_QUEUED_SWAPS} swaps are already waiting; ask again after they are done")
                if len(self.requested_swaps) >= MAX_SWAPS_PER_RUN:
                    raise WireError(f"this run took {MAX_SWAPS_PER_RUN} swap requests already")
                number = len(self.requested_swaps)
                self.requested_swaps[number] = None
                self.swap_requests.put((req.agent, req.to, number))
                answer = SwapQueued(queued=number)
            else:
                raise WireError(f"agent {req.agent} is not one of this run's 0..{self.n - 1}")
        except WireError as exc:
            answer = SwapRefused(error=f'{exc} (a swap request is {{"agent": 0..{self.n - 1}, "to": HOST}})')
        query.reply(query.key_expr, encode_swap_answer(answer))

    def _check_carrier(self, agent: int, to: str) -> None:
        """A WireError, before a swap is queued, for a host that is not one of the run's or may not
        carry ``agent`` (the hub would refuse it the agent's keys)."""
        if to == LOCAL or self.carriers is None or agent in self.carriers.get(to, ()):
            return
        able = sorted(host for host, ids in self.carriers.items() if agent in ids)
        known = (
            f"host {to!r} may not carry agent {agent}" if to in self.carriers else f"{to!r} is not a host of this run"
        )
        raise WireError(
            f"{known}; agent {agent} may move to {', '.join([LOCAL, *able])} (placement, swaps and may_carry "
            "name the hosts and agents a run admits)"
        )

    # -- checkpoints and restarts (run.on_agent_loss: restart) ---------------------------------------
    def _ask_checkpoints(self, k: int) -> None:
        """Every live agent reports its state before tick ``k`` (kept, the last of each, to restart it)."""
        self.checkpoint_tick = k
        for i in map(int, np.flatnonzero(self.world.alive)):
            if i not in self.lost and i not in self.down:
                incarnation = self.incarnation.get(i, 0)
                ticket = self.tickets.issue("checkpoint", i, incarnation)
                self.agent_pubs[i].put(encode_control(TAG_CHECKPOINT, incarnation, ticket))

    def _restart_due(self, k: int) -> None:
        """Try each agent that is down and due: a failed try is tried again after
        ``run.restart_backoff`` wall seconds (doubling) while ticks go on without it, until
        ``run.restart_attempts`` tries have failed; then it is lost."""
        r = self.exp.run
        for agent in sorted(self.down):
            tries, due = self.restart_tries.get(agent, (0, 0.0))
            if time.monotonic() < due:
                continue
            record = self._restart(agent, k, tries)
            tries += 1
            self.restart_log.append(record)
            if record.outcome == "ok":
                self.restart_tries.pop(agent, None)
            elif tries < r.restart_attempts:
                record.outcome = "retrying"
                self.restart_tries[agent] = (tries, time.monotonic() + r.restart_backoff * 2 ** (tries - 1))
            else:
                self.restart_tries.pop(agent, None)
                lost_at = self.down.pop(agent)
                self.lost[agent] = lost_at
                self.world.kill(agent)

    def _restart(self, agent: int, k: int, failed_tries: int = 0) -> RestartRecord:
        """Start agent ``agent`` again before tick ``k``, under its id, on its host: from its last
        checkpoint if there is one, else fresh. Messages to it while it was gone were booked
        ``receiver_dead`` by the proxy. Each try is a new incarnation: a failed try's process,
        should it join late, is never taken for this one."""
        t0 = time.perf_counter()
        new = self.incarnation.get(agent, 0) + 1 + failed_tries
        host = self.hosts.get(agent, LOCAL)
        checkpoint = self.checkpoints.get(agent)
        record = RestartRecord(
            tick=k,
            agent=agent,
            lost_at_tick=self.down[agent],
            incarnation=new,
            host=host,
            checkpoint_tick=checkpoint[0] if checkpoint else "",
        )
        assert self.placement is not None
        if checkpoint:
            self.snapshots[agent] = checkpoint[1]
        try:
            self.placement.place(agent, host, new, restore=checkpoint is not None)
            got = self._await_swap_event(
                agent, -1, new, ("restored", "restore_failed") if checkpoint else ("join", "join")
            )
        except Exception as exc:
            got = f"cannot start it on {host}: {exc}"
        finally:
            self.snapshots.pop(agent, None)
        record.wait_ms = round((time.perf_counter() - t0) * 1000, 3)
        if got in ("restored", "join"):
            self.incarnation[agent] = new
            del self.down[agent]
            record.outcome = "ok"
        else:
            record.reason = got
            log.warning("coordinator: agent %d could not be restarted before tick %d: %s", agent, k, got)
            try:
                self.placement.unplace(agent, host, new)
            except Exception as exc:  # the host is away: its process, if any, is stale from now on
                log.warning("coordinator: could not stop the failed restart of agent %d on %s: %s", agent, host, exc)
        return record

    # -- moving agents (swaps) ---------------------------------------------------------------------
    def _swap_due(self, k: int) -> None:
        """Every swap scripted for tick ``k`` and every one requested since the last tick, in order."""
        due: list[tuple[int, str, int | None]] = [(a, h, None) for a, h in self.swaps_due.pop(k, [])]
        while True:
            try:
                due.append(self.swap_requests.get_nowait())
            except queue.Empty:
                break
        for agent, host, number in due:
            record = self._swap(agent, host, k)
            self.swap_log.append(record)
            if number is not None:
                self.requested_swaps[number] = record

    def _swap(self, agent: int, to: str, k: int) -> SwapRecord:
        """Move ``agent`` to host ``to`` before tick ``k``: the old process hands its state over and
        freezes, a new process on ``to`` restores it and announces itself, the old one retires.
        Any failure resumes the old process; the record says what happened."""
        t0 = time.perf_counter()
        old = self.incarnation.get(agent, 0)
        new = old + 1
        record = SwapRecord(tick=k, agent=agent, from_host=self.hosts.get(agent, "local"), to=to)

        def finish(reason: str = "") -> SwapRecord:
            record.pause_ms = round((time.perf_counter() - t0) * 1000, 3)
            if reason:
                record.reason = reason
                log.warning("coordinator: swap of agent %d to %s before tick %d failed: %s", agent, to, k, reason)
            return record

        if agent in self.lost or self.placement is None:
            return finish("the agent is not running" if agent in self.lost else "this run cannot start processes")
        if to != LOCAL and self.carriers is not None and agent not in self.carriers.get(to, ()):
            return finish(
                f"host {to} may not carry agent {agent}: the hub admits a host only to the agents placed on "
                f"it, moved to it by a scripted swap or listed for it in may_carry"
            )
        self.snapshots.pop(agent, None)
        self.agent_pubs[agent].put(encode_control(TAG_SNAPSHOT, old, self.tickets.issue("snapshot", agent, old)))
        got = self._await_swap_event(agent, old, new, ("snapshot", "snapshot_failed"))
        if got != "snapshot":
            self.tickets.cancel("snapshot", agent)
            return finish(got)
        record.snapshot_bytes = len(self.snapshots[agent])
        try:
            self.placement.place(agent, to, new)
        except Exception as exc:  # the host refused or is gone: the old process goes on
            self.agent_pubs[agent].put(encode_control(TAG_RESUME, old))
            return finish(f"cannot start it on {to}: {exc}")
        got = self._await_swap_event(agent, old, new, ("restored", "restore_failed"))
        if got != "restored":
            self.agent_pubs[agent].put(encode_control(TAG_RESUME, old))
            self.placement.unplace(agent, to, new)
            return finish(got)
        self.incarnation[agent] = new
        self.agent_pubs[agent].put(encode_control(TAG_RETIRE, old))
        self.hosts[agent] = to
        self.snapshots.pop(agent, None)
        record.outcome = "ok"
        return finish()

    def _await_swap_event(self, agent: int, old: int, new: int, wanted: tuple[str, str]) -> str:
        """``wanted[0]`` when it comes; otherwise why not (the failure's reason). Other events wait."""

        def take(what: str, data: Any) -> object:
            if what == "snapshot" and data == agent and wanted[0] == "snapshot":
                return "snapshot"
            if what == "join" and wanted[0] == "join" and data == self.keys.alive_agent(agent, new):
                return "join"
            if what == "report":
                rep = self.decode_report(*data)
                if rep is None:
                    return CONSUMED
                if rep.agent == agent and rep.kind in wanted:
                    return "restored" if rep.kind == "restored" else f"{rep.kind}: {getattr(rep, 'error', '')}"
            if what == "leave" and "/alive/agent/" in data and agent_id_of(data) == agent:
                gone = incarnation_of(data)
                if gone in (old, new):
                    return f"the {'old' if gone == old else 'new'} process of agent {agent} exited"
            return None

        timeout = self.exp.run.tick_timeout
        return str(self.events.wait_for(timeout, take, f"no {wanted[0]} within {timeout:.0f} s"))
