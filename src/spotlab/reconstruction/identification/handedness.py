"""Which way round a flat cluster sits: directions to markers off the cluster.

Distances cannot tell a flat cluster from its mirror image: three markers (or markers
nearly in one plane) are fitted as well by the wrong one of two alike markers (a
triangle with two sides alike, the left and right markers of a symmetric set) as by
the right one, and a wrong identity taken once passes every later distance check. A
marker off the cluster (on the next segment, over a joint) tells the two apart: seen
from the cluster's own frame, fitted to its labelled markers, it stays within a cone
of directions as the body moves, and a wrong identity turns the frame round (a mirror
image fitted by a rotation turns the cluster over) so that the marker falls outside.

:func:`learn_references` learns such directions (:class:`Reference`) from labelled
trajectories, for the flat clusters of a model; :func:`wrong_way_round` checks
candidate identities of one cluster against them, :func:`misplaced_segments` the
clusters labelled in one frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spotlab.reconstruction.rigid import rigid_fit, rigid_pose

__all__ = [
    "MARGIN_DEG",
    "Reference",
    "learn_references",
    "misplaced_segments",
    "side_table",
    "wrong_way_round",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

#: A reference marker outside its cone by more than this is on the wrong side (degrees):
#: room for motion the learnt frames did not show.
MARGIN_DEG = 25.0
#: Widest cone of a reference (degrees): wider ones hardly tell a mirror image apart.
MAX_SPREAD_DEG = 45.0
#: Share of the learnt frames whose directions fall inside the cone (the rest: glitches
#: in the file, a wrong label in the learnt frames).
CONE_SHARE = 0.99
#: References kept per cluster (the narrowest cones).
PER_SEGMENT = 4
#: A reference must stand at least this far from its cluster's centre (mm): nearer, the
#: skin motion of the cluster turns its direction.
MIN_DISTANCE_MM = 30.0
#: A side is learnt for a reference that stood this far off the cluster's plane (mm);
#: checked, a reference within ``SIDE_NOISE_MM`` of the plane says nothing.
MIN_SIDE_MM = 15.0
SIDE_NOISE_MM = 5.0

_NEXT = np.array([1, 2, 0])
_LAST = np.array([2, 0, 1])


@dataclass(frozen=True)
class Reference:
    """A marker seen in a fixed cone of directions from a cluster's frame.

    Attributes
    ----------
    segment : int
        Index of the cluster in :attr:`MarkerModel.segments`.
    marker : int
        Index of the reference marker (not on the cluster) in :attr:`MarkerModel.labels`.
    direction : ndarray, shape (3,)
        Unit axis of the cone, in the cluster's frame (its ``coordinates``).
    spread_deg : float
        Half-angle of the cone (degrees): the learnt directions' largest angle to the
        axis (of the ``CONE_SHARE`` nearest).
    triple : tuple of int
        Three markers of the cluster spanning its largest triangle (model indices), or
        () for none.
    side : int
        +1 or -1: the side of the triangle ``triple`` (its normal ``(b - a) x (c - a)``)
        the marker stood on, at least ``MIN_SIDE_MM`` off its plane, in the
        ``CONE_SHARE`` of the learnt frames; 0 when it did not keep to one side.
    """

    segment: int
    marker: int
    direction: FloatArray
    spread_deg: float
    triple: tuple[int, ...] = ()
    side: int = 0


def is_flat(coordinates: FloatArray, tolerance_mm: float) -> bool:
    """Whether a cluster (P, 3) mm is nearly in one plane: its RMS distance to its best
    plane below ``tolerance_mm``, so a mirror image fits it within the tolerance."""
    c = coordinates - coordinates.mean(axis=0)
    s = np.linalg.svd(c, compute_uv=False)
    return bool(s[-1] / np.sqrt(c.shape[0]) < tolerance_mm) if c.shape[0] >= 3 else True


def learn_references(
    segments: tuple[tuple[IntArray, FloatArray], ...],
    positions: FloatArray,
    tolerance_mm: float,
) -> tuple[Reference, ...]:
    """Reference markers of the flat clusters, learnt from labelled trajectories.

    Parameters
    ----------
    segments : tuple of (markers, coordinates)
        Each cluster's marker indices (P,) and its layout (P, 3) mm, in model order.
    positions : ndarray, shape (F, M, 3)
        Labelled trajectories (mm), NaN where missing.
    tolerance_mm : float
        Rigid tolerance of the model: a cluster closer than this to a plane is flat.

    Returns
    -------
    tuple of Reference
        Up to ``PER_SEGMENT`` per flat cluster, the narrowest cones first, each no wider
        than ``MAX_SPREAD_DEG``, of markers off the cluster seen (with the cluster
        complete) in at least half of the frames where the cluster is complete.
    """
    out: list[Reference] = []
    for s, (markers, coords) in enumerate(segments):
        if not is_flat(coords, tolerance_mm):
            continue
        Y = positions[:, markers]
        complete = np.isfinite(Y).all(axis=(1, 2))
        if complete.sum() < 3:
            continue
        triple = _largest_triangle(coords)
        heights = _heights(positions[complete][:, markers[triple]], positions[complete])
        pose = rigid_pose(coords, Y[complete])
        R, t = pose.R[pose.valid], pose.t[pose.valid]
        X = positions[complete][pose.valid]
        local = np.einsum("fji,fmj->fmi", R, X - t[:, None, :])  # (F, M, 3)
        dist = np.linalg.norm(local, axis=2)
        found: list[Reference] = []
        for m in np.setdiff1d(np.arange(positions.shape[1]), markers):
            ok = np.isfinite(dist[:, m]) & (dist[:, m] > 0)
            if ok.sum() < max(3, 0.5 * X.shape[0]) or np.median(dist[ok, m]) < MIN_DISTANCE_MM:
                continue
            u = local[ok, m] / dist[ok, m, None]
            axis = u.mean(axis=0)
            norm = float(np.linalg.norm(axis))
            if norm < 1e-9:
                continue
            axis /= norm
            angle = np.degrees(np.arccos(np.clip(u @ axis, -1.0, 1.0)))
            spread = float(np.quantile(angle, CONE_SHARE))
            if spread <= MAX_SPREAD_DEG:
                h = heights[:, m][np.isfinite(heights[:, m])]
                side = 0
                for sign in (1, -1):
                    if h.size and np.quantile(sign * h, 1.0 - CONE_SHARE) > MIN_SIDE_MM:
                        side = sign
                tri = tuple(int(markers[k]) for k in triple)
                found.append(Reference(s, int(m), axis, spread, tri, side))
        found.sort(key=lambda r: r.spread_deg)
        out.extend(found[:PER_SEGMENT])
    return tuple(out)


def _largest_triangle(coords: FloatArray) -> list[int]:
    """Indices of the three points (P, 3) spanning the largest triangle."""
    P = coords.shape[0]
    best, area = [0, 1, 2], -1.0
    for i in range(P):
        for j in range(i + 1, P):
            for k in range(j + 1, P):
                a = float(np.linalg.norm(np.cross(coords[j] - coords[i], coords[k] - coords[i])))
                if a > area:
                    best, area = [i, j, k], a
    return best


def _heights(tri: FloatArray, X: FloatArray) -> FloatArray:
    """Signed distances (F, M) mm of points ``X`` (F, M, 3) from the planes of the
    triangles ``tri`` (F, 3, 3), along ``(b - a) x (c - a)``; NaN where unknown."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    n = np.cross(b - a, c - a)
    with np.errstate(invalid="ignore", divide="ignore"):
        n = n / np.linalg.norm(n, axis=1, keepdims=True)
    return np.asarray(np.einsum("fi,fmi->fm", n, X - a[:, None, :]))


