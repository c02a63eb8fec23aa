"""Error estimates of Yeadon (1990) and Woltring's sigma^2 tau figure.

Per-sample standard errors feed the Wood & Jennings smoothing spline
(:class:`spotlab.kinematics.SmoothingSpline` with ``sigma``): timer rounding,
repeated digitisation (local and global variance mixed with k = 0.25), and the
four combinations of two cameras each digitised twice. ``sigma2_tau`` compares the
spatio-temporal resolution of systems (Woltring & Huiskes 1990).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.kinematics.continuous import align_angle
from spotlab.kinematics.errors import KinematicsError

__all__ = [
    "equivalent_sd",
    "four_combinations",
    "repeated_measurement_sd",
    "rounding_sd",
    "sigma2_tau",
]

FloatArray = NDArray[np.float64]


def _positive(value: float, what: str) -> float:
    v = float(value)
    if not (math.isfinite(v) and v > 0.0):
        raise KinematicsError(f"{what} must be a positive finite number, got {value!r}")
    return v


def rounding_sd(unit: float = 1.0) -> float:
    r"""Standard deviation of the error of a value rounded to a whole ``unit``.

    Parameters
    ----------
    unit : float
        Rounding step (e.g. 1 ms for a millisecond timer).

    Returns
    -------
    float
        ``unit / sqrt(12)`` (0.289 ms for a millisecond timer).

    Notes
    -----
    The error is uniform on :math:`[-u/2, u/2]`, with variance
    :math:`\int_{-1/2}^{1/2} t^2\,dt = 1/12` in units of :math:`u^2` (Yeadon 1990).
    """
    return _positive(unit, "unit") / math.sqrt(12.0)


def repeated_measurement_sd(estimates: Any, *, k: float = 0.25) -> FloatArray:
    r"""Per-sample standard error from repeated measurements (Yeadon 1990).

    Parameters
    ----------
    estimates : array_like, shape (n, N, ...)
        ``n >= 2`` repeated measurements (e.g. digitisations) of ``N`` samples, with
        any trailing channel axes; NaN marks a missing measurement.
    k : float
        Weight of the local variance, ``0 <= k <= 1``; Yeadon's choice 0.25.

    Returns
    -------
    ndarray, shape (N, ...)
        :math:`\delta = (k V_l + (1 - k) V_g)^{1/2}` per sample; NaN where fewer than
        2 measurements of the sample exist.

    Raises
    ------
    KinematicsError
        Fewer than 2 repetitions, k outside [0, 1], infinite values, or no sample of
        a channel measured twice.

    Notes
    -----
    ``V_l`` is the unbiased variance of the repeated values of one sample
    (:math:`\frac{1}{2}(x_1 - x_2)^2` for n = 2), ``V_g`` its mean over all samples
    of the channel. The local variance alone overweights samples whose repeats agree
    by chance; the global alone ignores the local information. With k = 0.25 a large
    error is underestimated by at most a factor 2 (:math:`\delta \ge
    \frac{1}{2} V_l^{1/2}`) and :math:`\delta \ge 0.87\, V_g^{1/2}` (Yeadon 1990).
    """
    x = np.asarray(estimates, dtype=np.float64)
    if x.ndim < 2 or x.shape[0] < 2:
        raise KinematicsError(
            f"estimates must have shape (n >= 2 repetitions, N samples, ...), got {x.shape}"
        )
    if not 0.0 <= float(k) <= 1.0:
        raise KinematicsError(f"k must lie in [0, 1], got {k!r}")
    if np.any(np.isinf(x)):
        raise KinematicsError("estimates hold infinite values (use NaN for missing)")
    count = np.sum(np.isfinite(x), axis=0)
    enough = count >= 2
    if not np.all(np.any(enough, axis=0)):
        raise KinematicsError("a channel has no sample measured at least twice")
    mean = np.nansum(x, axis=0) / np.maximum(count, 1)
    local = np.nansum((x - mean) ** 2, axis=0) / np.maximum(count - 1, 1)
    local = np.where(enough, local, np.nan)
    global_ = np.nanmean(local, axis=0)
    return np.asarray(np.sqrt(k * local + (1.0 - k) * global_), dtype=np.float64)


def four_combinations(
    a11: Any, a12: Any, a21: Any, a22: Any, *, angles: bool = False
) -> tuple[FloatArray, FloatArray]:
    r"""Mean and standard error from two cameras each measured twice (Yeadon 1990).

    Parameters
    ----------
    a11, a12, a21, a22 : array_like, broadcast together
        ``a_ij``: the value computed from the i-th measurement of the first camera
        and the j-th of the second.
    angles : bool
        The values are angles (rad): bring ``a12, a21, a22`` within pi of ``a11``
        by whole turns first (:func:`spotlab.kinematics.align_angle`).

    Returns
    -------
    mean : ndarray
        Mean of the four values, the best estimate.
    sd : ndarray
        Standard error of the mean, :math:`\{[(a_{11} - a_{22})^2 + (a_{12} -
        a_{21})^2] / 8\}^{1/2}`.

    Notes
    -----
    To first order :math:`a_{ij} = A_0 + X_i + Y_j` with independent errors ``X``
    (camera 1) and ``Y`` (camera 2); the mean's variance is
    :math:`\frac{1}{2}\operatorname{var}X + \frac{1}{2}\operatorname{var}Y`, estimated
    from the two independent pairs :math:`a_{11}:a_{22}` and :math:`a_{12}:a_{21}`.
    """
    try:
        v11, v12, v21, v22 = np.broadcast_arrays(
            *(np.asarray(v, dtype=np.float64) for v in (a11, a12, a21, a22))
        )
    except ValueError as exc:
        raise KinematicsError(f"the four estimates do not broadcast together: {exc}") from None
    if any(np.any(np.isinf(v)) for v in (v11, v12, v21, v22)):
        raise KinematicsError("the four estimates hold infinite values")
    if angles:
        v12, v21, v22 = (align_angle(v, v11) for v in (v12, v21, v22))
    mean = (v11 + v12 + v21 + v22) / 4.0
    sd = np.sqrt(((v11 - v22) ** 2 + (v12 - v21) ** 2) / 8.0)
    return mean, sd


def _value_and_interval(value: Any, what: str, interval: Any) -> tuple[FloatArray, FloatArray]:
    v = np.asarray(value, dtype=np.float64)
    tau = np.asarray(interval, dtype=np.float64)
    if np.any(~np.isfinite(v) | (v < 0.0)):
        raise KinematicsError(f"{what} must be finite and >= 0")
    if np.any(~np.isfinite(tau) | (tau <= 0.0)):
        raise KinematicsError("interval must be finite and > 0 (s)")
    return v, tau


def sigma2_tau(sd: Any, interval: Any) -> FloatArray:
    r"""Woltring's figure of merit :math:`\sigma^2 \tau` (variance times sampling interval).

    Parameters
    ----------
    sd : array_like
        Standard deviation of a reconstructed coordinate (e.g. mm) in a standardised
        environment.
    interval : array_like
        Sampling interval :math:`\tau` (s), i.e. 1 / rate.

    Returns
    -------
    ndarray
        :math:`\sigma^2 \tau` (e.g. mm² s); smaller is better.

    Notes
    -----
    White noise of variance :math:`\sigma^2` sampled every :math:`\tau` and averaged
    (or low-pass filtered) over a time :math:`T` keeps a variance of about
    :math:`\sigma^2 \tau / T`: a system with 4 times the rate may have twice the
    noise and resolve the same motion equally well. Woltring & Huiskes (1990) cite
    it as "a useful criterion for comparing spatio-temporal resolution between
    systems" (Woltring 1984).
    """
    s, tau = _value_and_interval(sd, "sd", interval)
    return np.asarray(s**2 * tau, dtype=np.float64)


def equivalent_sd(figure: Any, interval: Any) -> FloatArray:
    r"""Standard deviation that gives a :math:`\sigma^2 \tau` figure at another sampling interval.

    Parameters
    ----------
    figure : array_like
        :math:`\sigma^2 \tau` (e.g. mm² s), see :func:`sigma2_tau`.
    interval : array_like
        Sampling interval (s).

    Returns
    -------
    ndarray
        :math:`(\sigma^2 \tau / \tau')^{1/2}`.
    """
    f, tau = _value_and_interval(figure, "the sigma^2 tau figure", interval)
    return np.asarray(np.sqrt(f / tau), dtype=np.float64)
