"""Robust straight-line fit of reference seconds against int64 device ticks."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from spotlab.core.errors import ClockError

I64 = npt.NDArray[np.int64]
F64 = npt.NDArray[np.float64]

#: 1 / Phi^-1(3/4): the median absolute deviation times this estimates a normal SD.
MAD_TO_SD = 1.482602218505602


def robust_sd(values: F64) -> float:
    """Standard deviation estimated as 1.4826 x the median absolute deviation, shape (N,)."""
    v = np.asarray(values, dtype=np.float64)
    if v.size == 0:
        return 0.0
    return float(MAD_TO_SD * np.median(np.abs(v - np.median(v))))


@dataclass(frozen=True)
class LineFit:
    """Result of :func:`fit_line`.

    Attributes
    ----------
    origin : int
        Tick at which ``offset_s`` holds.
    offset_s : float
        Fitted reference time at ``origin``, s.
    rate : float
        Fitted seconds per tick.
    residuals : ndarray of float64, shape (N,)
        Reference minus fit, s.
    jitter_s : float
        Robust SD of the residuals, s.
    """

    origin: int
    offset_s: float
    rate: float
    residuals: F64
    jitter_s: float


def fit_line(
    ticks: I64,
    ref_s: F64,
    *,
    origin: int | None = None,
    huber: float = 1.5,
    iterations: int = 30,
    floor_s: float = 0.0,
) -> LineFit:
    r"""Huber-robust line ``ref = offset + rate (ticks - origin)`` by re-weighted least squares.

    Parameters
    ----------
    ticks : ndarray of int64, shape (N,)
        Device ticks, N >= 2, not all equal.
    ref_s : ndarray of float64, shape (N,)
        Reference times, s.
    origin : int, optional
        Tick origin; default the median tick (it decorrelates offset and rate).
    huber : float
        Huber threshold in robust SDs: residuals beyond it get weight
        ``huber * scale / |r|`` (Huber 1964).
    iterations : int
        Maximum re-weighting iterations.
    floor_s : float
        Smallest scale used in the weights, s (e.g. the tick rounding SD), so that
        exact data do not give zero weights.

    Returns
    -------
    LineFit

    Raises
    ------
    ClockError
        Fewer than 2 pairs, all ticks equal, or non-finite values.
    """
    x_int = np.asarray(ticks, dtype=np.int64)
    y = np.asarray(ref_s, dtype=np.float64)
    if x_int.size < 2 or x_int.shape != y.shape:
        raise ClockError(f"a line fit needs at least 2 pairs of equal length, got {x_int.size}")
    if not np.all(np.isfinite(y)):
        raise ClockError("reference times must be finite")
    org = int(np.median(x_int)) if origin is None else int(origin)
    x = (x_int - np.int64(org)).astype(np.float64)
    if np.ptp(x) == 0:
        raise ClockError("all ticks are equal: the rate cannot be fitted")
    y0 = float(y[y.size // 2])
    yc = y - y0
    w = np.ones_like(x)
    offset, rate = 0.0, 0.0
    for _ in range(iterations):
        sw = np.sum(w)
        xm = np.sum(w * x) / sw
        ym = np.sum(w * yc) / sw
        dx = x - xm
        sxx = np.sum(w * dx * dx)
        if sxx <= 0:
            raise ClockError("the pairs kept by the robust fit have a single tick value")
        new_rate = float(np.sum(w * dx * (yc - ym)) / sxx)
        new_offset = float(ym - new_rate * xm)
        r = yc - new_offset - new_rate * x
        scale = max(robust_sd(r), floor_s, 1e-15)
        new_w = np.minimum(1.0, huber * scale / np.maximum(np.abs(r), 1e-300))
        done = np.allclose(new_w, w, rtol=0.0, atol=1e-6)
        w, offset, rate = new_w, new_offset, new_rate
        if done:
            break
    residuals = yc - offset - rate * x
    return LineFit(
        origin=org,
        offset_s=y0 + offset,
        rate=rate,
        residuals=np.asarray(residuals, dtype=np.float64),
        jitter_s=robust_sd(residuals),
    )