def _verdicts(
    coords: FloatArray, observed: FloatArray, refs: list[Reference], ref_points: FloatArray
) -> tuple[IntArray, IntArray]:
    """Per candidate (n,): how many labelled references fall outside their cone (beyond
    ``MARGIN_DEG``) and how many inside, for the cluster placed at ``observed`` (n, P, 3)
    and the references at ``ref_points`` (K, 3), NaN where unlabelled."""
    R, t, _ = rigid_fit(coords, observed)
    local = np.einsum("nji,nkj->nki", R, ref_points[None] - t[:, None, :])  # (n, K, 3)
    norm = np.linalg.norm(local, axis=2)
    axes = np.array([r.direction for r in refs])
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.einsum("nki,ki->nk", local, axes) / norm
    angle = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    limit = np.array([r.spread_deg for r in refs]) + MARGIN_DEG
    known = np.isfinite(angle)
    outside = known & (angle > limit)
    return outside.sum(axis=1), (known & ~outside).sum(axis=1)


def wrong_way_round(
    coords: FloatArray,
    refs: list[Reference],
    points: FloatArray,
    rows: IntArray,
    ref_rows: IntArray,
) -> NDArray[np.bool_]:
    """Candidate identities of one cluster that its references refuse.

    Parameters
    ----------
    coords : ndarray, shape (P, 3)
        The cluster's layout (mm).
    refs : list of Reference
        The cluster's references.
    points : ndarray, shape (K, 3)
        Points of the frame (mm).
    rows : ndarray of int, shape (n, P)
        Candidate point of each marker (-1: missing).
    ref_rows : ndarray of int, shape (len(refs),)
        Point labelled as each reference marker, -1 where unlabelled.

    Returns
    -------
    ndarray of bool, shape (n,)
        True where at least as many labelled references fall outside their cones as
        inside, and one at least (a doubtful identity waits: no label beats a wrong one).
    """
    if not refs or not (ref_rows >= 0).any() or rows.shape[0] == 0:
        return np.zeros(rows.shape[0], dtype=bool)
    padded = np.vstack([points, np.full((1, 3), np.nan)])
    K = points.shape[0]
    observed = padded[np.where(rows >= 0, rows, K)]
    ref_points = padded[np.where(ref_rows >= 0, ref_rows, K)]
    outside, inside = _verdicts(coords, observed, refs, ref_points)
    return np.asarray((outside > 0) & (outside >= inside))


