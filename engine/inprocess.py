"""The in-process transport: every agent's runtime and the radio stepped in this process.

What an agent process and the netem proxy do with a tick, without the processes: each live
agent's :class:`~swarmbed.agent_runtime.runtime.AgentRuntime` steps on its observation and inbox
as they would arrive over the wire (observation, action and messages pass through their wire
encodings), and the proxy's :class:`~swarmbed.netem.exchange.Exchange` routes the messages with
the same random streams. A lock-step run's result files come out byte for byte as a real run's
(tested); wall-clock matters (real-time clock, restarts, swaps, timings) have no meaning here.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

from swarmbed.agent_runtime.runtime import AgentRuntime
from swarmbed.extension.scenario import World
from swarmbed.netem.exchange import Exchange
from swarmbed.wire.codec import EMPTY_INBOX, NetemStep, WorldSample, decode_agent_out, encode_agent_out
from swarmbed.wire.observation import Observation
from swarmbed.wire.reports import Final, NetemFinal, RestartRecord, SwapRecord
from swarmbed.wire.schema import Experiment, Targets, agent_spec, netem_spec


class InProcess:
    """A :class:`~swarmbed.engine.loop.TickTransport` for lock-step runs of one process; the
    radio's ledger goes to ``out_dir`` as the proxy's would."""

    def __init__(self, exp: Experiment, targets: Targets, world: World, out_dir: Path) -> None:
        if exp.run.clock != "lockstep":
            raise ValueError("the in-process engine steps lock-step runs only (run.clock: lockstep)")
        spec = agent_spec(exp, targets)
        self.world = world
        self.runtimes = {i: AgentRuntime(spec, i) for i in range(exp.agents.count)}
        self.radio_exchange = Exchange(netem_spec(exp), out_dir)
        # what the recorder reads of a run's membership: no process is ever lost, swapped or restarted
        self.lost: dict[int, int] = {}  # agent -> tick its robot was lost (the scenario's losses)
        self.swap_log: list[SwapRecord] = []
        self.restart_log: list[RestartRecord] = []
        #: the decisions for the tick in hand of an allocator that takes them from outside (``external``:
        #: a learner that owns the loop sets them between TickLoop.begin and complete)
        self.decisions: Mapping[int, int] = {}

    # -- the transport ----------------------------------------------------------------------------
    def run_starts(self) -> None:
        pass

    def tick_starts(self, k: int) -> None:
        pass

    def before_world(self, k: int) -> None:
        pass

    def incarnations(self) -> dict[int, int]:
        return {}

    def world_ready(self, sample: WorldSample) -> None:
        self.radio_exchange.radio.confirm()  # the inboxes made for this tick arrived

    def exchange(
        self, k: int, sample: WorldSample, observed: Mapping[int, Observation], inboxes: Mapping[int, bytes]
    ) -> NetemStep:
        outs = {}
        for i, obs in observed.items():
            runtime = self.runtimes[i]
            action, messages, events = runtime.step(
                k, runtime.decode_observation(obs.to_wire()), inboxes.get(i, EMPTY_INBOX), self.decisions.get(i)
            )
            outs[i] = decode_agent_out(encode_agent_out(k, i, action, messages, events))
        return self.radio_exchange.route(sample, outs)

    def lose(self, agent: int, k: int) -> None:  # no process to lose
        raise AssertionError(f"agent {agent} lost at tick {k} in a run of one process")

    def retire(self, agent: int, tick: int) -> None:
        self.lost[agent] = tick
        self.world.kill(agent)

    def clock_columns(self) -> Sequence[float]:
        return ()

    def tick_done(self, k: int, admitted: Mapping[int, list]) -> None:
        pass

    def should_stop(self) -> bool:
        return False

    def run_ends(self) -> None:
        pass

    # -- at the end ------------------------------------------------------------------------------
    def reports(self) -> dict[int, Final]:
        """Every agent's final report, as its process would send it."""
        return {i: runtime.report() for i, runtime in self.runtimes.items()}

    def finish(self, last_tick: int) -> NetemFinal:
        """Close the radio's ledger and make the proxy's final report."""
        return self.radio_exchange.finish(last_tick, malformed=0)
