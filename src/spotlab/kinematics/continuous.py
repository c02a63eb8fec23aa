"""Continuous angle histories from sines and cosines (Yeadon 1990's incremental rule)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.kinematics.errors import KinematicsError

__all__ = ["align_angle", "continuous_angle"]

FloatArray = NDArray[np.float64]


def continuous_angle(sin: Any, cos: Any, *, axis: int = 0, reference: Any = None) -> FloatArray:
    r"""A continuous angle history from sequences of its sine and cosine.

    Parameters
    ----------
    sin, cos : array_like, same shape
        Sine and cosine values of the angle (any common positive scale: ``(r sin A,
        r cos A)`` is accepted), samples along ``axis``; NaN marks a missing sample.
    axis : int
        Time axis.
    reference : array_like, optional
        An angle (rad), broadcast over the other axes, within pi of which the first
        valid sample is placed. Default: Yeadon's range (-pi/2, 3pi/2].

    Returns
    -------
    ndarray, same shape
        Angles (rad), each within pi of the previous valid one; NaN where missing.

    Raises
    ------
    KinematicsError
        Shapes that differ, infinite values, no valid sample, or a sample with sine and
        cosine both 0.

    Notes
    -----
    Yeadon (1990): :math:`A_0` in :math:`(-\pi/2, 3\pi/2]`, then for each sample
    :math:`B = \operatorname{atan2}(\sin A \cos A_1 - \cos A \sin A_1,\ \cos A \cos A_1
    + \sin A \sin A_1)` in :math:`(-\pi, \pi]` and :math:`A = A_1 + B`. The increments
    use the previous *valid* sample, so a gap does not break the history (a jump of
    more than pi across a gap cannot be told from its complement). The paper writes
    :math:`A_0 = \pi + \arctan(s/c)` for :math:`c \le 0`, which gives :math:`3\pi/2`
    instead of :math:`\pi/2` at :math:`c = 0, s > 0`; ``atan2`` avoids that.

    Examples
    --------
    >>> import numpy as np
    >>> a = np.linspace(0.0, 12.0, 25)  # almost two turns
    >>> bool(np.allclose(continuous_angle(np.sin(a), np.cos(a)), a))
    True
    """
    s, c = (np.asarray(v, dtype=np.float64) for v in (sin, cos))
    if s.shape != c.shape or s.ndim == 0:
        raise KinematicsError(
            f"sin and cos must be arrays of the same shape, got {s.shape} and {c.shape}"
        )
    if np.any(np.isinf(s) | np.isinf(c)):
        raise KinematicsError("sin or cos holds infinite values (use NaN for missing)")
    s, c = np.moveaxis(s, axis, 0), np.moveaxis(c, axis, 0)
    valid = np.isfinite(s) & np.isfinite(c)
    if np.any(valid & (s == 0.0) & (c == 0.0)):
        raise KinematicsError("a sample has sine and cosine both 0: its angle is undefined")
    if not np.any(valid):
        raise KinematicsError("sin and cos are NaN everywhere: no angle to follow")
    n = s.shape[0]
    # index of the last valid sample at or before each sample (-1 before the first)
    idx = np.where(valid, np.arange(n).reshape((n,) + (1,) * (s.ndim - 1)), -1)
    idx = np.maximum.accumulate(idx, axis=0)
    has = idx >= 0
    sf = np.take_along_axis(s, np.maximum(idx, 0), axis=0)
    cf = np.take_along_axis(c, np.maximum(idx, 0), axis=0)
    sp = np.concatenate([sf[:1], sf[:-1]], axis=0)
    cp = np.concatenate([cf[:1], cf[:-1]], axis=0)
    step = np.arctan2(sf * cp - cf * sp, cf * cp + sf * sp)
    step = np.where(has, step, 0.0)
    step = np.where(np.concatenate([np.zeros_like(has[:1]), has[:-1]], axis=0), step, 0.0)
    first_idx = np.argmax(valid, axis=0)
    s0 = np.take_along_axis(s, first_idx[None], axis=0)[0]
    c0 = np.take_along_axis(c, first_idx[None], axis=0)[0]
    a0 = np.arctan2(s0, c0)
    if reference is None:
        a0 = np.where(a0 <= -np.pi / 2, a0 + 2.0 * np.pi, a0)
    else:
        a0 = align_angle(a0, reference)
    out = a0 + np.cumsum(step, axis=0)
    out = np.where(valid, out, np.nan)
    return np.moveaxis(out, 0, axis)


def align_angle(angle: Any, reference: Any) -> FloatArray:
    """Shift angles by whole turns to lie within pi of a reference.

    Parameters
    ----------
    angle, reference : array_like, broadcast together
        Angles (rad).

    Returns
    -------
    ndarray
        ``angle - 2 pi k`` in ``(reference - pi, reference + pi]``.

    Notes
    -----
    Yeadon (1990) notes that repeated estimates of an angle near a singularity can
    drift apart by about 2 pi and brings each back to follow the first estimate;
    this is that step (by whole turns), applied before the estimates are averaged.
    """
    a = np.asarray(angle, dtype=np.float64)
    r = np.asarray(reference, dtype=np.float64)
    two_pi = 2.0 * np.pi
    k = np.ceil((a - r - np.pi) / two_pi)
    return np.asarray(a - two_pi * k, dtype=np.float64)
