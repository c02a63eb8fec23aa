"""What the page shows live, handed from the acquisition threads by latest value.

The acquisition never waits for the web side: :class:`ViewSink` is a queued session
sink (the session drops its blocks, for it alone, when its queue is full) that keeps
only the last frame of each stream, and :class:`MarkerSlot` is a live-pipeline consumer
that keeps only the last 3-D frame. Each stores a new small object by one reference
assignment; the web side reads the latest one whenever it wants, with no lock held
across the acquisition.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from spotlab.acquisition.interfaces import Device, SinkBase
from spotlab.core.frames import FrameBlock

__all__ = ["ClockPair", "MarkerSlot", "StreamView", "ViewSink"]


@dataclass(frozen=True)
class StreamView:
    """The last frame of one stream, for the page.

    Attributes
    ----------
    seq : int
        Its sequence number.
    arrival_ns : int
        Host arrival of its last byte, ``time.monotonic_ns`` ns.
    cameras : list of list of [x, y]
        Per camera (sensor) the readings seen, in the stream's units (pixels, counts):
        the markers of an ``image2d`` stream, the blobs of a ``blobs2d`` one.
    """

    seq: int
    arrival_ns: int
    cameras: list[list[list[float]]]


@dataclass(frozen=True)
class ClockPair:
    """First and latest (device time, host arrival) of a stream, s.

    The offset is device time minus host arrival time at the latest frame; the drift is
    the device clock's rate against the host's since the first (taken 1 s after the
    stream's first frame: start-up arrives in bursts), in ppm, from 5 s on (arrival
    stamps: millisecond-level, so meaningful after a minute or so).
    """

    first_dev_s: float
    first_host_s: float
    dev_s: float
    host_s: float

    @property
    def offset_s(self) -> float:
        """Device time minus host arrival time, s."""
        return self.dev_s - self.host_s

    @property
    def drift_ppm(self) -> float | None:
        """Device clock rate against the host's, ppm (None before 5 s)."""
        span = self.host_s - self.first_host_s
        if span < 5.0:
            return None
        return ((self.dev_s - self.first_dev_s) / span - 1.0) * 1e6


#: Stream kinds with a 2-D view (a timer has none).
VIEWED = ("image2d", "blobs2d")
#: Seconds after a stream's first frame at which its clock pair is anchored.
ANCHOR_AFTER_S = 1.0


def _xy_columns(values: Sequence[str]) -> tuple[int, int]:
    names = list(values)
    if "x" in names and "y" in names:
        return names.index("x"), names.index("y")
    return 0, 1


class ViewSink(SinkBase):
    """A queued session sink keeping the last frame of each stream for the page.

    Parameters
    ----------
    max_rate_hz : float
        How often a stream's view is rebuilt at most (the page shows <= 30 Hz).
    """

    name = "console-view"

    def __init__(self, max_rate_hz: float = 30.0) -> None:
        self.views: dict[str, StreamView] = {}
        self.clocks: dict[str, ClockPair] = {}
        self.units: dict[str, str] = {}
        self._columns: dict[str, tuple[int, int]] = {}
        self._tick_hz: dict[str, float] = {}
        self._seen_s: dict[str, float] = {}
        self._kinds: dict[str, str] = {}
        self._arrival_ns: dict[str, int] = {}
        self._period_ns = int(1e9 / max_rate_hz)

    def on_start(self, devices: Sequence[Device]) -> None:
        """Learn each stream's x and y columns, units and tick rate."""
        for device in devices:
            spec = device.spec
            self._columns[spec.name] = _xy_columns(spec.values)
            self._tick_hz[spec.name] = float(spec.tick_hz)
            self.units[spec.name] = spec.units[0].split("|")[0] if spec.units else ""
            self._kinds[spec.name] = str(spec.kind)

    def on_block(self, stream: str, block: FrameBlock) -> None:
        """Keep the block's last frame (at most ``max_rate_hz`` times a second)."""
        if len(block) == 0:
            return
        arrival = int(block.arrival_ns[-1])
        self._arrival_ns[stream] = arrival
        tick_hz = self._tick_hz.get(stream, 0.0)
        if tick_hz > 0:
            dev_s, host_s = float(block.ticks[-1]) / tick_hz, arrival / 1e9
            old = self.clocks.get(stream)
            seen = self._seen_s.setdefault(stream, host_s)
            if old is None or old.first_host_s - seen < ANCHOR_AFTER_S:
                # the frames of the first second arrive in bursts (start-up): anchor later
                first = (dev_s, host_s)
            else:
                first = (old.first_dev_s, old.first_host_s)
            self.clocks[stream] = ClockPair(first[0], first[1], dev_s, host_s)
        kind = self._kinds.get(stream)
        if kind not in VIEWED:
            return
        old_view = self.views.get(stream)
        if old_view is not None and arrival - old_view.arrival_ns < self._period_ns:
            return
        cx, cy = self._columns.get(stream, (0, 1))
        data = block.data[-1]  # (M, S, V)
        if kind == "blobs2d":
            data = data[1:]  # row 0 is each camera's own row (exposure, frame, counts)
        cameras: list[list[list[float]]] = []
        if data.shape[2] > max(cx, cy):
            for s in range(data.shape[1]):
                xy = data[:, s, [cx, cy]]
                seen = xy[np.all(np.isfinite(xy), axis=1)]
                cameras.append([[round(float(x), 2), round(float(y), 2)] for x, y in seen])
        self.views[stream] = StreamView(int(block.seq[-1]), arrival, cameras)

    def last_arrival_s(self, stream: str) -> float | None:
        """Seconds since the stream's last frame arrived (None if none has)."""
        arrival = self._arrival_ns.get(stream)
        if arrival is None:
            return None
        return (time.monotonic_ns() - arrival) / 1e9


class MarkerSlot:
    """A live-pipeline consumer keeping the latest 3-D frame (one reference assignment:
    it runs in the reader thread, so it converts nothing; :meth:`snapshot` does)."""

    def __init__(self) -> None:
        self.latest: Any = None
        self.frames = 0

    def __call__(self, frame: Any) -> None:
        """Take one ``LiveFrame``."""
        self.latest = frame
        self.frames += 1

    def snapshot(self) -> dict[str, Any] | None:
        """The latest frame for the page: points (M, 3) mm (None where not seen), labels."""
        frame = self.latest
        if frame is None:
            return None
        points = [
            [round(float(v), 1) for v in p] if all(math.isfinite(v) for v in p) else None
            for p in np.asarray(frame.points).tolist()
        ]
        return {
            "seq": int(frame.seq),
            "time_s": float(frame.frame_time_s),
            "points": points,
            "labels": [str(label) for label in frame.labels],
        }
