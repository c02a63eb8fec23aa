"""What a processing step reports its progress to (the command line shows it on stderr).

A processing step never prints: it calls ``update`` and ``close`` of a
:class:`ProgressSink` it is given (:class:`spotlab.console.progress.Progress` is one), or
makes one with a :data:`ProgressFactory` once it knows how much work there is.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

__all__ = ["ProgressFactory", "ProgressSink"]


class ProgressSink(Protocol):
    """Receives the progress of one piece of work."""

    def update(self, done: float, detail: str = "") -> None:
        """``done`` of the work's total (frames), with a short ``detail`` text."""

    def close(self) -> None:
        """The work is over."""


#: Makes the sink of a piece of work from its label ("reconstructing") and total
#: (frames); ``spotlab.console.progress.Progress`` itself is one.
ProgressFactory = Callable[[str, float], ProgressSink]
