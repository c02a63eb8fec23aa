"""Progress of long work on stderr: a live line on a terminal, nothing otherwise."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    """A one-line progress display.

    Parameters
    ----------
    label : str
        What is being done ("recording", "decoding").
    total : float, optional
        The amount at which the work is complete (seconds, bytes, frames).
    stream : file, optional
        Where to write; defaults to stderr. Nothing is written unless it is a terminal
        or ``force`` is true.
    """

    def __init__(
        self,
        label: str,
        total: float | None = None,
        stream: TextIO | None = None,
        force: bool = False,
    ) -> None:
        self.label = label
        self.total = total
        self.stream = stream or sys.stderr
        self.enabled = force or bool(getattr(self.stream, "isatty", lambda: False)())
        self._last = 0.0
        self._shown = False

    def update(self, done: float, detail: str = "") -> None:
        """Show ``done`` of ``total`` (at most ten times a second)."""
        if not self.enabled:
            return
        now = time.monotonic()
        if now - self._last < 0.1:
            return
        self._last = now
        if self.total:
            pct = min(100.0, 100.0 * done / self.total)
            text = f"{self.label}: {pct:5.1f}% {detail}"
        else:
            text = f"{self.label}: {done:.0f} {detail}"
        self.stream.write("\r" + text.ljust(78)[:78])
        self.stream.flush()
        self._shown = True

    def close(self) -> None:
        """End the line."""
        if self.enabled and self._shown:
            self.stream.write("\n")
            self.stream.flush()
