"""The error of anything that arrives over the network and does not follow the wire contract.

It lives below both the key parsers (:mod:`.keys`) and the codec (:mod:`.codec`), so that a
malformed key and a malformed payload are caught, dropped and counted by the same ``except``.
"""


class WireError(ValueError):
    """A sample, key or request that does not follow the wire contract; the message says how."""
