"""What the live pipeline hands to its consumers, and two consumers: LSL and a file."""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import ConfigurationError, RecordingError
from spotlab.core.streams import StreamSpec

__all__ = ["LiveFrame", "LslMarkers", "MarkerPusher", "PointRecorder"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class LiveFrame:
    """The 3-D markers of one frame time.

    Attributes
    ----------
    index : int
        Frame number in the pipeline's output, from 0.
    seq : int
        Sequence number of the frame in the first stream (-1 if it missed the group).
    frame_time_s : float
        Session time of the frame (its first slot's start), s.
    time_s : ndarray, shape (M,)
        Session time of each marker's sample (frame time plus its LED slot offset), s.
    points : ndarray, shape (M, 3)
        Marker positions, mm; NaN where fewer than two cameras saw a marker (or,
        passed through from a ``point3d`` stream, where its system had no point).
    residual_px : ndarray, shape (M,)
        RMS distance of the marker's rays from its point, undistorted px; NaN with it
        (and NaN for points passed through: not triangulated here).
    n_views : ndarray of int, shape (M,)
        Cameras that saw each marker (0 for points passed through: not known here).
    arrival_ns : int
        Host arrival of the last byte of the frame (the latest of the group's streams),
        ``time.monotonic_ns`` clock.
    labels : tuple of str
        Marker names (M,): a ``point3d`` stream's ``marker_labels``, else ``m<k>``.
    """

    index: int
    seq: int
    frame_time_s: float
    time_s: FloatArray
    points: FloatArray
    residual_px: FloatArray
    n_views: NDArray[np.intp]
    arrival_ns: int
    labels: tuple[str, ...] = ()


class MarkerPusher(Protocol):
    """What :class:`LslMarkers` needs of an outlet (``spotlab.acquisition.lsl.MarkerOutlet``)."""

    def push_markers(self, time_s: FloatArray, X: FloatArray) -> None:
        """Publish positions (M, 3) at one session time."""


class LslMarkers:
    """Consumer publishing every frame's points on an LSL marker outlet.

    Parameters
    ----------
    outlet : MarkerOutlet, optional
        For example ``MarkerOutlet(n_markers, rate_hz)`` (the ``lsl`` extra); its
        timestamps are the frames' session times. Default: a ``MarkerOutlet`` made
        when the pipeline sets its inputs (:meth:`on_configure`), with the pipeline's
        marker count, rate and labels (a ``point3d`` stream's ``marker_labels``).
    **outlet_kwargs
        For the outlet made here: ``name``, ``source_id``, ``channel_format``,
        ``clock``, ``max_buffered_s`` (see ``MarkerOutlet``).
    """

    def __init__(self, outlet: MarkerPusher | None = None, **outlet_kwargs: Any) -> None:
        self.outlet = outlet
        self._kwargs = outlet_kwargs
        self._made = False

    def on_configure(self, spec: StreamSpec) -> None:
        """Make the outlet (if none was given) for the pipeline's output ``spec``.

        Raises
        ------
        ConfigurationError
            If pylsl is missing.
        """
        if self.outlet is not None:
            return
        from spotlab.acquisition.lsl import MarkerOutlet

        labels = [str(x) for x in spec.metadata.get("marker_labels", [])]
        self.outlet = MarkerOutlet(spec.n_markers, spec.rate_hz, labels=labels, **self._kwargs)
        self._made = True

    def __call__(self, frame: LiveFrame) -> None:
        """Push the frame (its time is the frame time: one LSL sample per frame)."""
        if self.outlet is None:
            raise ConfigurationError("LslMarkers has no outlet: the pipeline was not configured")
        self.outlet.push_markers(np.array([frame.frame_time_s]), frame.points)

    def close(self) -> None:
        """Close the outlet made here (its ports close); one given stays the caller's."""
        if self._made and self.outlet is not None:
            close = getattr(self.outlet, "close", None)
            if callable(close):
                close()
            self.outlet = None
            self._made = False


class PointRecorder:
    """Consumer keeping every frame's results, written to ``.npz`` or ``.c3d`` at the end.

    Memory grows with the run (about 4 kB per frame of 128 markers): meant for runs of
    minutes; the journal of the raw bytes is the record of long sessions.
    """

    def __init__(self) -> None:
        self._frames: list[LiveFrame] = []
        self._lock = threading.Lock()

    def __call__(self, frame: LiveFrame) -> None:
        """Keep one frame."""
        with self._lock:
            self._frames.append(frame)

    def __len__(self) -> int:
        return len(self._frames)

    def arrays(self) -> dict[str, NDArray[np.generic]]:
        """The results stacked per frame: ``seq`` (F,), ``frame_time_s`` (F,), ``time_s``
        (F, M), ``points`` (F, M, 3), ``residual_px`` (F, M), ``n_views`` (F, M),
        ``arrival_ns`` (F,).

        Raises
        ------
        ConfigurationError
            If no frame was recorded.
        """
        with self._lock:
            frames = list(self._frames)
        if not frames:
            raise ConfigurationError("the live pipeline produced no frame to keep")
        return {
            "seq": np.array([f.seq for f in frames], dtype=np.int64),
            "frame_time_s": np.array([f.frame_time_s for f in frames]),
            "time_s": np.stack([f.time_s for f in frames]),
            "points": np.stack([f.points for f in frames]),
            "residual_px": np.stack([f.residual_px for f in frames]),
            "n_views": np.stack([f.n_views for f in frames]),
            "arrival_ns": np.array([f.arrival_ns for f in frames], dtype=np.int64),
        }

    def save(self, path: str | os.PathLike[str], rate_hz: float | None = None) -> Path:
        """Write the results: ``.npz`` (every array of :meth:`arrays`) or ``.c3d`` (the
        frames' marker labels, else ``m<k>``).

        Parameters
        ----------
        path : str or Path
            Output file; its suffix chooses the format.
        rate_hz : float, optional
            Frame rate for C3D (default: from the median frame interval).

        Raises
        ------
        RecordingError
            For another suffix, or a C3D rate that cannot be found.
        """
        out = Path(path)
        data = self.arrays()
        suffix = out.suffix.lower()
        if suffix == ".npz":
            np.savez(out, **data)  # type: ignore[arg-type]
            return out
        if suffix != ".c3d":
            raise RecordingError(f"{out}: write live results as .npz or .c3d")
        from spotlab.io import Trial, write_c3d

        if rate_hz is None:
            dt = np.diff(np.asarray(data["frame_time_s"], dtype=np.float64))
            rate_hz = float(1.0 / np.median(dt)) if dt.size else float("nan")
        if not (np.isfinite(rate_hz) and rate_hz > 0):
            raise RecordingError(f"{out}: no frame rate for C3D (give rate_hz)")
        points = np.asarray(data["points"], dtype=np.float64)
        with self._lock:
            named = self._frames[-1].labels if self._frames else ()
        labels = list(named) if len(named) == points.shape[1] else None
        labels = labels or [f"m{i}" for i in range(points.shape[1])]
        write_c3d(out, Trial(points=points, labels=labels, point_rate=rate_hz))
        return out
