"""The error that ends a run."""


class RunError(RuntimeError):
    """The run cannot go on; the message says which process, at which tick, and where its log is."""
