r"""Offline refinement of a clock model by a smoothing spline of its residuals.

Yeadon (1990) fits frame times read from a timer in view with a smoothing spline whose
per-sample error is the timer's rounding error, 1/sqrt(12) of its unit, so that drift
may vary slowly while the rounding is removed. Here, within each segment of a fitted
:class:`~spotlab.acquisition.clocks.model.ClockModel` (never across a step or reset),
the residuals ``r_i = ref_i - model(ticks_i)`` are smoothed by a quintic
:class:`~spotlab.kinematics.SmoothingSpline` with

.. math:: \sigma_i^2 = \frac{u_d^2 + u_r^2}{12} + \sigma_j^2,

:math:`u_d` the device tick, :math:`u_r` the reference resolution and
:math:`\sigma_j` the jitter beyond rounding (default: what the segment's measured
jitter leaves after rounding), the smoothing parameter set by Wood & Jennings'
constraint :math:`\sum (g(t_i) - r_i)^2 / \sigma_i^2 = N`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from spotlab.acquisition.clocks.model import ClockModel
from spotlab.acquisition.clocks.pairs import as_pairs
from spotlab.core.errors import ClockError
from spotlab.kinematics import KinematicsError, SmoothingSpline

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class RefinedClock:
    """A clock model plus a smooth correction per segment.

    Attributes
    ----------
    model : ClockModel
        The affine model refined.
    splines : tuple of (ResidualSpline or None)
        Correction of each segment as a function of the model's session time (None
        where the segment had too few pairs); constant beyond the fitted range.
    ranges : tuple of (float, float)
        Session-time range of the pairs of each segment, s.
    """

    model: ClockModel
    splines: tuple[ResidualSpline | None, ...]
    ranges: tuple[tuple[float, float], ...]

    def __call__(self, ticks: npt.ArrayLike, epoch: npt.ArrayLike | None = None) -> F64:
        """Session seconds of device ticks, shape (N,) (as :meth:`ClockModel.__call__`)."""
        tk = np.asarray(ticks, dtype=np.int64).reshape(-1)
        ep = self.model.epochs_of(tk) if epoch is None else np.broadcast_to(epoch, tk.shape)
        base = self.model(tk, ep)
        seg = self.model._segment_index(tk, np.asarray(ep, dtype=np.int64))
        out = base.copy()
        for i, spline in enumerate(self.splines):
            sel = seg == i
            if spline is None or not np.any(sel):
                continue
            lo, hi = self.ranges[i]
            out[sel] += spline(np.clip(base[sel], lo, hi))
        return out


def refine_model(
    model: ClockModel,
    ticks: npt.ArrayLike,
    ref_s: npt.ArrayLike,
    *,
    ref_resolution_s: float = 0.0,
    jitter_s: float | None = None,
) -> RefinedClock:
    """Refine ``model`` by a Wood & Jennings smoothing spline of its residuals per segment.

    Parameters
    ----------
    model : ClockModel
        A model fitted to these pairs (e.g. by :func:`fit_edges`).
    ticks : array_like of int, shape (N,)
        Device ticks, in acquisition order (epochs inferred as in the model).
    ref_s : array_like of float, shape (N,)
        Reference times, s.
    ref_resolution_s : float
        Resolution (tick) of the reference, s; its rounding SD is this / sqrt(12).
    jitter_s : float, optional
        Jitter beyond rounding, s; default per segment
        ``sqrt(max(0, segment.jitter_s**2 - rounding**2))``.

    Returns
    -------
    RefinedClock

    Raises
    ------
    ClockError
        Bad pairs (see :func:`~spotlab.acquisition.clocks.pairs.as_pairs`), a negative
        resolution or jitter.
    """
    tk, ref = as_pairs(ticks, ref_s)
    if ref_resolution_s < 0 or (jitter_s is not None and jitter_s < 0):
        raise ClockError("reference resolution and jitter must be >= 0 s")
    rounding2 = ((1.0 / model.tick_hz) ** 2 + ref_resolution_s**2) / 12.0
    ep = model.epochs_of(tk)
    seg = model._segment_index(tk, ep)
    base = model(tk, ep)
    splines: list[ResidualSpline | None] = []
    ranges: list[tuple[float, float]] = []
    for i, segment in enumerate(model.segments):
        sel = np.flatnonzero(seg == i)
        extra2 = max(segment.jitter_s**2 - rounding2, 0.0) if jitter_s is None else jitter_s**2
        sigma = math.sqrt(rounding2 + extra2)
        if sel.size < 6 or np.any(np.diff(base[sel]) <= 0):
            splines.append(None)
            ranges.append((0.0, 0.0))
            continue
        t = base[sel]
        # the spline works in units of sigma so its banded algebra stays well scaled
        try:
            fit = ResidualSpline(t, (ref[sel] - t) / sigma, sigma)
        except KinematicsError as exc:
            raise ClockError(f"segment {i}: smoothing spline failed: {exc}") from exc
        splines.append(fit)
        ranges.append((float(t[0]), float(t[-1])))
    return RefinedClock(model=model, splines=tuple(splines), ranges=tuple(ranges))


class ResidualSpline:
    """Quintic SmoothingSpline of one segment's residuals, fitted in units of sigma.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Model session times of the pairs, s, increasing.
    r_scaled : ndarray, shape (N,)
        Residuals divided by ``sigma``.
    sigma : float
        Per-sample error, s (Wood & Jennings' constraint with unit errors after scaling).
    """

    def __init__(self, t: F64, r_scaled: F64, sigma: float) -> None:
        self.sigma = sigma
        self.spline = SmoothingSpline(t - t[0], r_scaled, sigma=np.ones_like(t), degree=5)
        self.t0 = float(t[0])

    def __call__(self, t: F64) -> F64:
        return np.asarray(self.spline(np.asarray(t) - self.t0) * self.sigma)
