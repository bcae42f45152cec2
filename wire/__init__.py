"""The wire contract: key expressions, message schemas and codec shared by every swarmbed process.

Every process imports its keys and its encoders/decoders from here and nowhere else, so that
coordinator, netem proxy and agents (possibly on other hosts) always agree on the protocol.
"""

from swarmbed.wire.codec import WireError
from swarmbed.wire.keys import Keys

__all__ = ["Keys", "WireError"]
