"""A sign of life for long work (a soak, a replay, an analysis, the re-runs of ``--verify``): a
progress bar where the output is a terminal, else one line every minute (a log file or a CI job
gets lines it can read, not a bar redrawn with carriage returns)."""

from __future__ import annotations

import sys
import time
from typing import Any, TextIO


class Progress:
    """``total`` units of work named ``desc``; :meth:`update` with the units done so far."""

    def __init__(
        self,
        total: float,
        desc: str,
        unit: str = "",
        enabled: bool = True,
        every_s: float = 60.0,
        stream: TextIO | None = None,
    ) -> None:
        self.total, self.desc, self.unit, self.every_s = total, desc, unit, every_s
        self.stream = stream or sys.stderr
        self.enabled = enabled
        self.done = 0.0
        self.started = self._said = time.monotonic()
        self.bar: Any = None
        if enabled and self.stream.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, desc=desc, unit=unit or "it", file=self.stream, leave=False)

    def update(self, done: float, note: str = "") -> None:
        """``done`` units of the total are done (``note``: what to say beside the count)."""
        if not self.enabled:
            return
        step, self.done = done - self.done, done
        if self.bar is not None:
            self.bar.update(step)
            if note:
                self.bar.set_postfix_str(note, refresh=False)
            return
        now = time.monotonic()
        if now - self._said >= self.every_s:
            self._said = now
            share = f" ({100 * done / self.total:.0f} %)" if self.total else ""
            elapsed = time.strftime("%H:%M:%S", time.gmtime(now - self.started))
            unit = f" {self.unit}" if self.unit else ""
            print(
                f"{self.desc}: {done:,.0f} of {self.total:,.0f}{unit}{share} after {elapsed}"
                f"{'; ' + note if note else ''}",
                file=self.stream,
                flush=True,
            )

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
