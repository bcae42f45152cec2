"""A lock-step run in this one process, on the in-process engine: ``swarmbed run --engine
inprocess``, ``swarmbed sweep --engine inprocess`` and the learning environment's
``engine="inprocess"``.

The same result files as a run of processes writes for the same configuration and seed
(``summary.json``, ``timeseries.csv``, ``agents.csv``, the ledgers, ``config.yaml``,
``provenance.json``), byte for byte, without Zenoh, the proxy or agent processes: each live
agent's :class:`~swarmbed.agent_runtime.runtime.AgentRuntime` steps on its observation and inbox
as they would arrive over the wire (observation, action and messages pass through their wire
encodings), and the proxy's :class:`~swarmbed.netem.exchange.Exchange` routes the messages with
the same random streams (:class:`InProcess`, the transport; :class:`InProcessRun`, the run on an
engine :class:`~swarmbed.engine.Session`). What needs processes is refused before anything starts
(:func:`swarmbed.engine.refusals`): the real-time clock, other hosts and swaps, decisions from
ROS 2, ROS 2 topics, behavior-tree logs, and a hub others join. ``timings.json`` and
``deployment.json`` say which engine ran.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from contextlib import ExitStack
from pathlib import Path

from swarmbed.agent_runtime.runtime import AgentRuntime
from swarmbed.engine import ENGINES, OneProcess, Session, TickInHand, refusals, results
from swarmbed.files import safefiles
from swarmbed.launch.runner import RunResult, View, plan_run, start_result_dir
from swarmbed.netem.exchange import Exchange, SplitExchange
from swarmbed.records.run_folder import DEPLOYMENT
from swarmbed.schema.experiment import Experiment, Targets, agent_spec, netem_spec
from swarmbed.wire.child_process import tune_gc
from swarmbed.wire.codec import EMPTY_INBOX, NetemStep, WorldSample, decode_agent_out, encode_agent_out
from swarmbed.wire.control import Final, NetemFinal
from swarmbed.wire.observation import Observation
from swarmbed.wire.tickdecode import TickDecoder

__all__ = ["ENGINES", "InProcess", "InProcessRun", "refusals", "run_in_process"]


class InProcess:
    """The in-process :class:`~swarmbed.engine.Transport`: every agent's runtime and the radio, stepped
    here; the radio's ledger goes to ``out_dir`` as the proxy's would."""

    def __init__(self, exp: Experiment, targets: Targets, out_dir: Path) -> None:
        if exp.run.clock != "lockstep":
            raise ValueError("the in-process engine steps lock-step runs only (run.clock: lockstep)")
        spec = agent_spec(exp, targets)
        self.runtimes = {i: AgentRuntime(spec, i) for i in range(exp.agents.count)}
        self.decoder = TickDecoder(next(iter(self.runtimes.values())).scenario.Observation) if self.runtimes else None
        radio = netem_spec(exp)
        self.radio_exchange = Exchange(radio, out_dir) if radio.split.shards == 1 else SplitExchange(radio, out_dir)

    def exchange(
        self,
        k: int,
        sample: WorldSample,
        observed: Mapping[int, Observation],
        inboxes: Mapping[int, bytes],
        decisions: Mapping[int, int],
    ) -> NetemStep:
        self.radio_exchange.confirm()  # the inboxes made for this tick arrived
        outs = {}
        for i, obs in observed.items():
            runtime = self.runtimes[i]
            assert self.decoder is not None
            action, messages, events = runtime.step(
                k, self.decoder.observation(obs.to_wire()), inboxes.get(i, EMPTY_INBOX), decisions.get(i)
            )
            outs[i] = decode_agent_out(encode_agent_out(k, i, action, messages, events))
        return self.radio_exchange.route(sample, outs)

    def reports(self) -> dict[int, Final]:
        """Every agent's final report, as its process would send it."""
        return {i: runtime.report() for i, runtime in self.runtimes.items()}

    def finish(self, last_tick: int) -> NetemFinal:
        """Close the radio's ledger and make the proxy's final report."""
        return self.radio_exchange.finish(last_tick, malformed=0)


class InProcessRun:
    """One run on the in-process engine, from its result folder made to its files written. The
    caller may own the loop (:meth:`observe`, :meth:`advance`: a learner, one tick a step) or let
    :meth:`run` step it to the end."""

    def __init__(self, exp: Experiment, out_dir: Path, env: bool = False, views: Sequence[View] = ()) -> None:
        self.t0 = time.perf_counter()
        if not env:  # a learner's process is its own: its collector's settings are left alone
            tune_gc()
        plan = plan_run(exp, out_dir)
        resolved = plan.resolved
        why = refusals(exp, resolved.allocator_cls.decision_source, "inprocess", driven=env)
        if why:
            raise ValueError(f"--engine inprocess: {why[0]}")
        self.exp, self.out_dir = exp, Path(out_dir)
        self._folder = ExitStack()  # the run's folder, opened once: every file of the run reached from it
        self._folder.enter_context(safefiles.rooted(self.out_dir))
        try:
            start_result_dir(plan)
            self.session = Session(exp, resolved.scenario(), resolved.allocator_cls, self.out_dir)
            self.world = self.session.world
            self.engine = InProcess(exp, resolved.targets, self.out_dir)
            self.session.connect(self.engine, OneProcess(self.world), [view(self.session) for view in views])
            self.result: RunResult | None = None
            self.session.start()
        except BaseException:
            self._folder.close()
            raise

    @property
    def over(self) -> bool:
        return self.result is not None or self.session.over

    @property
    def inboxes(self) -> dict[int, bytes]:
        """The inboxes the radio delivers at the tick in hand."""
        return self.session.inboxes

    def observe(self) -> TickInHand:
        """The tick in hand's first half (its observations), made once."""
        return self.session.observe()

    def advance(self, decisions: Mapping[int, int] | None = None) -> None:
        """Complete the tick in hand with ``decisions`` (agent -> task id, for an ``external``
        allocator) and move to the next one; write the result files when the run is over."""
        try:
            self.session.step(decisions)
        except BaseException:
            self.session.abandon()
            self._folder.close()
            raise
        if self.session.over:
            self.finish()

    def run(self, on_tick: Callable[[int, float], None] | None = None) -> RunResult:
        """Step every tick of the run to its end and write the result files."""
        while not self.over:
            self.advance()
            if on_tick:
                on_tick(self.world.tick, self.world.time)
        return self.finish()

    def finish(self) -> RunResult:
        """Write the result files of the ticks stepped so far (once)."""
        if self.result is not None:
            return self.result
        self.session.loop.end()  # a run cut short (a learner's episode): the hooks hear it end too
        with self._folder:  # closed once the files are written, or the run abandoned
            try:
                reports, netem = self.engine.reports(), self.engine.finish(self.session.last_tick)
                timings = {"engine": "inprocess", "run_s": time.perf_counter() - self.t0}
                summary = self.session.write(reports, netem, malformed=0, clock=None, timings=timings)
            except BaseException:
                self.session.abandon()
                raise
            results.write_json(self.out_dir / DEPLOYMENT, {"engine": "inprocess", "agents": "this process"})
        self.result = RunResult(self.out_dir, summary.document, timings)
        return self.result


def run_in_process(exp: Experiment, out_dir: Path) -> RunResult:
    """Run ``exp`` (lock-step) in this process and write its result files to ``out_dir``."""
    return InProcessRun(exp, out_dir).run()
