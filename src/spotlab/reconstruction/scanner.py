"""Optomechanical scanner (CODA-3 style): 3-D position from three angles and a fixed base.

Woltring & Huiskes (1990): two mirrors rotate about vertical axes a fixed base apart
(1 m in CODA-3), a third, halfway, about the horizontal axis through both. Each
mirror reports the angle of the plane in which the marker lies; the three planes
meet in the marker. "The fixed base [...] entails a quadratic dependence on the
distance from the mirrors for the longitudinal coordinate, and a linear dependence
for the two other coordinates."

Scanner frame (mm): origin halfway between the vertical axes, x along the base
(left axis at ``x = -b/2``, right at ``+b/2``), y forward (depth, away from the
scanner), z up. Angles (rad): ``alpha_left`` and ``alpha_right`` are the azimuths of
the marker seen from each vertical axis, measured from +y towards +x; ``beta`` the
elevation of the plane through the base line, from +y towards +z:

    tan alpha_left = (x + b/2) / y,  tan alpha_right = (x - b/2) / y,  tan beta = z / y
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import ReconstructionError

__all__ = ["scanner_angles", "scanner_position", "scanner_precision"]

FloatArray = NDArray[np.float64]


def _base(base: float) -> float:
    b = float(base)
    if not (np.isfinite(b) and b > 0.0):
        raise ReconstructionError(f"base must be a positive length (mm), got {base!r}")
    return b


def _triples(values: Any, what: str) -> FloatArray:
    a = np.asarray(values, dtype=np.float64)
    if a.ndim == 0 or a.shape[-1] != 3:
        raise ReconstructionError(f"{what} must have shape (..., 3), got {a.shape}")
    if np.any(np.isinf(a)):
        raise ReconstructionError(f"{what} hold infinite values (use NaN for missing)")
    return a


def scanner_angles(points: Any, base: float = 1000.0) -> FloatArray:
    """The three scanner angles of points in the scanner frame (the forward model).

    Parameters
    ----------
    points : array_like, shape (..., 3)
        Marker positions in the scanner frame (mm), in front of it (y > 0).
    base : float
        Distance between the two vertical mirror axes (mm).

    Returns
    -------
    ndarray, shape (..., 3)
        ``(alpha_left, alpha_right, beta)`` (rad).

    Raises
    ------
    ReconstructionError
        A point not in front of the scanner (y <= 0), bad shape or base.
    """
    b = _base(base)
    X = _triples(points, "points")
    x, y, z = X[..., 0], X[..., 1], X[..., 2]
    if np.any(y <= 0.0):
        raise ReconstructionError("a point is not in front of the scanner (y <= 0)")
    return np.stack([np.arctan2(x + b / 2, y), np.arctan2(x - b / 2, y), np.arctan2(z, y)], axis=-1)


def scanner_position(angles: Any, base: float = 1000.0) -> FloatArray:
    """Marker position from the three scanner angles, closed form.

    Parameters
    ----------
    angles : array_like, shape (..., 3)
        ``(alpha_left, alpha_right, beta)`` (rad), NaN for a missing reading.
    base : float
        Distance between the vertical mirror axes (mm).

    Returns
    -------
    ndarray, shape (..., 3)
        Position in the scanner frame (mm); NaN where a reading is missing.

    Raises
    ------
    ReconstructionError
        Readings whose vertical planes do not meet in front of the scanner
        (``alpha_left <= alpha_right``: parallel or diverging sight lines), angles
        of 90 degrees or more, bad shape or base.

    Notes
    -----
    From the definitions, ``y = b / (tan alpha_left - tan alpha_right)``,
    ``x = y (tan alpha_left + tan alpha_right) / 2``, ``z = y tan beta``.
    """
    b = _base(base)
    A = _triples(angles, "angles")
    if np.any(np.abs(A) >= np.pi / 2):
        raise ReconstructionError("scanner angles must lie within (-90, 90) degrees")
    tl, tr, tb = np.tan(A[..., 0]), np.tan(A[..., 1]), np.tan(A[..., 2])
    gap = tl - tr
    if np.any(gap <= 0.0):
        raise ReconstructionError(
            "left and right sight lines do not meet in front of the scanner "
            "(alpha_left <= alpha_right)"
        )
    y = b / gap
    return np.stack([y * (tl + tr) / 2.0, y, y * tb], axis=-1)


def scanner_precision(
    points: Any, sigma_angle: float | Any, base: float = 1000.0
) -> tuple[FloatArray, FloatArray]:
    r"""Standard deviations of a scanner's coordinates (first-order error propagation).

    Parameters
    ----------
    points : array_like, shape (..., 3)
        Marker positions in the scanner frame (mm).
    sigma_angle : float or array_like, shape (3,)
        Standard deviation of each angle reading (rad), independent errors. CODA-3:
        about 1/16000 of 40 degrees, 4.4e-5 rad ("about 50 um per m distance",
        Woltring & Huiskes 1990).
    base : float
        Distance between the vertical mirror axes (mm).

    Returns
    -------
    sd : ndarray, shape (..., 3)
        Standard deviations of x, y (depth), z (mm).
    cov : ndarray, shape (..., 3, 3)
        Covariance of the position (mm²), ``J diag(sigma²) J'``.

    Notes
    -----
    With :math:`T_l, T_r` the tangents and :math:`g = T_l - T_r`,
    :math:`\partial y / \partial\alpha_l = -y^2 \sec^2\alpha_l / b` and
    :math:`\partial y / \partial\alpha_r = y^2 \sec^2\alpha_r / b`: the depth error
    grows with the square of the distance over the base. The lateral coordinates
    gain the angle error times the distance (:math:`y \sec^2 \alpha / 2` and
    :math:`y \sec^2 \beta`) plus their share of the depth error, which vanishes on
    the centre line (x = 0, z = 0): there they grow linearly.
    """
    b = _base(base)
    A = scanner_angles(points, b)
    s = np.broadcast_to(np.asarray(sigma_angle, dtype=np.float64), (3,))
    if not np.all(np.isfinite(s)) or np.any(s < 0.0):
        raise ReconstructionError("sigma_angle must be finite and >= 0 (rad)")
    y = np.asarray(points, dtype=np.float64)[..., 1]
    sec2 = 1.0 / np.cos(A) ** 2
    tl, tr, tb = np.tan(A[..., 0]), np.tan(A[..., 1]), np.tan(A[..., 2])
    dy_dl = -(y**2) * sec2[..., 0] / b
    dy_dr = (y**2) * sec2[..., 1] / b
    half = (tl + tr) / 2.0
    zero = np.zeros_like(y)
    J = np.stack(
        [
            np.stack(
                [half * dy_dl + y * sec2[..., 0] / 2, half * dy_dr + y * sec2[..., 1] / 2, zero], -1
            ),
            np.stack([dy_dl, dy_dr, zero], -1),
            np.stack([tb * dy_dl, tb * dy_dr, y * sec2[..., 2]], -1),
        ],
        axis=-2,
    )
    cov = np.einsum("...ik,k,...jk->...ij", J, s**2, J)
    return np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1)), cov
