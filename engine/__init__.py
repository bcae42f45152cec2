"""The lock-step engine: the tick body written once, above the process roles, over a transport.

:class:`TickLoop` advances the world tick by tick; a :class:`TickTransport` carries each tick's
world sample and observations to the agents and brings back their actions and the inboxes of the
next tick. Two transports: the coordinator (real processes over Zenoh, through the netem proxy)
and :class:`InProcess` (every agent's runtime and the radio stepped in this process), which the
calibration scripts, the conformance checks and the result-level tests use. Runs stay processes.
"""

from swarmbed.engine.inprocess import InProcess
from swarmbed.engine.loop import TickLoop, TickTransport

__all__ = ["InProcess", "TickLoop", "TickTransport"]
