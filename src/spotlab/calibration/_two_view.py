"""Relative orientation of two cameras from corresponding rays: the essential matrix.

Longuet-Higgins' coplanarity condition ``x2' E x1 = 0`` on normalised image coordinates,
solved linearly (eight-point algorithm with Hartley's conditioning), projected onto the
essential manifold (two equal singular values, one zero), made robust by refitting
without the correspondences whose Sampson distance is large, and decomposed into the
rotation and baseline direction whose triangulated points lie in front of both cameras
(Hartley & Zisserman, Multiple View Geometry, 2nd ed., §9.6 and §11.3).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from spotlab.calibration.dlt import _normalisation
from spotlab.core.errors import CalibrationError

__all__ = ["essential_matrix", "midpoints", "relative_pose", "rotation_residual"]

FloatArray = NDArray[np.float64]


def _eight_point(x1: FloatArray, x2: FloatArray) -> FloatArray:
    T1, T2 = _normalisation(x1), _normalisation(x2)
    a = x1 @ T1[:2, :2].T + T1[:2, 2]
    b = x2 @ T2[:2, :2].T + T2[:2, 2]
    A = np.column_stack(
        [
            b[:, 0] * a[:, 0],
            b[:, 0] * a[:, 1],
            b[:, 0],
            b[:, 1] * a[:, 0],
            b[:, 1] * a[:, 1],
            b[:, 1],
            a[:, 0],
            a[:, 1],
            np.ones(len(a)),
        ]
    )
    _, _, vt = np.linalg.svd(A, full_matrices=False)
    E = T2.T @ vt[-1].reshape(3, 3) @ T1
    u, _, vt = np.linalg.svd(E)
    return u @ np.diag([1.0, 1.0, 0.0]) @ vt


def _sampson(E: FloatArray, x1: FloatArray, x2: FloatArray) -> FloatArray:
    h1 = np.column_stack([x1, np.ones(len(x1))])
    h2 = np.column_stack([x2, np.ones(len(x2))])
    Ex1 = h1 @ E.T
    Etx2 = h2 @ E
    num = np.sum(h2 * Ex1, axis=1) ** 2
    den = Ex1[:, 0] ** 2 + Ex1[:, 1] ** 2 + Etx2[:, 0] ** 2 + Etx2[:, 1] ** 2
    return np.sqrt(num / np.maximum(den, 1e-300))


def essential_matrix(x1: FloatArray, x2: FloatArray, *, rounds: int = 3) -> FloatArray:
    """Essential matrix (3, 3) with ``x2' E x1 = 0`` from normalised points (N, 2) each.

    Raises
    ------
    CalibrationError
        With fewer than 8 correspondences.
    """
    if len(x1) < 8:
        raise CalibrationError(f"relative orientation needs >= 8 common points, got {len(x1)}")
    keep = np.ones(len(x1), dtype=bool)
    E = _eight_point(x1, x2)
    for _ in range(rounds):
        d = _sampson(E, x1, x2)
        limit = 5.0 * 1.4826 * float(np.median(d)) + 1e-12
        new_keep = d <= limit
        if np.count_nonzero(new_keep) < 8 or np.array_equal(new_keep, keep):
            break
        keep = new_keep
        E = _eight_point(x1[keep], x2[keep])
    return E


def midpoints(
    c1: FloatArray, d1: FloatArray, c2: FloatArray, d2: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Midpoints of the common perpendiculars of rays ``c + s d``, and the parameters.

    Parameters
    ----------
    c1, c2 : ndarray, shape (3,) or (N, 3)
        Ray origins.
    d1, d2 : ndarray, shape (N, 3)
        Ray directions (any length).

    Returns
    -------
    X : ndarray, shape (N, 3)
        Midpoints (NaN for parallel rays).
    s : ndarray, shape (N, 2)
        Ray parameters of the two feet of the perpendicular.
    """
    w = c1 - c2
    a = np.sum(d1 * d1, axis=-1)
    b = np.sum(d1 * d2, axis=-1)
    c = np.sum(d2 * d2, axis=-1)
    d = np.sum(d1 * w, axis=-1)
    e = np.sum(d2 * w, axis=-1)
    den = a * c - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s1 = np.where(den > 1e-12 * a * c, (b * e - c * d) / den, np.nan)
        s2 = np.where(den > 1e-12 * a * c, (a * e - b * d) / den, np.nan)
    X = 0.5 * ((c1 + s1[..., None] * d1) + (c2 + s2[..., None] * d2))
    return X, np.stack([s1, s2], axis=-1)


def rotation_residual(x1: FloatArray, x2: FloatArray) -> float:
    """Median angle (rad) left when the two views are related by a rotation only.

    A camera pair that shares one perspective centre sees every point along rays
    related by one rotation, whatever the depth; a real baseline leaves a residual that
    grows with the spread of depths. The rotation is Kabsch's least-squares fit between
    the unit rays.
    """
    r1 = np.column_stack([x1, np.ones(len(x1))])
    r2 = np.column_stack([x2, np.ones(len(x2))])
    r1 /= np.linalg.norm(r1, axis=1, keepdims=True)
    r2 /= np.linalg.norm(r2, axis=1, keepdims=True)
    u, _, vt = np.linalg.svd(r2.T @ r1)
    R = u @ np.diag([1.0, 1.0, float(np.linalg.det(u @ vt))]) @ vt
    cos = np.clip(np.sum(r2 * (r1 @ R.T), axis=1), -1.0, 1.0)
    return float(np.median(np.arccos(cos)))


def relative_pose(x1: FloatArray, x2: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Rotation R (3, 3) and unit baseline t (3,) with ``x_cam2 = R x_cam1 + t * scale``.

    Parameters
    ----------
    x1, x2 : ndarray, shape (N, 2)
        Normalised image coordinates of the same points in cameras 1 and 2.

    Returns
    -------
    R, t : ndarray
        The decomposition of the essential matrix that puts most points in front of
        both cameras.
    """
    E = essential_matrix(x1, x2)
    u, _, vt = np.linalg.svd(E)
    if np.linalg.det(u) < 0:
        u = -u
    if np.linalg.det(vt) < 0:
        vt = -vt
    Wm = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    h1 = np.column_stack([x1, np.ones(len(x1))])
    h2 = np.column_stack([x2, np.ones(len(x2))])
    best = (-1, np.eye(3), u[:, 2])
    for R in (u @ Wm @ vt, u @ Wm.T @ vt):
        for t in (u[:, 2], -u[:, 2]):
            # Camera 2 centre in camera-1 coordinates: -R' t; ray directions in camera 1.
            c2 = -R.T @ t
            _, s = midpoints(np.zeros(3), h1, c2, h2 @ R)
            front = int(np.count_nonzero((s[:, 0] > 0) & (s[:, 1] > 0)))
            if front > best[0]:
                best = (front, R, t)
    return best[1], best[2]
