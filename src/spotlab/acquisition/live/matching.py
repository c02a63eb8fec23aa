"""Frames of several synchronised devices matched by their session time.

Two SELSPOT systems on one frame pulse (or one timer) take their frames at the same
instants; on the host their frames arrive in any order, each stream in its own order.
:class:`FrameMatcher` keeps the frames still waiting per stream and hands out a group as
soon as it is decided:

- the group of the oldest waiting frame (time ``t0``) holds, per stream, that stream's
  oldest waiting frame if its time is within ``tolerance_s`` of ``t0``;
- a stream whose oldest waiting frame is later than ``t0 + tolerance_s`` has missed
  ``t0`` (a stream's frames come in time order): its place in the group is None;
- a stream with nothing waiting may still deliver ``t0``: the group waits for it,
  unless some stream already delivered a frame later than ``t0 + max_wait_s`` (that
  stream stalled or lost the frame): then the group goes out without it, and the
  stream counts as stalled: later groups do not wait for it until it delivers again
  (a stalled system costs the others one wait, not one per frame).

A frame never waits for anything with one stream. The group is handed out the moment
its last member arrives, so its latency is counted from the last of its frames' last
bytes.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from typing import Generic, TypeVar

from spotlab.core.errors import ConfigurationError

__all__ = ["FrameMatcher"]

T = TypeVar("T")


class FrameMatcher(Generic[T]):
    """Group frames of ``n_streams`` streams that share a frame time (not thread-safe).

    Parameters
    ----------
    n_streams : int
        Streams to match (>= 1).
    tolerance_s : float
        Largest difference between the times of frames of one group, s (for example
        a quarter of a frame period).
    max_wait_s : float
        How far another stream may run ahead before a group goes out without a
        stream that has not delivered, s (for example three frame periods).

    Raises
    ------
    ConfigurationError
        If ``n_streams`` < 1 or a time is not positive.

    Examples
    --------
    >>> m = FrameMatcher[str](2, tolerance_s=0.001, max_wait_s=0.01)
    >>> m.add(0, 0.100, "a0")
    []
    >>> m.add(1, 0.1002, "b0")
    [(0.1, ['a0', 'b0'])]
    """

    def __init__(self, n_streams: int, tolerance_s: float, max_wait_s: float) -> None:
        if n_streams < 1:
            raise ConfigurationError(f"frame matching needs at least one stream, got {n_streams}")
        if not (tolerance_s > 0 and max_wait_s > 0):
            raise ConfigurationError(
                f"tolerance ({tolerance_s} s) and wait ({max_wait_s} s) must be positive"
            )
        self.tolerance_s = float(tolerance_s)
        self.max_wait_s = float(max_wait_s)
        self._queues: list[deque[tuple[float, T]]] = [deque() for _ in range(n_streams)]
        self._newest = float("-inf")
        self._last = [float("-inf")] * n_streams
        self._stalled = [False] * n_streams
        self.incomplete = 0
        self.late = 0

    @property
    def waiting(self) -> int:
        """Frames waiting for their group."""
        return sum(len(q) for q in self._queues)

    def add(self, stream: int, time_s: float, item: T) -> list[tuple[float, list[T | None]]]:
        """Take a frame of stream ``stream`` at session time ``time_s``.

        Returns
        -------
        list of (float, list)
            The groups now decided, oldest first: the time of the group's first frame
            and one item (or None) per stream.
        """
        if time_s <= self._last[stream]:
            self.late += 1  # out of order within its own stream: cannot be matched
            return []
        self._last[stream] = time_s
        self._stalled[stream] = False
        self._queues[stream].append((time_s, item))
        self._newest = max(self._newest, time_s)
        return self._drain()

    def flush(self) -> list[tuple[float, list[T | None]]]:
        """Hand out every waiting frame (the session ended)."""
        self._newest = float("inf")
        return self._drain()

    def _drain(self) -> list[tuple[float, list[T | None]]]:
        queues = self._queues
        out: list[tuple[float, list[T | None]]] = []
        while True:
            heads = [qq[0][0] if qq else None for qq in queues]
            present = [h for h in heads if h is not None]
            if not present:
                return out
            t0 = min(present)
            limit = t0 + self.tolerance_s
            stalled = self._stalled
            undecided = any(h is None and not stalled[i] for i, h in enumerate(heads))
            if undecided and self._newest <= t0 + self.max_wait_s:
                return out
            group: list[T | None] = []
            for i, (qq, h) in enumerate(zip(queues, heads, strict=True)):
                if h is not None and h <= limit:
                    group.append(qq.popleft()[1])
                else:
                    group.append(None)
                    if h is None:
                        self._stalled[i] = True
            if any(g is None for g in group):
                self.incomplete += 1
            out.append((t0, group))

    @staticmethod
    def default_tolerances(rates_hz: Sequence[float]) -> tuple[float, float]:
        """Tolerance and wait, s: a quarter of the longest frame period of ``rates_hz``,
        and three periods but at least 100 ms (on a busy machine one reader can fall
        behind another by tens of ms: waiting less splits pairs of frames into halves;
        a stalled stream costs the wait once)."""
        period = 1.0 / min(rates_hz)
        return 0.25 * period, max(3.0 * period, 0.1)
