"""Resampling one stream at common instants by cubic spline interpolation, never across a gap."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from spotlab.acquisition.synchroniser import _spline
from spotlab.acquisition.synchroniser.gaps import MISSING, OUTSIDE, check_frames, frame_gaps
from spotlab.core.errors import SynchronisationError

F64 = npt.NDArray[np.float64]
U8 = npt.NDArray[np.uint8]
B = npt.NDArray[np.bool_]

__all__ = ["Resampled", "resample"]

#: Samples plus instants times channels per block of markers.
_BLOCK = 1 << 20


@dataclass(frozen=True)
class Resampled:
    """A stream resampled at common instants.

    Attributes
    ----------
    values : ndarray, shape (T, M, ...)
        Values at the instants, in the stream's units; NaN where ``flags`` is not 0.
    flags : ndarray of uint8, shape (T, M, ...)
        Why there is no value: ``OUTSIDE``, ``LOST_FRAMES``, ``TIME_GAP``, ``MISSING``
        (see :mod:`spotlab.acquisition.synchroniser.gaps`), 0 where the value is given.
    frame_gaps : ndarray of uint8, shape (F - 1,)
        Gap flags of the stream's frame intervals.
    """

    values: F64
    flags: U8
    frame_gaps: U8

    @property
    def valid(self) -> B:
        """Where a value is given, shape (T, M, ...)."""
        return self.flags == 0


def resample(
    frame_times: npt.ArrayLike,
    values: npt.ArrayLike,
    instants: npt.ArrayLike,
    *,
    offsets: npt.ArrayLike | None = None,
    seq: npt.ArrayLike | None = None,
    max_interval_s: float = np.inf,
) -> Resampled:
    r"""Values of a stream at given instants, by cubic spline interpolation within gaps.

    Parameters
    ----------
    frame_times : array_like, shape (F,)
        Session time of each frame, s, strictly increasing.
    values : array_like, shape (F, M, ...)
        Samples per frame and marker (any trailing axes: sensors, values); NaN where
        missing.
    instants : array_like, shape (T,)
        Session times to resample at, s (any order).
    offsets : array_like, shape (M,), optional
        Time of each marker's sample after its frame's time, s (see
        :func:`~spotlab.acquisition.synchroniser.sample_offsets`); zeros when omitted.
    seq : array_like of int, shape (F,), optional
        Unwrapped sequence numbers; a jump of more than 1 is a gap (lost frames).
        Consecutive numbers are assumed when omitted.
    max_interval_s : float
        Frame intervals longer than this are gaps (a stall or a clock step), s.

    Returns
    -------
    Resampled

    Raises
    ------
    SynchronisationError
        Fewer than 2 frames, shapes that disagree, times or seq not strictly increasing,
        non-finite instants or offsets.

    Notes
    -----
    Sample ``f`` of marker ``m`` was taken at :math:`t_{f,m} = T_f + o_m`. Every channel
    (marker and trailing index) is interpolated by the cubic spline through its samples
    of one run: consecutive present samples with no lost frame and no interval longer
    than ``max_interval_s`` between them (not-a-knot ends; 3 samples give a parabola, 2
    a line). Shifting all of a marker's sample times by :math:`o_m` shifts its spline,
    so the spline is built on the frame times and evaluated at :math:`t - o_m`. The
    value at instant :math:`t` is given only when :math:`T_i \le t - o_m \le T_{i+1}`
    for a usable interval ``i``, or when :math:`t - o_m` is a present sample's own time:
    never across a gap, never extrapolated beyond a stream's ends; elsewhere it is NaN
    and its flag says why. Inside a run the
    interpolation error of a smooth signal is of order :math:`h^4 \max|y^{(4)}|`, ``h``
    the frame interval (de Boor, A Practical Guide to Splines, ch. V); a cubic is
    reproduced exactly.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(6) / 100.0
    >>> r = resample(t, t[:, None] ** 3, np.array([0.025, 0.07]))
    >>> print(round(float(r.values[0, 0]) / 0.025**3, 9), r.flags[:, 0].tolist())
    1.0 [0, 1]
    """
    y = np.array(values, dtype=np.float64)
    t_frames = np.asarray(frame_times, dtype=np.float64)
    if seq is None:
        seq = np.arange(t_frames.size)
    s, x = check_frames(seq, t_frames)
    f = x.size
    if y.ndim < 2 or y.shape[0] != f:
        raise SynchronisationError(
            f"values must have shape (F, M, ...) with F = {f} frames, got {y.shape}"
        )
    m = y.shape[1]
    trailing = y.shape[2:]
    u = np.asarray(instants, dtype=np.float64)
    if u.ndim != 1 or not np.all(np.isfinite(u)):
        raise SynchronisationError(f"instants must be finite, shape (T,), got shape {u.shape}")
    off = np.zeros(m) if offsets is None else np.asarray(offsets, dtype=np.float64)
    if off.shape != (m,) or not np.all(np.isfinite(off)):
        raise SynchronisationError(f"offsets must be finite, shape ({m},), got shape {off.shape}")
    gaps = frame_gaps(s, x, max_interval_s)

    k = int(np.prod(trailing))
    y3 = y.reshape(f, m, k)
    values = np.empty((u.size, m, k))
    flags = np.empty((u.size, m, k), dtype=np.uint8)
    # Markers in blocks, so that the work arrays stay at a few tens of MB.
    step = max(1, _BLOCK // max(1, (f + u.size) * k))
    for m0 in range(0, m, step):
        block = slice(m0, min(m, m0 + step))
        values[:, block], flags[:, block] = _resample_block(x, gaps, y3[:, block], u, off[block])
    return Resampled(
        values=values.reshape(u.size, m, *trailing),
        flags=flags.reshape(u.size, m, *trailing),
        frame_gaps=gaps,
    )


def _resample_block(x: F64, gaps: U8, y3: F64, u: F64, off: F64) -> tuple[F64, U8]:
    """Values (T, M, K) and flags of markers ``y3`` (F, M, K) at instants ``u`` (T,)."""
    f, m, k = y3.shape
    present = np.isfinite(y3)
    pair = present[:-1] & present[1:]  # (F-1, M, K)
    usable = pair & (gaps == 0)[:, None, None]
    slope = _spline.slopes(x, y3.reshape(f, -1), usable.reshape(f - 1, -1)).reshape(f, m, k)

    # Interval of each (instant, marker): T_i <= t - o_m <= T_{i+1}.
    local = u[:, None] - off[None, :]  # (T, M)
    i = np.clip(np.searchsorted(x, local, side="right") - 1, 0, f - 2)
    outside = (local < x[0]) | (local > x[-1])
    h = (x[i + 1] - x[i])[:, :, None]
    w = ((local - x[i]) / (x[i + 1] - x[i]))[:, :, None]
    ii = i[:, :, None]

    def at(a: npt.NDArray[Any], j: npt.NDArray[np.intp]) -> npt.NDArray[Any]:
        return np.take_along_axis(a, j, axis=0)

    # Outside the stream's span only OUTSIDE; on a sample's own time only MISSING when it
    # is absent; between samples the interval's frame gaps and MISSING when a sample at
    # either end is absent.
    on_sample = (local == x[i])[:, :, None]
    between = np.where(outside, 0, gaps[i])[:, :, None] | np.where(at(pair, ii), 0, MISSING)
    inside = np.where(on_sample, np.where(at(present, ii), 0, MISSING), between)
    flags: U8 = np.where(outside[:, :, None], OUTSIDE, inside).astype(np.uint8)
    yz = np.where(present, y3, 0.0)
    out = _spline.hermite(at(yz, ii), at(yz, ii + 1), at(slope, ii), at(slope, ii + 1), h, w)
    return np.where(flags == 0, out, np.nan), flags
