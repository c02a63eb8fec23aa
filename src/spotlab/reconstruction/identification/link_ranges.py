"""Distance ranges between markers: which points fit a marker by its links.

Markers on no rigid cluster, and cluster markers while their cluster has fewer than
three points, are labelled by the ranges of their distances to labelled partners
(:class:`.model.Link`, segment mates). These are the checks
:mod:`.link_labels` runs for that: one marker against candidate points
(:func:`link_fit`), every marker against the free points (:func:`fit_counts`), and
the labels taken together in one round against their cluster distances
(:func:`agreeing_labels`). Distances in mm.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from spotlab.reconstruction.identification.model import MarkerModel

__all__ = ["agreeing_labels", "fit_counts", "length", "link_fit"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def length(v: FloatArray) -> FloatArray:
    """Euclidean lengths of vectors (..., 3), summed in the order of
    :func:`numpy.linalg.norm` (``(x^2 + y^2) + z^2``) without its overhead."""
    s = v * v
    return np.asarray(np.sqrt((s[..., 0] + s[..., 1]) + s[..., 2]))


def link_fit(
    model: MarkerModel,
    points: FloatArray,
    point_of: IntArray,
    marker: int,
    candidates: IntArray,
    tol_mm: float,
    min_links: int,
) -> tuple[NDArray[np.bool_], FloatArray]:
    """Which ``candidates`` (points) fit ``marker`` by its links to labelled markers
    (all within range, ``tol_mm`` beyond, at least ``min_links`` of them), and how far
    each sits from the middle of its ranges (RMS over the links, in half-widths)."""
    partner, lo, hi = model.partners[marker]
    have = point_of[partner] >= 0
    if have.sum() < min_links:
        return np.zeros(candidates.size, dtype=bool), np.full(candidates.size, np.inf)
    lo_, hi_ = lo[have], hi[have]
    d = length(points[candidates][:, None] - points[point_of[partner[have]]][None])
    ok = ((d >= lo_ - tol_mm) & (d <= hi_ + tol_mm)).all(axis=1)
    half = np.maximum(0.5 * (hi_ - lo_), tol_mm)
    off = np.sqrt(np.mean(((d - 0.5 * (lo_ + hi_)) / half) ** 2, axis=1))
    return np.asarray(ok), off


def fit_counts(
    model: MarkerModel,
    points: FloatArray,
    point_of: IntArray,
    free: IntArray,
    tol_mm: float,
    min_links: int,
) -> IntArray:
    """For every marker, how many of the ``free`` points fit it by its ranges to the
    labelled markers, as :func:`link_fit` judges (its own label left aside), shape (M,)."""
    M = point_of.size
    m_all, n_all, lo, hi = model.directed
    use = point_of[n_all] >= 0
    m_c, n_c = m_all[use], n_all[use]
    d = length(points[free][:, None] - points[point_of[n_c]][None])  # (P, L)
    ok = (d >= lo[use] - tol_mm) & (d <= hi[use] + tol_mm)
    cell = (np.arange(free.size)[:, None] * M + m_c[None]).ravel()
    bad = np.bincount(cell[~ok.ravel()], minlength=free.size * M).reshape(free.size, M)
    fits = (bad == 0) & (np.bincount(m_c, minlength=M) >= min_links)[None]
    return np.asarray(fits.sum(axis=0), dtype=np.intp)


def agreeing_labels(
    model: MarkerModel, points: FloatArray, rows: IntArray, markers: IntArray, tol_mm: float
) -> NDArray[np.bool_]:
    """Which of the labels :func:`.link_labels.linked_labels` takes in one round (marker
    ``markers[n]`` on point ``rows[n]``, shape (N,)) to keep, shape (N,).

    Each was judged against the markers labelled before, not against the others of its
    round. Two markers of one cluster labelled in the same round must keep their
    cluster distance (``tol_mm`` beyond its range), the model's tightest: where they do
    not, neither is taken (one distance cannot say which is wrong). Nothing would refuse
    the pair later: :func:`.labelling.inconsistent_labels` weighs that distance against the wider
    links and drops by the majority (``Walk1.c3d`` seed 1: the toe's label on the heel's
    point, taken with the ankle's 62 mm short of their range, kept for 22 frames).
    """
    keep = np.ones(markers.size, dtype=bool)
    if markers.size < 2:
        return keep
    slot = np.full(len(model.labels), -1, dtype=np.intp)
    slot[markers] = np.arange(markers.size)
    n = sum(len(seg.markers) * (len(seg.markers) - 1) // 2 for seg in model.segments)
    i, j, lo, hi = (v[:n] for v in model.intervals)  # the cluster pairs come first
    a, b = slot[i], slot[j]
    both = np.flatnonzero((a >= 0) & (b >= 0))
    if both.size == 0:
        return keep
    a, b = a[both], b[both]
    d = length(points[rows[a]] - points[rows[b]])
    bad = (d < lo[both] - tol_mm) | (d > hi[both] + tol_mm)
    keep[a[bad]] = False
    keep[b[bad]] = False
    return keep
