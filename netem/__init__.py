"""The emulated radio between agents: range, loss, rate cap, queue limit, latency, and a byte ledger."""

from swarmbed.netem.params import NetemParams
from swarmbed.netem.radio import Radio
from swarmbed.netem.ledger import Ledger

__all__ = ["NetemParams", "Radio", "Ledger"]
