"""Blobs of several cameras -> 3-D points: epipolar matching without prior knowledge.

Every pair of blobs of two cameras whose rays pass within ``gate_px`` of each other (the
epipolar distance, both ways) seeds a point at the midpoint of the two rays. A seed is
supported by the cameras that have a blob within ``gate_px`` of its projection. Seeds are
taken greedily, best supported first; each takes the nearest free blob of every other
camera, so each blob serves one point. The groups are triangulated together with
outlier rays dropped (:meth:`RigGeometry.triangulate`); points seen by fewer than
``min_cameras`` cameras are discarded: two rays always meet somewhere on an epipolar
line, three or more rarely do by chance (Woltring & Huiskes 1990 on identification
"between cameras"; the epipolar constraint as in Hartley & Zisserman 2004, §9).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import ReconstructionError
from spotlab.reconstruction.identification.geometry import RigGeometry

__all__ = ["Correspondence", "match_blobs"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


@dataclass(frozen=True)
class Correspondence:
    """Points found among unexplained blobs.

    Attributes
    ----------
    points : ndarray, shape (G, 3)
        Triangulated points (mm).
    blobs : ndarray of int, shape (C, G)
        Index (into the blobs given) of the ray of camera ``c`` for point ``g``; -1 where
        the camera does not support the point.
    ray_px : ndarray, shape (C, G)
        Ray errors (undistorted px), NaN where unsupported.
    """

    points: FloatArray
    blobs: IntArray
    ray_px: FloatArray

    @property
    def n_cameras(self) -> IntArray:
        """Cameras supporting each point, shape (G,)."""
        return np.asarray((self.blobs >= 0).sum(axis=0), dtype=np.intp)


def _midpoints(
    geom: RigGeometry, xy: FloatArray, cam: IntArray, a: IntArray, b: IntArray
) -> FloatArray:
    """Midpoints (S, 3) of the shortest segments between the rays of blobs ``a`` and ``b``."""
    h = np.concatenate([xy, np.ones((xy.shape[0], 1))], axis=1)
    d = np.einsum("nji,nj->ni", geom.R[cam], h)  # ray directions in the world, R' (x, y, 1)
    da, db = d[a], d[b]
    ca, cb = geom.centers[cam[a]], geom.centers[cam[b]]
    w0 = ca - cb
    aa = (da * da).sum(1)
    ab = (da * db).sum(1)
    bb = (db * db).sum(1)
    wa = (da * w0).sum(1)
    wb = (db * w0).sum(1)
    with np.errstate(divide="ignore", invalid="ignore"):
        den = aa * bb - ab * ab
        sa = (ab * wb - bb * wa) / den
        sb = (aa * wb - ab * wa) / den
        X = 0.5 * (ca + sa[:, None] * da + cb + sb[:, None] * db)
    X[~((sa > 0) & (sb > 0))] = np.nan  # behind a camera or parallel rays
    return X


def _epipolar_pairs(
    geom: RigGeometry, xy: FloatArray, cam: IntArray, gate_px: float
) -> tuple[IntArray, IntArray, FloatArray]:
    """Blob pairs of different cameras within ``gate_px`` of each other's epipolar line."""
    a, b = geom.pairs(cam.size)
    other = cam[a] != cam[b]
    a, b = a[other], b[other]
    h = np.concatenate([xy, np.ones((xy.shape[0], 1))], axis=1)
    ca, cb = cam[a], cam[b]
    E = geom.E_flat[ca * len(geom) + cb]  # (P, 3, 3): h_b' E h_a = 0
    line_b = np.einsum("pij,pj->pi", E, h[a])
    line_a = np.einsum("pij,pi->pj", E, h[b])
    algebraic = np.abs((line_b * h[b]).sum(1))
    fa, fb = geom.f[ca], geom.f[cb]
    # The exact distances (hypot, slow) only for pairs a rough test with a 1 % margin
    # does not put outside the gate in both images.
    rough = _maybe_within(algebraic * fb, line_b, gate_px) & _maybe_within(
        algebraic * fa, line_a, gate_px
    )
    idx = np.flatnonzero(rough)
    algebraic, line_a, line_b = algebraic[idx], line_a[idx], line_b[idx]
    with np.errstate(divide="ignore", invalid="ignore"):
        dist_b = algebraic / np.hypot(line_b[:, 0], line_b[:, 1]) * fb[idx]
        dist_a = algebraic / np.hypot(line_a[:, 0], line_a[:, 1]) * fa[idx]
    dist = np.maximum(dist_a, dist_b)
    keep = dist < gate_px
    return a[idx[keep]], b[idx[keep]], dist[keep]


