"""Several streams of different rates and families on one time base."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import numpy.typing as npt

from spotlab.acquisition.synchroniser.gaps import TIME_GAP, check_frames, valid_runs
from spotlab.acquisition.synchroniser.resample import Resampled, resample
from spotlab.acquisition.synchroniser.sample_times import sample_offsets
from spotlab.core.errors import SynchronisationError
from spotlab.core.streams import StreamSpec

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

__all__ = ["StreamInput", "StreamStats", "Synchronised", "Synchroniser"]


@dataclass(frozen=True)
class StreamInput:
    """One stream to synchronise: its frames on the session clock.

    Parameters
    ----------
    spec : StreamSpec
        What the stream is (its name, nominal rate, slot period, markers).
    seq : array_like of int, shape (F,)
        Unwrapped sequence numbers, strictly increasing; jumps are lost frames.
    frame_times : array_like, shape (F,)
        Session time of each frame (its first sample), s, from the device's clock model.
    data : array_like, shape (F, M, ...)
        Samples per frame and marker (then sensors, values), NaN where missing.
    clock_rate : float
        Session seconds per device second of the stream's clock (``1 + drift``); scales
        the slot offsets and the nominal frame period.
    """

    spec: StreamSpec
    seq: npt.ArrayLike
    frame_times: npt.ArrayLike
    data: npt.ArrayLike
    clock_rate: float = 1.0

    @property
    def name(self) -> str:
        """The stream's name (``spec.name``)."""
        return self.spec.name


@dataclass(frozen=True)
class StreamStats:
    """What the synchroniser saw in one stream.

    Attributes
    ----------
    name, kind : str
        From the stream's spec.
    n_frames : int
        Frames given.
    lost_frames : int
        Frames missing according to seq (sum of the jumps beyond 1).
    time_gaps : int
        Frame intervals longer than the largest allowed one times their seq step
        (stalls, clock steps).
    missing_runs : int
        Runs of missing (NaN) samples, over every channel, not counting lost frames.
    rate_hz : float
        Measured frame rate, 1 / median frame interval, Hz.
    first_time_s, last_time_s : float
        Session times of the first and last frame, s.
    valid_fraction : float
        Fraction of the resampled values that are given (flag 0).
    """

    name: str
    kind: str
    n_frames: int
    lost_frames: int
    time_gaps: int
    missing_runs: int
    rate_hz: float
    first_time_s: float
    last_time_s: float
    valid_fraction: float


@dataclass(frozen=True)
class Synchronised:
    """Every stream at the same instants.

    Attributes
    ----------
    times : ndarray, shape (T,)
        The common instants, session s.
    streams : dict of str to Resampled
        Per stream name: values (T, M, ...) and flags (T, M, ...).
    stats : dict of str to StreamStats
        Per stream name.
    """

    times: F64
    streams: dict[str, Resampled] = field(default_factory=dict)
    stats: dict[str, StreamStats] = field(default_factory=dict)


@dataclass(frozen=True)
class _Checked:
    spec: StreamSpec
    seq: I64
    times: F64
    data: F64
    offsets: F64
    max_interval_s: float


