"""What the coordinator's Zenoh callbacks hand the tick loop's thread: one queue of ``(what, data)`` events.

Callbacks run on Zenoh's threads and only put events here; everything that acts on them runs on
the tick loop's thread. A part that waits for one kind of event (a swap's snapshot, a proxy's last
report) takes what it wants with :meth:`EventQueue.wait_for` and leaves every other event for the
tick loop, in the order it came.
"""

from __future__ import annotations

import queue
import time
from collections.abc import Callable
from typing import Any

CONSUMED = object()  # what an event filter of EventQueue.wait_for returns for an event it used


class EventQueue:
    def __init__(self) -> None:
        self._queue: queue.SimpleQueue[tuple[str, Any]] = queue.SimpleQueue()
        self._pushback: list[tuple[str, Any]] = []

    def put(self, event: tuple[str, Any]) -> None:
        self._queue.put(event)

    def next(self, timeout: float) -> tuple[str, Any]:
        """The oldest event (those a wait left come first); ``queue.Empty`` after ``timeout`` s."""
        if self._pushback:
            return self._pushback.pop(0)
        return self._queue.get(timeout=max(0.0, timeout))

    def wait_for(self, seconds: float, take: Callable[[str, Any], object], timeout: object = None) -> object:
        """Events for up to ``seconds``: ``take(what, data)`` returns None to keep an event for the
        tick loop (in order), :data:`CONSUMED` for one it used, anything else to end the wait with
        that value; ``timeout`` when the time is up."""
        deadline = time.monotonic() + seconds
        held: list[tuple[str, Any]] = []
        try:
            while True:
                try:
                    what, data = self._queue.get(timeout=max(0.0, deadline - time.monotonic()))
                except queue.Empty:
                    return timeout
                got = take(what, data)
                if got is None:
                    held.append((what, data))
                elif got is not CONSUMED:
                    return got
        finally:
            self._pushback.extend(held)
