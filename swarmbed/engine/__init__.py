"""The lock-step engine: a run's tick body and its result files, written once, below the process roles.

A :class:`Session` builds a run's world and recorder and steps it with a :class:`TickLoop` over a
:class:`Transport` (one call a tick: carry the observations and inboxes to the agents, bring back
their actions and the next inboxes), with the run's :class:`Membership` and the
:class:`~swarmbed.engine.hooks.TickHook` list around a tick. Two transports plug in from above the
roles: the coordinator (:class:`swarmbed.coordinator.zenoh_transport.ZenohTransport`: real processes over
Zenoh, through the netem proxy) and the in-process one (:mod:`swarmbed.launch.inprocess`:
every agent's runtime and the radio stepped in this process).
"""

from swarmbed.engine.hooks import StopWhenAsked, TickHook
from swarmbed.engine.loop import Membership, OneProcess, TickInHand, TickLoop, Transport
from swarmbed.engine.run_errors import RunError
from swarmbed.engine.session import ENGINES, Session, refusals

__all__ = [
    "ENGINES",
    "Membership",
    "OneProcess",
    "RunError",
    "Session",
    "StopWhenAsked",
    "TickHook",
    "TickInHand",
    "TickLoop",
    "Transport",
    "refusals",
]
