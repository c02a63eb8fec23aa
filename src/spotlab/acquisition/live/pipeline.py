"""The live pipeline: image2d frames in, 3-D markers out, in the reader thread.

A labelled ``point3d`` stream (Qualisys, OptiTrack NatNet: markers the vendor's system
reconstructed already) goes through without a rig or triangulation: its points are the
result, handed out with their labels and session times.

Per frame of each ``image2d`` stream: image coordinates per camera (PSD rule of
:mod:`~spotlab.acquisition.live.readings`), session time of the frame from the stream's
clock and of each marker's sample (plus its LED slot offset,
:func:`~spotlab.acquisition.synchroniser.sample_offsets`), the frames of several
streams matched by time (:class:`~spotlab.acquisition.live.matching.FrameMatcher`),
triangulation with the loaded rig (:class:`FrameTriangulator`), and the result handed
to the consumers. Host latency: the instant the result is handed out minus the
arrival of the frame's last byte (``FrameBlock.arrival_ns``). See ``docs/live.md``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from spotlab.acquisition.clocks import ClockModel, EdgeClockEstimator
from spotlab.acquisition.interfaces import Device, SinkBase
from spotlab.acquisition.live.latency import LatencyStats, LatencySummary
from spotlab.acquisition.live.matching import FrameMatcher
from spotlab.acquisition.live.readings import pixels_by_marker
from spotlab.acquisition.live.results import LiveFrame
from spotlab.acquisition.lsl.outlet import marker_spec
from spotlab.acquisition.synchroniser import sample_offsets
from spotlab.core.errors import ConfigurationError, SpotlabError
from spotlab.core.failures import FailureTally
from spotlab.core.streams import StreamSpec
from spotlab.geometry import Rig
from spotlab.reconstruction.frame_triangulator import FrameTriangulator

__all__ = ["ClockLike", "LivePipeline", "LiveStats"]

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
#: A stream's clock: a fitted model, an online estimator (its current model is used),
#: or any callable mapping ticks (F,) int64 to session seconds (F,).
ClockLike = ClockModel | EdgeClockEstimator | Callable[[NDArray[np.int64]], FloatArray]
Consumer = Callable[[LiveFrame], Any]


@dataclass(frozen=True)
class LiveStats:
    """What the pipeline did.

    Attributes
    ----------
    frames_in : dict of str to int
        Frames received per stream.
    frames_out : int
        Frames handed to the consumers.
    incomplete : int
        Output frames missing some stream's frame (its cameras NaN).
    unclocked : int
        Frames dropped because their stream's clock had no model yet.
    failed : int
        Frames whose triangulation raised.
    late : int
        Frames older than their stream's previous one (not matched).
    consumer_errors : int
        Exceptions raised by consumers (the other consumers still ran).
    failures : dict of str to int
        Both kinds of failure by kind (type and place,
        :func:`spotlab.core.failures.failure_kind`); the first of each kind is logged.
    latency : LatencySummary
        Host latency of every output frame.
    latency_by_stream : dict of str to LatencySummary
        The same, by the stream whose frame arrived last in the group.
    """

    frames_in: dict[str, int]
    frames_out: int
    incomplete: int
    unclocked: int
    failed: int
    late: int
    consumer_errors: int
    latency: LatencySummary
    latency_by_stream: dict[str, LatencySummary]
    failures: dict[str, int]


class _Stream:
    """One image2d input: its cameras' place in the rig and its clock."""

    def __init__(self, index: int, spec: StreamSpec, first: int, clock: ClockLike | None) -> None:
        self.index = index
        self.spec = spec
        self.cameras = slice(first, first + spec.n_sensors)
        self.clock = clock
        self.rate = 1.0
        self.offsets = sample_offsets(spec, 1.0)
        self.frames = 0
        self.latency = LatencyStats()

    def frame_times(self, ticks: NDArray[np.int64]) -> FloatArray:
        """Session time of each frame, s; updates the slot offsets to the clock's rate.

        Raises ClockError while an online estimator has too few pairs.
        """
        clock = self.clock
        if clock is None:
            return ticks / self.spec.tick_hz
        if isinstance(clock, EdgeClockEstimator):
            clock = clock.model
        if isinstance(clock, ClockModel):
            rate = clock.segments[-1].rate * clock.tick_hz
            if rate != self.rate:
                self.rate, self.offsets = rate, sample_offsets(self.spec, rate)
            return clock(ticks)
        return np.asarray(clock(ticks), dtype=np.float64).reshape(ticks.shape)


