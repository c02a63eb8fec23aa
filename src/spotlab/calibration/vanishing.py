"""Vanishing points of straight lines from markers at known positions along them.

A marker at position ``s`` on a 3-D line ``X(s) = X0 + s D`` projects to the homogeneous
image point ``b + s a`` with ``a = P (D, 0)`` and ``b = P (X0, 1)``: along the image of the
line, the image coordinate is a 1-D projective function of ``s``. Fitting that function to
three or more markers and letting ``s -> infinity`` gives the vanishing point ``a`` of the
line's direction (Pribanić, Sturm & Cifrek 2005, Sec. 4.1: "from known ratios on a single
line"). With three markers the fit is exact, and equivalent to preserving their cross-ratio
with the point at infinity.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import CalibrationError

__all__ = ["vanishing_point"]

FloatArray = NDArray[np.float64]

#: Re-weighting passes of the 1-D projective fit (algebraic -> near-geometric error).
_REWEIGHT_PASSES = 3


def _check_positions(positions: Any) -> FloatArray:
    s = np.asarray(positions, dtype=np.float64)
    if s.ndim != 1:
        raise CalibrationError(f"positions must have shape (M,), got {s.shape}")
    if s.size < 3:
        raise CalibrationError(
            f"a vanishing point needs at least 3 markers on the line, got {s.size}"
        )
    if not np.all(np.isfinite(s)):
        raise CalibrationError("positions hold NaN or infinite values")
    gaps = np.diff(np.sort(s))
    if np.any(gaps <= 1e-9 * float(np.ptp(s))) or not np.ptp(s) > 0.0:
        raise CalibrationError("positions must be distinct: two markers share a position")
    return s


def _fit_line_coordinate(uv: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Image line of each marker row: centroid (L, 2), unit direction (L, 2), t (L, M)."""
    centroid = uv.mean(axis=-2)
    d = uv - centroid[..., None, :]
    # Principal direction of the 2x2 scatter matrix, in closed form per line.
    sxx = np.sum(d[..., 0] ** 2, axis=-1)
    syy = np.sum(d[..., 1] ** 2, axis=-1)
    sxy = np.sum(d[..., 0] * d[..., 1], axis=-1)
    theta = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    e = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
    t = np.sum(d * e[..., None, :], axis=-1)
    return centroid, e, t


def vanishing_point(uv: Any, positions: Any) -> FloatArray:
    """Vanishing point of each line from collinear markers at known positions.

    Parameters
    ----------
    uv : array_like, shape (..., M, 2)
        Image coordinates (px) of the M markers of each line, distortion already removed
        (a straight 3-D line must image as a straight line). NaN marks an unseen marker.
    positions : array_like, shape (M,)
        Known positions of the markers along their line (mm, or any unit: only ratios
        matter), distinct, M >= 3; the same for every line.

    Returns
    -------
    ndarray, shape (..., 3)
        Homogeneous vanishing points ``(x, y, w)`` with unit norm and ``w >= 0``: the image
        point is ``(x / w, y / w)`` px, and ``w = 0`` is a point at infinity (a line
        parallel to the image plane), in direction ``(x, y)``. NaN for a line with a NaN
        marker or with all its markers on one image point (a line through the camera
        centre).

    Raises
    ------
    CalibrationError
        Fewer than 3 markers, repeated or non-finite positions, or ``uv`` not of shape
        ``(..., M, 2)``.

    Notes
    -----
    Per line, the markers are projected on their total-least-squares image line (centroid
    ``c``, unit direction ``e``), giving coordinates ``t_i``. The 1-D homography
    ``t = (alpha s + beta) / (gamma s + delta)`` is fitted by homogeneous least squares on
    ``t_i (gamma s_i + delta) - (alpha s_i + beta) = 0`` with ``s`` and ``t`` centred and
    scaled, and re-weighted by ``1 / (gamma s_i + delta)`` (a few passes) so that the
    residual is the image distance along the line rather than the algebraic error. The
    vanishing point is the limit ``s -> infinity``: ``(gamma c + alpha e, gamma)``.
    With M = 3 the fit is exact: the cross-ratio of the three markers and the point at
    infinity is preserved (Hartley & Zisserman 2004, Sec. 2.5 and 8.6; Pribanić, Sturm &
    Cifrek 2005, Sec. 4.1).

    Examples
    --------
    >>> import numpy as np
    >>> from spotlab.calibration import vanishing_point
    >>> # Points s = 0, 1, 3 of a line whose image is u = 100 s / (s + 1), v = 0.
    >>> uv = [[0.0, 0.0], [50.0, 0.0], [75.0, 0.0]]
    >>> v = vanishing_point(uv, [0.0, 1.0, 3.0])
    >>> np.round(v[:2] / v[2], 9)
    array([100.,   0.])
    """
    s = _check_positions(positions)
    pts = np.asarray(uv, dtype=np.float64)
    if pts.ndim < 2 or pts.shape[-1] != 2 or pts.shape[-2] != s.size:
        raise CalibrationError(
            f"uv must have shape (..., {s.size}, 2) for {s.size} positions, got {pts.shape}"
        )
    batch = pts.shape[:-2]
    pts = pts.reshape(-1, s.size, 2)
    out = np.full((pts.shape[0], 3), np.nan)
    usable = np.all(np.isfinite(pts), axis=(1, 2))
    spread = np.zeros(pts.shape[0])
    spread[usable] = np.ptp(pts[usable], axis=1).max(axis=1)
    usable &= spread > 0.0
    if np.any(usable):
        out[usable] = _fit(pts[usable], s)
    return out.reshape(*batch, 3)


def _fit(pts: FloatArray, s: FloatArray) -> FloatArray:
    """Vanishing points (L, 3) of L lines with finite, not coincident markers (L, M, 2)."""
    centroid, e, t = _fit_line_coordinate(pts)
    s0, s_scale = s.mean(), np.abs(s - s.mean()).mean()
    sn = (s - s0) / s_scale
    t_scale = np.abs(t).mean(axis=-1, keepdims=True)
    tn = t / t_scale
    ones = np.ones_like(tn)
    snb = np.broadcast_to(sn, tn.shape)
    # Unknowns (alpha, beta, gamma, delta) of tn = (alpha sn + beta) / (gamma sn + delta).
    A = np.stack([-snb, -ones, tn * snb, tn], axis=-1)  # (L, M, 4)
    w = np.ones_like(tn)
    for _ in range(_REWEIGHT_PASSES):
        h = np.linalg.svd(A * w[..., None])[2][..., -1, :]  # (L, 4)
        denom = h[:, 2:3] * snb + h[:, 3:4]
        scale = np.abs(denom).mean(axis=-1, keepdims=True)
        with np.errstate(divide="ignore", invalid="ignore"):
            w_new = scale / np.abs(denom)
        if not np.all(np.isfinite(w_new)):
            break  # a marker imaged at the vanishing point: keep the previous weights
        w = w_new
    alpha, gamma = h[:, 0], h[:, 2]
    # Undo the scaling of t (the scaling of s does not move the limit s -> infinity).
    t_inf = np.stack([alpha * t_scale[:, 0], gamma], axis=-1)
    vp = np.concatenate(
        [t_inf[:, 1:2] * centroid + t_inf[:, 0:1] * e, t_inf[:, 1:2]],
        axis=-1,
    )
    vp /= np.linalg.norm(vp, axis=-1, keepdims=True)
    flip = (vp[:, 2] < 0.0) | ((vp[:, 2] == 0.0) & (vp[:, 0] < 0.0))
    vp[flip] *= -1.0
    return vp