def side_table(refs: tuple[Reference, ...]) -> tuple[IntArray, IntArray, FloatArray]:
    """The references with a side, as arrays ``(segment (n,), markers (4, n), side (n,))``,
    ``markers`` the triangle's three then the reference (built once per model:
    :func:`misplaced_segments` uses them every frame)."""
    keep = [r for r in refs if r.side != 0 and len(r.triple) == 3]
    return (
        np.array([r.segment for r in keep], dtype=np.intp),
        np.array([[*r.triple, r.marker] for r in keep], dtype=np.intp).reshape(-1, 4).T.copy(),
        np.array([r.side for r in keep], dtype=np.float64),
    )


def misplaced_segments(
    segments: tuple[tuple[IntArray, FloatArray], ...],
    table: tuple[IntArray, IntArray, FloatArray],
    points: FloatArray,
) -> NDArray[np.bool_]:
    """Labels of clusters turned the wrong way round in one frame.

    Parameters
    ----------
    segments : tuple of (markers, coordinates)
        Each cluster's marker indices and layout (mm).
    table : tuple of arrays
        :func:`side_table` of the model's references.
    points : ndarray, shape (M, 3)
        Labelled points of the frame in model order (mm), NaN where missing.

    Returns
    -------
    ndarray of bool, shape (M,)
        True for every marker of a cluster on whose triangle (labelled) more labelled
        references stand on the wrong side than on their own (more than
        ``SIDE_NOISE_MM`` off its plane): a mirror image (two alike markers exchanged)
        turns the triangle over. Its identity is dropped and found again, with the
        references, from the cluster's shape. A few array operations for all clusters:
        cheap enough for every frame.
    """
    drop = np.zeros(points.shape[0], dtype=bool)
    segment, markers, side = table
    if segment.size == 0:
        return drop
    q = points[markers]  # (4, n, 3): a, b, c, the reference
    d = q[1:] - q[0]  # b - a, c - a, reference - a
    u, v = d[0], d[1]
    n = u[:, _NEXT] * v[:, _LAST]
    n -= u[:, _LAST] * v[:, _NEXT]  # (b - a) x (c - a)
    along = np.einsum("ij,ij->i", n, d[2]) * side  # height on its side, times |n|
    nn = np.einsum("ij,ij->i", n, n)
    with np.errstate(invalid="ignore"):
        far = along * along > SIDE_NOISE_MM**2 * nn
        wrong = far & (along < 0.0)
    if not wrong.any():
        return drop
    right = far & ~wrong
    S = len(segments)
    bad = np.bincount(segment[wrong], minlength=S) > np.bincount(segment[right], minlength=S)
    for s in np.flatnonzero(bad):
        drop[segments[s][0]] = True
    return drop