def point_labels(spec: StreamSpec) -> tuple[str, ...]:
    """Marker names of a stream: ``metadata["marker_labels"]`` if one per marker, else ``m<k>``."""
    labels = spec.metadata.get("marker_labels")
    if isinstance(labels, list) and len(labels) == spec.n_markers:
        return tuple(str(x) for x in labels)
    return tuple(f"m{k}" for k in range(spec.n_markers))


def is_points(spec: StreamSpec) -> bool:
    """Whether a stream holds 3-D points already: kind ``point3d``, one sensor, x, y, z first."""
    return spec.kind == "point3d" and spec.n_sensors == 1 and spec.values[:3] == ("x", "y", "z")


class _Item(NamedTuple):
    """One frame of one stream waiting to be triangulated (or passed through)."""

    uv: FloatArray  # (M, S, 2) image coordinates, or (M, 3) points of a point3d stream
    arrival_ns: int
    seq: int
    stream: _Stream
    time_s: float


class LivePipeline(SinkBase):
    """Session sink turning ``image2d`` frames into 3-D markers, inline in the readers.

    Parameters
    ----------
    rig : Rig or None
        The calibrated cameras, for example ``Rig.load("rig.toml")``: the cameras of
        the streams in order (stream 0's sensors first). None: the input is one
        ``point3d`` stream of 3-D markers (x, y, z in mm, for example Qualisys or
        NatNet), passed through without triangulation.
    consumers : iterable of callable
        Each called with every :class:`LiveFrame`, in frame order, from a reader
        thread: keep them quick (:class:`LslMarkers`, :class:`PointRecorder`). A
        consumer with an ``on_configure(spec)`` method is told the output's
        ``point3d`` spec (markers, rate, labels) when the inputs are set.
    streams : sequence of str, optional
        Names of the image2d streams whose cameras make up the rig, in rig order.
        Default: every image2d device of the session, in session order. Without a
        rig: the name of the one point3d stream (default: the session's only one).
    clocks : mapping of str to ClockLike, optional
        Clock of each stream; default: device ticks times the tick period. Streams
        matched by time need clocks on one time base (or shared ticks).
    tolerance_s, max_wait_s : float, optional
        Frame matching of several streams (see
        :class:`~spotlab.acquisition.live.matching.FrameMatcher`); default a quarter
        of the frame period, and three periods but at least 100 ms.
    name : str
        Sink name in the session's reports.
    inline : bool
        Run in the readers' threads (default); False: in a dispatcher thread of its
        own behind a bounded queue, like other sinks (for comparison).

    Raises
    ------
    ConfigurationError
        If ``rig`` is not a Rig or None.

    Notes
    -----
    With ``inline`` the session calls :meth:`on_block` in each device's reader
    thread, with no queue or hand-off (see ``Session``). Several readers share the
    pipeline through one lock. Frames are triangulated one at a time, so a frame's
    result does not depend on how the bytes were chunked: replaying the recording
    gives the same points.
    """

    inline = True

    def __init__(
        self,
        rig: Rig | None,
        consumers: Iterable[Consumer] = (),
        *,
        streams: Sequence[str] | None = None,
        clocks: Mapping[str, ClockLike] | None = None,
        tolerance_s: float | None = None,
        max_wait_s: float | None = None,
        name: str = "live",
        inline: bool = True,
    ) -> None:
        if rig is not None and not isinstance(rig, Rig):
            raise ConfigurationError(f"rig must be a spotlab Rig, got {type(rig).__name__}")
        self.rig = rig
        self.name = name
        self.inline = inline
        self.consumers = list(consumers)
        self._wanted = None if streams is None else list(streams)
        self._clocks = dict(clocks or {})
        self._tolerance = tolerance_s
        self._max_wait = max_wait_s
        self._triangulate = None if rig is None else FrameTriangulator(rig)
        self._streams: dict[str, _Stream] = {}
        self._matcher: FrameMatcher[_Item] | None = None
        self._lock = threading.Lock()
        self._uv = np.full((0, 0 if rig is None else len(rig), 2), np.nan)  # (M, C, 2)
        self.labels: tuple[str, ...] = ()
        self.latency = LatencyStats()
        self._index = 0
        self._unclocked = self._failed = self._consumer_errors = 0
        self._failures = FailureTally()

    # -- set-up ---------------------------------------------------------------
    def on_start(self, devices: Sequence[Device]) -> None:
        """Take the image2d streams of the session's devices (see ``streams``)."""
        self.configure([d.spec for d in devices])

    def configure(self, specs: Iterable[StreamSpec]) -> None:
        """Set the input streams from their descriptions (the session does it at start).

        Parameters
        ----------
        specs : iterable of StreamSpec
            Descriptions of the session's streams; those that are not image2d, or not
            named in ``streams``, are ignored.

        Raises
        ------
        ConfigurationError
            If a named stream is missing or not image2d, the streams' cameras do not
            add up to the rig's, or their marker counts differ.
        """
        by_name = {s.name: s for s in specs}
        rig = self.rig
        if rig is None:
            self._configure_points(by_name)
            return
        if self._wanted is None:
            chosen = [s for s in by_name.values() if s.kind == "image2d"]
        else:
            missing = [n for n in self._wanted if n not in by_name]
            if missing:
                raise ConfigurationError(f"live pipeline: no stream named {missing}")
            chosen = [by_name[n] for n in self._wanted]
        wrong = [s.name for s in chosen if s.kind != "image2d"]
        if wrong or not chosen:
            raise ConfigurationError(f"live pipeline needs image2d streams; got {wrong or 'none'}")
        cameras = sum(s.n_sensors for s in chosen)
        if cameras != len(rig):
            raise ConfigurationError(
                f"the streams {[s.name for s in chosen]} have {cameras} cameras but the rig "
                f"has {len(rig)}"
            )
        markers = {s.n_markers for s in chosen}
        if len(markers) > 1:
            raise ConfigurationError(f"the streams' marker counts differ: {sorted(markers)}")
        unknown = sorted(set(self._clocks) - {s.name for s in chosen})
        if unknown:
            raise ConfigurationError(f"clocks given for streams not read here: {unknown}")
        streams, first = {}, 0
        for i, spec in enumerate(chosen):
            streams[spec.name] = _Stream(i, spec, first, self._clocks.get(spec.name))
            first += spec.n_sensors
        tol, wait = FrameMatcher.default_tolerances([s.rate_hz for s in chosen])
        self._matcher = (
            FrameMatcher(
                len(chosen),
                tol if self._tolerance is None else self._tolerance,
                wait if self._max_wait is None else self._max_wait,
            )
            if len(chosen) > 1
            else None
        )
        n_markers = markers.pop()
        self._uv = np.full((n_markers, len(rig), 2), np.nan)
        self._streams = streams
        self.labels = tuple(f"m{k}" for k in range(n_markers))
        self._tell_consumers(n_markers, chosen[0].rate_hz)
        # Warm-up: the first call's numpy paths (the lenses' undistortion start is
        # already fitted by the triangulator's construction).
        centre = np.mean([cam.center for cam in rig], axis=0)
        ahead = np.mean([cam.R[2] for cam in rig], axis=0)
        assert self._triangulate is not None
        self._triangulate.by_marker(rig.project(centre[None] + 1000.0 * ahead[None]).swapaxes(0, 1))

    def _configure_points(self, by_name: Mapping[str, StreamSpec]) -> None:
        """Without a rig: one ``point3d`` stream whose points pass through."""
        if self._wanted is None:
            chosen = [s for s in by_name.values() if s.kind == "point3d"]
        else:
            missing = [n for n in self._wanted if n not in by_name]
            if missing:
                raise ConfigurationError(f"live pipeline: no stream named {missing}")
            chosen = [by_name[n] for n in self._wanted]
        if len(chosen) != 1 or not is_points(chosen[0]):
            raise ConfigurationError(
                "live pipeline without a rig needs one point3d stream of x, y, z; got "
                f"{[(s.name, s.kind) for s in chosen] or 'none'}"
            )
        spec = chosen[0]
        unknown = sorted(set(self._clocks) - {spec.name})
        if unknown:
            raise ConfigurationError(f"clocks given for streams not read here: {unknown}")
        self._streams = {spec.name: _Stream(0, spec, 0, self._clocks.get(spec.name))}
        self._matcher = None
        self.labels = point_labels(spec)
        self._tell_consumers(spec.n_markers, spec.rate_hz)

    def _tell_consumers(self, n_markers: int, rate_hz: float) -> None:
        """Call ``on_configure(spec)`` of the consumers that have it: the output's spec."""
        spec = marker_spec(n_markers, rate_hz, self.name, self.labels)
        for consumer in self.consumers:
            hook = getattr(consumer, "on_configure", None)
            if callable(hook):
                hook(spec)

    # -- frames -----------------------------------------------------------------
    def on_block(self, stream: str, block: Any) -> None:
        """Frames of one stream: triangulate and hand out every decided frame."""
        st = self._streams.get(stream)
        n = len(block)
        if st is None or not n:
            return
        if self._triangulate is None:  # 3-D points already: x, y, z of the one sensor
            uv = np.asarray(block.data[:, :, 0, :3], dtype=np.float64)
        else:
            uv = pixels_by_marker(st.spec, block.data, block.flags)  # no transposed copy
        with self._lock:
            st.frames += n
            try:
                times = st.frame_times(block.ticks)
            except SpotlabError:
                self._unclocked += n
                return
            arrival, seq = block.arrival_ns, block.seq
            for i in range(n):
                item = _Item(uv[i], int(arrival[i]), int(seq[i]), st, float(times[i]))
                if self._matcher is None:
                    self._emit([item])
                else:
                    for _, group in self._matcher.add(st.index, item.time_s, item):
                        self._emit(group)

    def on_error(self, stream: str, exc: BaseException) -> None:
        """Device errors are the session's to report; the pipeline goes on."""

    def stop(self) -> None:
        """Hand out the frames still waiting for their group (several streams)."""
        with self._lock:
            if self._matcher is not None:
                for _, group in self._matcher.flush():
                    self._emit(group)

    def _emit(self, group: Sequence[_Item | None]) -> None:
        """Triangulate one frame time (one item per stream, None where missing)."""
        members = [g for g in group if g is not None]
        if len(group) == 1:
            uv = members[0].uv
        else:
            uv = self._uv
            uv.fill(np.nan)
            for g in members:
                uv[:, g.stream.cameras] = g.uv
        try:
            if self._triangulate is None:  # passed through: the vendor's reconstruction
                X = uv.copy()
                rms = np.full(len(X), np.nan)
                n_views = np.zeros(len(X), dtype=np.intp)
            else:
                X, rms, n_views = self._triangulate.by_marker(uv)
        except SpotlabError as exc:
            self._failed += 1
            if self._failures.add(exc):  # the first of its kind: counted all the same
                log.error("live pipeline: frame %d not triangulated: %s", self._index, exc)
            return
        ref = members[0]  # the first stream present gives the frame's times
        last = ref if len(members) == 1 else max(members, key=lambda m: m.arrival_ns)
        frame = LiveFrame(
            index=self._index,
            seq=ref.seq if group[0] is not None else -1,
            frame_time_s=ref.time_s,
            time_s=ref.time_s + ref.stream.offsets,
            points=X,
            residual_px=rms,
            n_views=n_views,
            arrival_ns=last.arrival_ns,
            labels=self.labels,
        )
        self._index += 1
        latency = time.monotonic_ns() - last.arrival_ns
        self.latency.add(latency)
        last.stream.latency.add(latency)
        for consumer in self.consumers:
            try:
                consumer(frame)
            except Exception as exc:
                self._consumer_errors += 1
                if self._failures.add(exc):  # the first of its kind: counted all the same
                    log.exception("live pipeline: consumer %r failed", consumer)

    # -- figures ------------------------------------------------------------------
    def reset_latency(self) -> None:
        """Forget the latencies so far (for example those of a warm-up)."""
        with self._lock:
            self.latency = LatencyStats()
            for st in self._streams.values():
                st.latency = LatencyStats()

    def stats(self) -> LiveStats:
        """Counters and latency figures so far."""
        matcher = self._matcher
        streams = self._streams.values()
        return LiveStats(
            frames_in={s.spec.name: s.frames for s in streams},
            frames_out=self._index,
            incomplete=0 if matcher is None else matcher.incomplete,
            unclocked=self._unclocked,
            failed=self._failed,
            late=0 if matcher is None else matcher.late,
            consumer_errors=self._consumer_errors,
            latency=self.latency.summary(),
            latency_by_stream={s.spec.name: s.latency.summary() for s in streams},
            failures=self._failures.snapshot(),
        )
