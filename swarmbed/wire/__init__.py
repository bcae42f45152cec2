"""The wire contract: key expressions, message schemas and codec shared by every swarmbed process,
and what it is to be a run process (seeds, sessions, logs, credentials).

Every process imports its keys and its encoders/decoders from here and nowhere else, so that
coordinator, netem proxy and agents (possibly on other hosts) always agree on the protocol. The
experiment's schema is ``swarmbed.schema`` and what a run writes ``swarmbed.records``, just above;
safe file reading and writing is ``swarmbed.files``, just below.
"""

from swarmbed.wire.codec import WireError
from swarmbed.wire.keys import Keys

__all__ = ["Keys", "WireError"]
