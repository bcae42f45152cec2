"""The emulated radio between agents: range, loss, rate cap, queue limit, latency, and a byte ledger.

Its parameters are ``swarmbed.schema.experiment.NetworkSection`` (the experiment's ``network:`` section).
"""

from swarmbed.netem.ledger import Ledger
from swarmbed.netem.radio import Radio

__all__ = ["Radio", "Ledger"]
