"""The emulated radio between agents: range, loss, rate cap, queue limit, latency, and a byte ledger."""

from netem.params import NetemParams
from netem.radio import Radio
from netem.ledger import Ledger

__all__ = ["NetemParams", "Radio", "Ledger"]
