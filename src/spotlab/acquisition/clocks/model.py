"""Piecewise affine clock model: device ticks (int64) to session seconds.

Within one segment ``t = offset + rate * (ticks - origin)``; ``origin`` is an int64
tick inside the segment, subtracted in integer arithmetic before the conversion to
float, so the map keeps 1e-9 s resolution for days at GHz tick rates (a float64
holds ticks exactly only up to 2**53).

A device clock that steps (its counter jumps relative to the reference) starts a new
segment in the same *epoch*; a counter that goes backwards (device reset, a step back
larger than a frame period) starts a new epoch, since ticks alone no longer say which
segment a frame belongs to.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from spotlab.core.errors import ClockError

I64 = npt.NDArray[np.int64]
F64 = npt.NDArray[np.float64]

EVENT_KINDS = ("step", "reset", "wrap")
FORMAT = "spotlab.clock_model"
VERSION = 1


@dataclass(frozen=True)
class ClockEvent:
    """A discontinuity of a device clock.

    Attributes
    ----------
    kind : {"step", "reset", "wrap"}
        ``step``: the counter jumped relative to the reference (forwards or backwards)
        while still counting up; ``reset``: the counter went backwards (device restart,
        a step back larger than a frame period); ``wrap``: a step of a whole number of
        counter periods (2**16 or 2**32 ticks), a wrap the unwrapper missed or added.
    at_tick : int
        First device tick of the new segment.
    size_s : float
        Jump of the device clock relative to the reference, s: device time after minus
        device time the old segment predicts for the same reference instant
        (positive: the device clock jumped ahead).
    index : int
        Index of the first fitted pair after the event (-1 when not known).
    """

    kind: str
    at_tick: int
    size_s: float
    index: int = -1

    def __post_init__(self) -> None:
        if self.kind not in EVENT_KINDS:
            raise ClockError(f"clock event kind must be one of {EVENT_KINDS}, got {self.kind!r}")


@dataclass(frozen=True)
class ClockSegment:
    """One affine piece of a clock model.

    Attributes
    ----------
    epoch : int
        Counter epoch (0 before the first reset, +1 at each reset).
    tick_start, tick_end : int
        First and last device tick fitted in this segment (inclusive).
    origin : int
        Tick at which ``offset_s`` holds.
    offset_s : float
        Session time at ``origin``, s.
    rate : float
        Session seconds per device tick.
    n : int
        Number of pairs fitted.
    jitter_s : float
        Robust standard deviation of the residuals (1.4826 x median absolute
        deviation), s.
    rms_s, max_abs_s : float
        RMS and largest absolute residual, s.
    """

    epoch: int
    tick_start: int
    tick_end: int
    origin: int
    offset_s: float
    rate: float
    n: int = 0
    jitter_s: float = 0.0
    rms_s: float = 0.0
    max_abs_s: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.offset_s) and math.isfinite(self.rate) and self.rate > 0):
            raise ClockError(
                f"segment needs a finite offset and a positive rate, got {self.offset_s}, "
                f"{self.rate}"
            )
        if self.tick_end < self.tick_start:
            raise ClockError(f"segment tick range {self.tick_start}..{self.tick_end} is empty")

    def seconds(self, ticks: I64) -> F64:
        """Session seconds of int64 ``ticks``, shape (N,) -> (N,)."""
        dt = (np.asarray(ticks, dtype=np.int64) - np.int64(self.origin)).astype(np.float64)
        return np.asarray(self.offset_s + self.rate * dt, dtype=np.float64)

    def ticks(self, seconds: F64) -> F64:
        """Device ticks (float) of session ``seconds``, shape (N,) -> (N,)."""
        return np.asarray(self.origin + (np.asarray(seconds) - self.offset_s) / self.rate)


@dataclass(frozen=True, eq=False, init=False)
class ClockModel:
    """Piecewise affine map of one device's ticks to session seconds.

    Parameters
    ----------
    tick_hz : float
        Nominal tick rate of the device, Hz (drift is measured against it).
    segments : sequence of ClockSegment
        Ordered by epoch, then by ``tick_start``.
    events : sequence of ClockEvent
        Steps, resets and wraps, in order.
    residuals : ndarray of float64, shape (N,), optional
        Residuals of the fitted pairs, s (reference minus model), in input order.
    method : str
        How the model was fitted ("edges", "probes", "arrivals", "xdf", ...).

    Raises
    ------
    ClockError
        No segment, a non-positive tick rate, segments out of order.

    Examples
    --------
    >>> import numpy as np
    >>> seg = ClockSegment(epoch=0, tick_start=0, tick_end=10**6, origin=0,
    ...                    offset_s=2.0, rate=1e-6)
    >>> m = ClockModel(1e6, [seg])
    >>> float(m(np.array([500_000]))[0])
    2.5
    """

    tick_hz: float
    segments: tuple[ClockSegment, ...]
    events: tuple[ClockEvent, ...] = ()
    residuals: F64 = field(default_factory=lambda: np.zeros(0))
    method: str = ""

    def __init__(
        self,
        tick_hz: float,
        segments: Sequence[ClockSegment],
        events: Sequence[ClockEvent] = (),
        residuals: npt.ArrayLike | None = None,
        method: str = "",
    ) -> None:
        if not (math.isfinite(tick_hz) and tick_hz > 0):
            raise ClockError(f"tick rate must be finite and positive, got {tick_hz}")
        segs = tuple(segments)
        if not segs:
            raise ClockError("a clock model needs at least one segment")
        keys = [(s.epoch, s.tick_start) for s in segs]
        if any(b <= a for a, b in itertools.pairwise(keys)):
            raise ClockError("segments must be ordered by epoch, then by first tick")
        res = np.zeros(0) if residuals is None else np.asarray(residuals, dtype=np.float64)
        object.__setattr__(self, "tick_hz", float(tick_hz))
        object.__setattr__(self, "segments", segs)
        object.__setattr__(self, "events", tuple(events))
        object.__setattr__(self, "residuals", res.reshape(-1))
        object.__setattr__(self, "method", str(method))

    # -- figures -------------------------------------------------------------
    @property
    def epochs(self) -> int:
        """Number of counter epochs (1 + number of resets)."""
        return self.segments[-1].epoch - self.segments[0].epoch + 1

    @property
    def segment_drift_ppm(self) -> F64:
        """Drift of each segment against the nominal tick rate, ppm, shape (S,).

        Positive: the device clock runs fast (fewer session seconds per tick).
        """
        rates = np.array([s.rate for s in self.segments])
        return np.asarray((1.0 / (rates * self.tick_hz) - 1.0) * 1e6)

    @property
    def drift_ppm(self) -> float:
        """Drift, ppm, averaged over segments weighted by their number of pairs."""
        n = np.array([max(s.n, 1) for s in self.segments], dtype=np.float64)
        return float(np.sum(self.segment_drift_ppm * n) / np.sum(n))

    @property
    def jitter_s(self) -> float:
        """Jitter, s: root of the pair-weighted mean of the segments' squared jitters."""
        n = np.array([max(s.n, 1) for s in self.segments], dtype=np.float64)
        j = np.array([s.jitter_s for s in self.segments])
        return float(np.sqrt(np.sum(n * j**2) / np.sum(n)))

    # -- mapping -------------------------------------------------------------
    def epochs_of(self, ticks: npt.ArrayLike, first_epoch: int | None = None) -> I64:
        """Epoch of each tick of a sequence in acquisition order, shape (N,).

        Each backwards step of the counter starts the next epoch; the sequence starts in
        ``first_epoch`` (default: the model's first epoch).
        """
        tk = _as_ticks(ticks)
        start = self.segments[0].epoch if first_epoch is None else int(first_epoch)
        back = np.concatenate([[0], np.cumsum(np.diff(tk) < 0)]) if tk.size else tk
        return np.asarray(start + back, dtype=np.int64)

    def _boundaries(self, members: npt.NDArray[np.intp]) -> I64:
        """First tick each segment of one epoch owns, shape (S,).

        Between two segments the boundary lies in the gap of ticks between their fitted
        ranges: at the mean of the ticks the two segments assign to the middle of the
        gap in session time. A tick jump far larger than the gap (a wrap, a big step)
        is thereby split correctly however long the gap is.
        """
        segs = [self.segments[i] for i in members]
        out = np.empty(len(segs), dtype=np.int64)
        out[0] = segs[0].tick_start
        for j in range(1, len(segs)):
            prev, nxt = segs[j - 1], segs[j]
            t_end = float(prev.seconds(np.array([prev.tick_end]))[0])
            t_start = float(nxt.seconds(np.array([nxt.tick_start]))[0])
            t_mid = np.array([0.5 * (t_end + t_start)])
            mid = 0.5 * (float(prev.ticks(t_mid)[0]) + float(nxt.ticks(t_mid)[0]))
            out[j] = int(np.clip(math.ceil(mid), prev.tick_end + 1, nxt.tick_start))
        return out

    def _segment_index(self, ticks: I64, epoch: I64) -> npt.NDArray[np.intp]:
        idx = np.empty(ticks.shape, dtype=np.intp)
        ep = np.array([s.epoch for s in self.segments])
        for e in np.unique(epoch):
            members = np.flatnonzero(ep == e)
            if members.size == 0:
                raise ClockError(f"the clock model has no segment in epoch {int(e)}")
            starts = self._boundaries(members)
            sel = epoch == e
            pos = np.searchsorted(starts, ticks[sel], side="right") - 1
            idx[sel] = members[np.clip(pos, 0, members.size - 1)]
        return idx

    def __call__(self, ticks: npt.ArrayLike, epoch: npt.ArrayLike | None = None) -> F64:
        """Session seconds of device ticks.

        Parameters
        ----------
        ticks : array_like of int, shape (N,)
            Unwrapped device ticks (int64).
        epoch : int or array_like of int, shape (N,), optional
            Counter epoch of each tick. Default: one epoch if the model has one,
            else inferred from the sequence (see :meth:`epochs_of`).

        Returns
        -------
        ndarray of float64, shape (N,)
            Session time, s. Ticks outside a segment's range use the nearest segment of
            the same epoch (extrapolation).
        """
        tk = _as_ticks(ticks)
        if epoch is None:
            ep = self.epochs_of(tk)
        else:
            ep = np.broadcast_to(np.asarray(epoch, dtype=np.int64), tk.shape)
        idx = self._segment_index(tk, ep)
        origin = np.array([s.origin for s in self.segments], dtype=np.int64)[idx]
        offset = np.array([s.offset_s for s in self.segments])[idx]
        rate = np.array([s.rate for s in self.segments])[idx]
        return np.asarray(offset + rate * (tk - origin).astype(np.float64), dtype=np.float64)

    def inverse(self, seconds: npt.ArrayLike, epoch: int | None = None) -> F64:
        """Device ticks (float64) of session times.

        Parameters
        ----------
        seconds : array_like, shape (N,)
            Session times, s.
        epoch : int, optional
            Restrict to the segments of this epoch; default all segments.

        Returns
        -------
        ndarray of float64, shape (N,)
            Ticks; a time falls in the segment that started last before it (by the
            session time of the segment's first tick).
        """
        t = np.asarray(seconds, dtype=np.float64).reshape(-1)
        if not np.all(np.isfinite(t)):
            raise ClockError("session times must be finite")
        members = [i for i, s in enumerate(self.segments) if epoch is None or s.epoch == int(epoch)]
        if not members:
            raise ClockError(f"the clock model has no segment in epoch {epoch}")
        segs = [self.segments[i] for i in members]
        starts = np.array([float(s.seconds(np.array([s.tick_start]))[0]) for s in segs])
        order = np.argsort(starts, kind="stable")
        pos = np.clip(np.searchsorted(starts[order], t, side="right") - 1, 0, len(segs) - 1)
        out = np.empty_like(t)
        for k in np.unique(pos):
            seg = segs[int(order[k])]
            sel = pos == k
            out[sel] = seg.ticks(t[sel])
        return out

    # -- storage -------------------------------------------------------------
    def to_dict(self, include_residuals: bool = False) -> dict[str, Any]:
        """JSON-safe description (floats, ints, strings, lists), for journal metadata."""
        out: dict[str, Any] = {
            "format": FORMAT,
            "version": VERSION,
            "tick_hz": self.tick_hz,
            "method": self.method,
            "drift_ppm": self.drift_ppm,
            "jitter_s": self.jitter_s,
            "segments": [
                {
                    "epoch": s.epoch,
                    "tick_start": s.tick_start,
                    "tick_end": s.tick_end,
                    "origin": s.origin,
                    "offset_s": s.offset_s,
                    "rate": s.rate,
                    "n": s.n,
                    "jitter_s": s.jitter_s,
                    "rms_s": s.rms_s,
                    "max_abs_s": s.max_abs_s,
                }
                for s in self.segments
            ],
            "events": [
                {"kind": e.kind, "at_tick": e.at_tick, "size_s": e.size_s, "index": e.index}
                for e in self.events
            ],
        }
        if include_residuals:
            out["residuals"] = [float(r) for r in self.residuals]
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ClockModel:
        """Model from :meth:`to_dict` output; ClockError names what is wrong."""
        try:
            if data.get("format") != FORMAT or int(data["version"]) != VERSION:
                raise ClockError(
                    f"not a {FORMAT} version {VERSION} description: "
                    f"{data.get('format')!r} version {data.get('version')!r}"
                )
            segs = [
                ClockSegment(
                    epoch=int(s["epoch"]),
                    tick_start=int(s["tick_start"]),
                    tick_end=int(s["tick_end"]),
                    origin=int(s["origin"]),
                    offset_s=float(s["offset_s"]),
                    rate=float(s["rate"]),
                    n=int(s.get("n", 0)),
                    jitter_s=float(s.get("jitter_s", 0.0)),
                    rms_s=float(s.get("rms_s", 0.0)),
                    max_abs_s=float(s.get("max_abs_s", 0.0)),
                )
                for s in data["segments"]
            ]
            events = [
                ClockEvent(
                    kind=str(e["kind"]),
                    at_tick=int(e["at_tick"]),
                    size_s=float(e["size_s"]),
                    index=int(e.get("index", -1)),
                )
                for e in data.get("events", [])
            ]
            return cls(
                float(data["tick_hz"]),
                segs,
                events,
                residuals=data.get("residuals"),
                method=str(data.get("method", "")),
            )
        except (KeyError, TypeError, ValueError) as exc:
            if isinstance(exc, ClockError):
                raise
            raise ClockError(f"clock model description is incomplete or malformed: {exc}") from exc


def _as_ticks(ticks: npt.ArrayLike) -> I64:
    arr = np.asarray(ticks)
    if arr.dtype.kind == "f":
        if not np.all(np.isfinite(arr)):
            raise ClockError("ticks must be finite (NaN or infinite tick)")
        if np.any(arr != np.round(arr)):
            raise ClockError("ticks must be whole numbers")
    elif arr.dtype.kind not in "iu" and arr.size:
        raise ClockError(f"ticks must be integers, got dtype {arr.dtype}")
    return np.asarray(arr, dtype=np.int64).reshape(-1)
