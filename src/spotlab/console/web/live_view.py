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

from spotlab.acquisition.clocks import ArrivalDejitter, ClockSegment
from spotlab.acquisition.interfaces import Device, SinkBase
from spotlab.core.errors import ClockError
from spotlab.core.frames import FrameBlock

__all__ = ["MarkerSlot", "StreamClock", "StreamView", "ViewSink"]


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


class StreamClock:
    """The session's clock model of one stream: device ticks to session time.

    The console has no timer edges live, so its model is the one ``spotlab export``
    falls back to for a stream without a timer input: an online line fit of host
    arrival times against device ticks (:class:`ArrivalDejitter`, liblsl's dejitter;
    docs/synchronisation.md), on the session's reference: the host's monotonic clock, 0
    at the session's start. :class:`ViewSink` fits a block's last frame, at most
    :data:`CLOCK_HZ` times a second.

    Parameters
    ----------
    tick_hz : float
        The device's tick rate, Hz.
    t0_ns : int
        The session's start, ``time.monotonic_ns`` ns.
    """

    def __init__(self, tick_hz: float, t0_ns: int) -> None:
        self.tick_hz = tick_hz
        self.t0_ns = t0_ns
        self._fit = ArrivalDejitter(tick_hz, allow_resets=True)
        self._first_s: float | None = None
        #: Session time minus device time (ticks / tick rate) at the latest pair, s, by
        #: the model (None before it has enough pairs): where the device clock's zero
        #: lies on the session's time line. Two streams' difference is their clocks'.
        self.offset_s: float | None = None
        #: The device clock's rate against the session's, ppm, by the model (None
        #: before 5 s of pairs: arrival stamps are millisecond-level).
        self.drift_ppm: float | None = None

    def update(self, tick: int, arrival_ns: int) -> None:
        """Fit one (device tick, host arrival) pair; the offset and drift follow."""
        t = (arrival_ns - self.t0_ns) / 1e9
        try:
            self._fit.update(np.array([tick], dtype=np.int64), np.array([t]))
        except ClockError:  # ticks that repeat: start the fit again
            self._fit = ArrivalDejitter(self.tick_hz, allow_resets=True)
            self._first_s = None
            self.offset_s = self.drift_ppm = None
            return
        if self._first_s is None:
            self._first_s = t
        try:
            seg: ClockSegment = self._fit.model.segments[-1]
        except ClockError:  # too few pairs yet
            return
        self.offset_s = (
            float(seg.seconds(np.array([tick], dtype=np.int64))[0]) - tick / self.tick_hz
        )
        if t - self._first_s >= 5.0:
            self.drift_ppm = (1.0 / (seg.rate * self.tick_hz) - 1.0) * 1e6


#: Stream kinds with a 2-D view (a timer has none).
VIEWED = ("image2d", "blobs2d")
#: Pairs a second a stream's clock model is fitted with at most.
CLOCK_HZ = 10.0
#: Seconds after a stream's first frame before its clock is fitted (the frames of the
#: first second arrive in bursts: start-up dialogue, queued frames).
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
        self.clocks: dict[str, StreamClock] = {}
        self._t0_ns = time.monotonic_ns()  # the session's reference: 0 s here
        self._fitted_ns: dict[str, int] = {}
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
            seen = self._seen_s.setdefault(stream, arrival / 1e9)
            if arrival / 1e9 - seen >= ANCHOR_AFTER_S:
                clock = self.clocks.get(stream)
                if clock is None:
                    clock = self.clocks[stream] = StreamClock(tick_hz, self._t0_ns)
                if arrival - self._fitted_ns.get(stream, 0) >= 1e9 / CLOCK_HZ:
                    self._fitted_ns[stream] = arrival
                    clock.update(int(block.ticks[-1]), arrival)
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
