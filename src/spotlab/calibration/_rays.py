"""Rays of image observations and their least-squares intersection.

Calibration needs a quick triangulation of its own observations at every stage (it may
not import ``spotlab.reconstruction``, which sits beside it in the layers): the point
nearest in the least-squares sense to all rays that see it (Woltring & Huiskes Eq. 6,
unweighted).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from spotlab.geometry import Camera

__all__ = ["intersect", "nearest_points"]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


def nearest_points(
    origins: FloatArray, directions: FloatArray, seen: BoolArray
) -> tuple[FloatArray, NDArray[np.intp]]:
    """Points nearest in the least-squares sense to the rays that see them.

    Parameters
    ----------
    origins : ndarray, shape (C, 3)
        Perspective centres (mm).
    directions : ndarray, shape (C, N, 3)
        Unit ray directions per camera and point (any finite value where unseen).
    seen : ndarray of bool, shape (C, N)
        Which rays exist.

    Returns
    -------
    X : ndarray, shape (N, 3)
        NaN where fewer than two rays exist or the rays are parallel.
    views : ndarray of int, shape (N,)
        Number of rays per point.
    """
    d = np.where(seen[..., None], directions, 0.0)
    m = seen.astype(np.float64)
    A = m.sum(axis=0)[:, None, None] * np.eye(3) - np.einsum("cni,cnj->nij", d, d)
    proj = origins[:, None, :] * m[..., None] - d * np.einsum("cni,ci->cn", d, origins)[..., None]
    b = proj.sum(axis=0)
    views = seen.sum(axis=0)
    X = np.full(b.shape, np.nan)
    ok = np.flatnonzero(views >= 2)
    if ok.size:
        # Parallel rays leave A singular: its smallest eigenvalue measures the angle.
        smallest = np.linalg.eigvalsh(A[ok])[:, 0]
        idx = ok[smallest > 1e-12]
        X[idx] = np.linalg.solve(A[idx], b[idx][..., None])[..., 0]
    return X, views


def intersect(cameras: Sequence[Camera], uv: FloatArray) -> tuple[FloatArray, NDArray[np.intp]]:
    """Triangulate image points (C, N, 2) seen by ``cameras``; returns X (N, 3), views (N,)."""
    C, N = uv.shape[:2]
    origins = np.array([cam.center for cam in cameras])
    dirs = np.zeros((C, N, 3))
    for c, cam in enumerate(cameras):
        xy = cam.normalize(uv[c])
        h = np.concatenate([xy, np.ones((N, 1))], axis=1) @ cam.R
        dirs[c] = h / np.linalg.norm(h, axis=1, keepdims=True)
    seen = np.all(np.isfinite(uv), axis=-1)
    return nearest_points(origins, np.nan_to_num(dirs), seen)
