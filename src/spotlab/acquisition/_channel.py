"""A bounded queue from the reader threads to one sink, dropping and counting on overflow."""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass

from spotlab.core.failures import FailureTally
from spotlab.core.frames import FrameBlock


@dataclass(frozen=True)
class SinkStats:
    """What happened between the session and one sink.

    Attributes
    ----------
    name : str
        The sink's name.
    delivered : int
        Blocks handed to ``on_block``.
    overflows : int
        Blocks dropped for this sink because its queue was full.
    dropped_frames : int
        Frames in those blocks.
    errors_delivered : int
        Device errors handed to ``on_error`` (never dropped).
    sink_errors : int
        Exceptions the sink itself raised (delivery went on).
    sink_failures : dict of str to int
        Those exceptions by kind (type and place: :func:`spotlab.core.failures.failure_kind`);
        the first of each kind is logged with its traceback.
    peak_queue : int
        Most blocks ever waiting at once.
    """

    name: str
    delivered: int
    overflows: int
    dropped_frames: int
    errors_delivered: int
    sink_errors: int
    peak_queue: int
    sink_failures: dict[str, int]


class SinkChannel:
    """Items for one sink: blocks (bounded) and device errors (never dropped).

    Parameters
    ----------
    name : str
        The sink's name, for reports.
    maxsize : int
        Blocks that may wait at once; one more is dropped and counted.
    """

    def __init__(self, name: str, maxsize: int) -> None:
        self.name = name
        self.maxsize = maxsize
        self._items: deque[tuple[str, FrameBlock | BaseException]] = deque()
        self._blocks = 0
        self._cond = threading.Condition()
        self._closed = False
        self.delivered = 0
        self.overflows = 0
        self.dropped_frames = 0
        self.errors_delivered = 0
        self.failures = FailureTally()
        self.peak_queue = 0

    def put_block(self, stream: str, block: FrameBlock) -> bool:
        """Queue a block; False (and counted) when the queue is full."""
        with self._cond:
            if self._blocks >= self.maxsize:
                self.overflows += 1
                self.dropped_frames += len(block)
                return False
            self._items.append((stream, block))
            self._blocks += 1
            self.peak_queue = max(self.peak_queue, self._blocks)
            self._cond.notify()
        return True

    def put_error(self, stream: str, exc: BaseException) -> None:
        """Queue a device error; errors are rare and never dropped."""
        with self._cond:
            self._items.append((stream, exc))
            self._cond.notify()

    def get(self) -> tuple[str, FrameBlock | BaseException] | None:
        """Next item, waiting for one; None once closed and drained."""
        with self._cond:
            while not self._items and not self._closed:
                self._cond.wait()
            if not self._items:
                return None
            item = self._items.popleft()
            if isinstance(item[1], FrameBlock):
                self._blocks -= 1
            return item

    def close(self) -> None:
        """No more items will come; :meth:`get` returns None after the last one."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    def stats(self) -> SinkStats:
        """A snapshot of the counters."""
        with self._cond:
            return SinkStats(
                self.name,
                self.delivered,
                self.overflows,
                self.dropped_frames,
                self.errors_delivered,
                self.failures.total,
                self.peak_queue,
                self.failures.snapshot(),
            )
