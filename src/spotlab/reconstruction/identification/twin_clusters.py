"""Clusters another cluster's shape fits, and the links that refute them.

A body is nearly symmetric: the two hands' triangles, the two feet, may have the same
distances, and three markers fit their mirror image exactly. Such a *twin* cluster
(:func:`twin_segments`) can take the other side's points, and its shape then passes
every check of its own (the smallest RMS, :func:`.labelling.inconsistent_labels`,
which weighs its labels mostly against their own cluster distances). Its markers'
links to markers off the cluster (the elbow, the upper arm) are out of range there,
but they cannot say so: a marker is labelled by its links only where *every* labelled
partner is in range, so the wrong cluster labels keep the markers that would refute
them unlabelled. :func:`refuted_twins` reads that evidence off the free points: a
marker off the cluster with exactly one free point fitting all its links to the other
labelled markers (three or more), where that point lies out of more of its links to
the cluster's labelled markers than within them. The cluster's labels are then dropped
and its identity found again.

Found on ``read_NOTworking2.c3d`` (the hands' triangles alike within 3 mm):
``docs/identification.md``.
"""

from __future__ import annotations

from itertools import combinations, permutations

import numpy as np
from numpy.typing import NDArray

from spotlab.reconstruction.identification.link_ranges import length
from spotlab.reconstruction.identification.model import MarkerModel

__all__ = ["refuted_twins", "twin_partners", "twin_segments"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def twin_segments(model: MarkerModel, tol_mm: float) -> tuple[int, ...]:
    """Segments three of whose markers fit three markers of another segment.

    Parameters
    ----------
    model : MarkerModel
    tol_mm : float
        Largest difference of two distances that still fit (mm): the identifier's
        distance tolerance, with which a cluster's identity is taken.

    Returns
    -------
    tuple of int
        Indices of the segments (in ``model.segments``) with a twin, in order.
    """
    return tuple(sorted(twin_partners(model, tol_mm)))


def twin_partners(model: MarkerModel, tol_mm: float) -> dict[int, tuple[int, ...]]:
    """The twins of each segment that has any (:func:`twin_segments`), in order."""
    shapes = [_triangles(seg.coordinates) for seg in model.segments]
    twins: dict[int, list[int]] = {}
    for a, b in combinations(range(len(shapes)), 2):
        d = np.abs(shapes[a][:, None] - shapes[b][None])  # (Ta, Tb, 3)
        if (d <= tol_mm).all(axis=2).any():
            twins.setdefault(a, []).append(b)
            twins.setdefault(b, []).append(a)
    return {s: tuple(sorted(t)) for s, t in sorted(twins.items())}


def _triangles(coords: FloatArray) -> FloatArray:
    """Side lengths (T, 3) of every ordered triangle of a cluster's markers (mm)."""
    sides = []
    for tri in combinations(range(coords.shape[0]), 3):
        for i, j, k in permutations(tri):
            p = coords[[i, j, k]]
            sides.append(length(p - p[[1, 2, 0]]))
    return np.array(sides).reshape(-1, 3)


def refuted_twins(
    model: MarkerModel,
    twins: tuple[int, ...],
    points: FloatArray,
    free: FloatArray,
    tol_mm: float,
    min_links: int = 3,
) -> NDArray[np.bool_]:
    """Labels of twin clusters that a marker off them refutes by its links.

    Parameters
    ----------
    model : MarkerModel
    twins : tuple of int
        Segments to check (:func:`twin_segments`).
    points : ndarray, shape (M, 3)
        Labelled points of one frame in model order (mm), NaN where unlabelled.
    free : ndarray, shape (K, 3)
        Unlabelled points of the frame (mm).
    tol_mm : float
        Distance tolerance beyond a link's range (mm).
    min_links : int
        Labelled partners off the cluster, all in range, a marker needs to testify.

    Returns
    -------
    ndarray of bool, shape (M,)
        True for every marker of a twin cluster with labelled markers for which some
        unlabelled marker ``r`` off it has exactly one free point within range of all
        its links to labelled markers off the cluster (``min_links`` or more, ``tol_mm``
        beyond), and that point is out of range of more of ``r``'s links to the
        cluster's labelled markers than within, by more than the model's rigid
        tolerance (:attr:`.MarkerModel.tolerance_mm`; ``tol_mm`` if larger or None).

    Notes
    -----
    The other side's points are hundreds of mm out of the links (``read_NOTworking2``:
    90-235 mm). Ranges learnt from part of a trial are exceeded by poses it did not
    show by a few mm to tens of mm (a pelvis marker to the toe, 3-7 mm beyond in
    ``Gait with EMG``): the model treats deviations within its rigid tolerance as skin
    motion, so only a deviation beyond it is evidence. Free points within ``tol_mm``
    of a labelled point (a second track on a marker) are no marker of their own and
    are left out.
    """
    M = points.shape[0]
    drop = np.zeros(M, dtype=bool)
    if not twins or free.shape[0] == 0:
        return drop
    labelled = np.asarray(np.isfinite(points).all(axis=1), dtype=bool)
    # a free point on a labelled one is a second track of that marker, not another marker
    apart = length(free[:, None] - points[labelled][None]).min(axis=1, initial=np.inf) > tol_mm
    free = free[apart]
    far = max(tol_mm, model.tolerance_mm or 0.0)
    segment_of = model.segment_of
    for s in twins:
        mine = np.array(model.segments[s].markers, dtype=np.intp)
        if not labelled[mine].any():
            continue
        for r in np.flatnonzero(~labelled & (segment_of != s)):
            partner, lo, hi = model.partners[r]
            have = labelled[partner]
            to_s = have & (segment_of[partner] == s)
            rest = have & ~to_s
            if not to_s.any() or rest.sum() < min_links:
                continue
            d = length(free[:, None] - points[partner[have]][None])  # (K, L)
            ok = (d >= lo[have] - tol_mm) & (d <= hi[have] + tol_mm)
            on_s = to_s[have]
            fits = ok[:, ~on_s].all(axis=1)
            if fits.sum() != 1:
                continue
            k = np.flatnonzero(fits)[0]
            out = (d[k, on_s] < lo[have][on_s] - far) | (d[k, on_s] > hi[have][on_s] + far)
            if out.sum() > (~out).sum():
                drop[mine] = True
                break
    return drop
