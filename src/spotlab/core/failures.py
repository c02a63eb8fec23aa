"""Failures counted by kind, so that none is lost in a log that stops after a few.

A sink, a live consumer or a decoder that fails on every block would flood a log; one
that fails once in an hour would be drowned by it. :class:`FailureTally` counts every
failure under its kind (the exception's type and the place it was raised) and tells the
caller when a kind is new, so that the first of each kind is logged with its traceback
and the rest only counted; :attr:`FailureTally.counts` names and counts them all.
"""

from __future__ import annotations

import threading
import traceback
from pathlib import Path

__all__ = ["FailureTally", "failure_kind"]


def failure_kind(exc: BaseException) -> str:
    """``"TypeName at file.py:LINE"``: the exception's type and where it was raised."""
    frames = traceback.extract_tb(exc.__traceback__) if exc.__traceback__ else []
    if not frames:
        return type(exc).__name__
    last = frames[-1]
    return f"{type(exc).__name__} at {Path(last.filename).name}:{last.lineno}"


class FailureTally:
    """Failures by kind (thread-safe).

    Attributes
    ----------
    counts : dict of str to int
        Failures of each kind (:func:`failure_kind`), in the order first seen.
    """

    def __init__(self) -> None:
        self.counts: dict[str, int] = {}
        self._lock = threading.Lock()

    def add(self, exc: BaseException) -> bool:
        """Count ``exc``; True when it is the first of its kind (log it then)."""
        kind = failure_kind(exc)
        with self._lock:
            n = self.counts.get(kind, 0) + 1
            self.counts[kind] = n
        return n == 1

    @property
    def total(self) -> int:
        """All failures counted."""
        with self._lock:
            return sum(self.counts.values())

    def snapshot(self) -> dict[str, int]:
        """A copy of :attr:`counts`."""
        with self._lock:
            return dict(self.counts)