def _maybe_within(scaled: FloatArray, line: FloatArray, gate_px: float) -> NDArray[np.bool_]:
    """False only where ``scaled / |line[:, :2]|`` is surely at or beyond ``gate_px``
    (1 % margin; NaN, overflow or vanishing lines stay True)."""
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        n2 = line[:, 0] * line[:, 0] + line[:, 1] * line[:, 1]
        lhs = scaled * scaled
        rhs = (1.01 * gate_px) ** 2 * n2
        outside = (lhs >= rhs) & np.isfinite(lhs) & np.isfinite(rhs) & (n2 > 1e-200)
    return np.asarray(~outside)


def match_blobs(
    geom: RigGeometry,
    xy: FloatArray,
    camera: IntArray,
    *,
    gate_px: float = 2.0,
    min_cameras: int = 3,
    max_ray_px: float = 1.5,
) -> Correspondence:
    """Group blobs of different cameras into 3-D points by the epipolar constraint.

    Parameters
    ----------
    geom : RigGeometry
        The rig.
    xy : ndarray, shape (N, 2)
        Ideal normalised coordinates of the blobs (:meth:`RigGeometry.normalize`).
    camera : ndarray of int, shape (N,)
        Camera of each blob.
    gate_px : float
        Largest epipolar distance of a matched pair and largest distance between a
        seed's projection and a supporting blob (undistorted px).
    min_cameras : int
        Fewest cameras a point needs (>= 2).
    max_ray_px : float
        Largest ray error of a kept ray after triangulation (px).

    Returns
    -------
    Correspondence

    Raises
    ------
    ReconstructionError
        For ``min_cameras`` below 2 or arrays of mismatched shapes.
    """
    if min_cameras < 2:
        raise ReconstructionError(f"min_cameras must be at least 2, got {min_cameras}")
    cam = np.asarray(camera, dtype=np.intp)
    if xy.shape != (cam.size, 2):
        raise ReconstructionError(f"xy must have shape ({cam.size}, 2), got {xy.shape}")
    C = len(geom)
    empty = Correspondence(np.zeros((0, 3)), np.zeros((C, 0), np.intp), np.zeros((C, 0)))
    if np.count_nonzero(np.bincount(cam, minlength=C)) < min_cameras:  # cameras with blobs
        return empty
    a, b, dist = _epipolar_pairs(geom, xy, cam, gate_px)
    if a.size == 0:
        return empty
    X = _midpoints(geom, xy, cam, a, b)
    ok = np.isfinite(X[:, 0])
    a, b, dist, X = a[ok], b[ok], dist[ok], X[ok]
    if a.size == 0:
        return empty
    proj = geom.project(X)  # (C, S, 2)
    f = geom.f[cam]
    dx = proj[:, :, 0][cam].T - xy[:, 0]  # (S, N)
    dy = proj[:, :, 1][cam].T - xy[:, 1]
    # The exact distance (hypot, slow) only where a rough one, with a 1 % margin, is
    # within the gate: every blob near a seed passes the rough test; far ones stay inf.
    with np.errstate(invalid="ignore"):
        s_i, n_i = np.nonzero((dx * dx + dy * dy) * (f * f) < (1.01 * gate_px) ** 2)
    d = np.full(dx.shape, np.inf)
    d[s_i, n_i] = np.hypot(dx[s_i, n_i], dy[s_i, n_i]) * f[n_i]
    near = d < gate_px
    close = near[s_i, n_i]
    seen_by = np.zeros((X.shape[0], C), dtype=bool)  # (S, C): a near blob in camera c
    seen_by[s_i[close], cam[n_i[close]]] = True
    support = seen_by.sum(axis=1)
    order = np.lexsort((dist, -support))
    order = order[support[order] >= min_cameras]
    used = np.zeros(cam.size, dtype=bool)
    groups: list[IntArray] = []
    for s in order:
        if used[a[s]] or used[b[s]]:
            continue
        cand = np.flatnonzero(near[s] & ~used)
        cand = cand[np.lexsort((d[s, cand], cam[cand]))]
        _, first = np.unique(cam[cand], return_index=True)
        members = cand[first]
        if members.size < min_cameras:
            continue
        used[members] = True
        groups.append(members)
    if not groups:
        return empty
    G = len(groups)
    index = np.full((C, G), -1, dtype=np.intp)
    for g, members in enumerate(groups):
        index[cam[members], g] = members
    seen = index >= 0
    rays = np.where(seen[..., None], xy[np.maximum(index, 0)], 0.0)
    points, ray_px, kept = geom.triangulate(
        rays, seen, max_ray_px=max_ray_px, min_views=min_cameras
    )
    index[~kept] = -1
    good = np.isfinite(points[:, 0])
    return Correspondence(points[good], index[:, good], ray_px[:, good])