class Synchroniser:
    """Resamples streams of different rates and families at common instants.

    Parameters
    ----------
    streams : sequence of StreamInput
        At least one; names unique.
    slot_correction : bool
        Give each marker of a time-multiplexed stream its slot time (frame time + (k +
        1/2) slot); when false every marker is taken at its frame's time (for comparison
        only: this biases moving markers by their speed times the offset).
    max_gap_periods : float
        A frame interval longer than this many nominal frame periods is a gap (> 1).

    Raises
    ------
    SynchronisationError
        No stream, duplicate names, a stream with fewer than 2 frames, seq or times not
        strictly increasing, data whose shape disagrees with the frames or the spec's
        marker count; the stream is named.

    Examples
    --------
    >>> import numpy as np
    >>> from spotlab.core import StreamSpec
    >>> a = StreamSpec("a", "point3d", 1, 1, 100.0, 1e6)
    >>> b = StreamSpec("b", "point3d", 1, 1, 50.0, 1e6)
    >>> ta, tb = np.arange(101) / 100.0, np.arange(51) / 50.0
    >>> sync = Synchroniser([
    ...     StreamInput(a, np.arange(101), ta, ta[:, None, None] ** 2),
    ...     StreamInput(b, np.arange(51), tb, tb[:, None, None] ** 2),
    ... ])
    >>> out = sync.resample()
    >>> out.times.size, bool(np.allclose(out.streams["b"].values[:, 0, 0], out.times**2))
    (101, True)
    """

    def __init__(
        self,
        streams: Sequence[StreamInput],
        *,
        slot_correction: bool = True,
        max_gap_periods: float = 1.5,
    ) -> None:
        if not streams:
            raise SynchronisationError("nothing to synchronise: no stream given")
        if not max_gap_periods > 1:
            raise SynchronisationError(f"max_gap_periods must be > 1, got {max_gap_periods}")
        names = [s.name for s in streams]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise SynchronisationError(f"stream names must be unique, repeated: {dup}")
        self.slot_correction = slot_correction
        self._streams = [self._check(s, slot_correction, max_gap_periods) for s in streams]

    @staticmethod
    def _check(stream: StreamInput, slot_correction: bool, max_gap_periods: float) -> _Checked:
        spec = stream.spec
        try:
            seq, times = check_frames(stream.seq, stream.frame_times)
            data = np.asarray(stream.data, dtype=np.float64)
            if data.ndim < 2 or data.shape[0] != times.size:
                raise SynchronisationError(
                    f"data must have shape (F, M, ...) with F = {times.size}, got {data.shape}"
                )
            if data.shape[1] != spec.n_markers:
                raise SynchronisationError(
                    f"data has {data.shape[1]} markers, the spec {spec.n_markers}"
                )
            offsets = sample_offsets(spec, stream.clock_rate)
        except SynchronisationError as exc:
            raise SynchronisationError(f"stream {spec.name!r}: {exc}") from exc
        if not slot_correction:
            offsets = np.zeros_like(offsets)
        period = stream.clock_rate / spec.rate_hz
        return _Checked(spec, seq, times, data, offsets, max_gap_periods * period)

    @property
    def names(self) -> list[str]:
        """Stream names, in the order given."""
        return [s.spec.name for s in self._streams]

    def instants(
        self,
        rate_hz: float | None = None,
        *,
        span: Literal["overlap", "union"] = "overlap",
        start: float | None = None,
        stop: float | None = None,
    ) -> F64:
        """Common instants at a fixed rate.

        Parameters
        ----------
        rate_hz : float, optional
            Rate of the instants, Hz; the fastest stream's nominal rate when omitted.
        span : {"overlap", "union"}
            ``overlap``: from the first instant at which every sample of every stream
            has begun to the last at which none has ended; ``union``: from the earliest
            sample of any stream to the latest.
        start, stop : float, optional
            Override the span's ends, session s.

        Returns
        -------
        ndarray, shape (T,)
            ``start + j / rate_hz`` for ``j = 0, 1, ...`` while ``<= stop``.

        Raises
        ------
        SynchronisationError
            A rate that is not positive, an unknown span, or streams that do not overlap.
        """
        rate = max(s.spec.rate_hz for s in self._streams) if rate_hz is None else rate_hz
        if not (np.isfinite(rate) and rate > 0):
            raise SynchronisationError(f"rate must be finite and positive, got {rate_hz}")
        firsts = [(s.times[0] + s.offsets.min(initial=0.0)) for s in self._streams]
        firsts_all = [(s.times[0] + s.offsets.max(initial=0.0)) for s in self._streams]
        lasts = [(s.times[-1] + s.offsets.max(initial=0.0)) for s in self._streams]
        lasts_all = [(s.times[-1] + s.offsets.min(initial=0.0)) for s in self._streams]
        if span == "overlap":
            t0, t1 = max(firsts_all), min(lasts_all)
        elif span == "union":
            t0, t1 = min(firsts), max(lasts)
        else:
            raise SynchronisationError(f"span must be 'overlap' or 'union', got {span!r}")
        t0 = t0 if start is None else float(start)
        t1 = t1 if stop is None else float(stop)
        if not t1 >= t0:
            raise SynchronisationError(
                f"no common instants: the span ends ({t1!r} s) before it starts ({t0!r} s)"
                + ("; the streams do not overlap in time" if span == "overlap" else "")
            )
        n = int(np.floor((t1 - t0) * rate * (1.0 + 1e-12))) + 1
        return t0 + np.arange(n) / rate

    def resample(
        self,
        instants: npt.ArrayLike | None = None,
        *,
        rate_hz: float | None = None,
        span: Literal["overlap", "union"] = "overlap",
    ) -> Synchronised:
        """Every stream at the same instants.

        Parameters
        ----------
        instants : array_like, shape (T,), optional
            Session times, s; from :meth:`instants` (``rate_hz``, ``span``) when omitted.
        rate_hz, span
            As in :meth:`instants`.

        Returns
        -------
        Synchronised
        """
        times = (
            self.instants(rate_hz, span=span)
            if instants is None
            else np.asarray(instants, dtype=np.float64)
        )
        out: dict[str, Resampled] = {}
        stats: dict[str, StreamStats] = {}
        for s in self._streams:
            r = resample(
                s.times,
                s.data,
                times,
                offsets=s.offsets,
                seq=s.seq,
                max_interval_s=s.max_interval_s,
            )
            out[s.spec.name] = r
            stats[s.spec.name] = _stats(s, r)
        return Synchronised(times=times, streams=out, stats=stats)


def _stats(s: _Checked, r: Resampled) -> StreamStats:
    present = np.isfinite(s.data.reshape(s.times.size, -1))
    n_missing_runs = len(valid_runs(~present))
    return StreamStats(
        name=s.spec.name,
        kind=s.spec.kind,
        n_frames=int(s.times.size),
        lost_frames=int(np.sum(np.diff(s.seq) - 1)),
        time_gaps=int(np.count_nonzero(r.frame_gaps & TIME_GAP)),
        missing_runs=n_missing_runs,
        rate_hz=float(1.0 / np.median(np.diff(s.times))),
        first_time_s=float(s.times[0]),
        last_time_s=float(s.times[-1]),
        valid_fraction=float(np.mean(r.valid)) if r.flags.size else 0.0,
    )
