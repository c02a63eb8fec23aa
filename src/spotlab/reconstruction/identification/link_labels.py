"""Labels by links: free points labelled by their distance ranges to labelled markers.

Markers still missing after the cluster fits (:mod:`.labelling`) -- a marker on no
rigid cluster, or a cluster marker while its cluster has fewer than three points in
view -- are labelled by the ranges of their distances to labelled partners
(:class:`.model.Link`, segment mates; checks in :mod:`.link_ranges`):

* :func:`linked_labels` takes a label only where the point fits that marker alone and
  the marker that point alone, and two segment mates labelled so together keep their
  segment distance;
* :func:`exchanged_labels` undoes a label taken by the wrong one of two nearby markers
  on no segment, where exchanging it labels one more marker.

Both work in place on one frame's ``labels`` (label per point) and ``point_of`` (point
per marker); distances in mm.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from spotlab.reconstruction.identification.link_ranges import (
    agreeing_labels,
    fit_counts,
    length,
    link_fit,
)
from spotlab.reconstruction.identification.model import MarkerModel

__all__ = ["exchanged_labels", "linked_labels"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def exchanged_labels(
    model: MarkerModel,
    points: FloatArray,
    labels: IntArray,
    point_of: IntArray,
    tol_mm: float,
    min_links: int,
    linkable: NDArray[np.bool_],
) -> bool:
    """Undo a label taken by the wrong one of two nearby markers; True if any was.

    Markers on no segment are labelled by distance ranges alone, and two markers close
    together with wide ranges (the two wrist markers) can both fit one point: the first
    label taken may be the other marker's, and tracking then carries it while the right
    point stays free (it fits the marker already taken, nothing else). For a labelled
    marker ``m`` on no segment, with its point ``p``: when exactly one free point ``q``
    fits ``m``, ``q`` fits no missing marker, ``p`` fits exactly one missing marker
    ``m2``, ``q`` sits nearer the middle of ``m``'s ranges than ``p`` does and ``p``
    nearer the middle of ``m2``'s than of ``m``'s, the labels become ``m`` on ``q`` and
    ``m2`` on ``p``: one more marker labelled, every range kept.
    """
    owner = model.segment_of
    changed = False
    markers = np.flatnonzero((point_of >= 0) & (owner < 0))
    free = np.flatnonzero(labels < 0)
    if free.size == 0 or not (point_of < 0).any():
        return False
    # Until a label is exchanged, the free points fitting each marker: one pass for all.
    n_fit = fit_counts(model, points, point_of, free, tol_mm, min_links)
    for m in markers:
        if not changed and n_fit[m] != 1:
            continue
        free = np.flatnonzero(labels < 0)
        missing = np.flatnonzero(point_of < 0)
        if free.size == 0 or missing.size == 0:
            break
        p = int(point_of[m])
        point_of[m] = -1  # judged without its own label
        q_ok, q_off = link_fit(model, points, point_of, int(m), free, tol_mm, min_links)
        if q_ok.sum() != 1:
            point_of[m] = p
            continue
        here = np.array([p], dtype=np.intp)
        _, p_off = link_fit(model, points, point_of, int(m), here, tol_mm, min_links)
        point_of[m] = p
        if not q_off[q_ok][0] < p_off[0]:
            continue
        q = int(free[q_ok][0])
        if not linkable[q]:
            continue
        point_of[m] = -1
        p_fits = []
        for m2 in missing:
            ok, off = link_fit(model, points, point_of, int(m2), here, tol_mm, min_links)
            if ok[0]:
                p_fits.append((int(m2), float(off[0])))
        point_of[m] = p
        # p must be more an m2 than an m (nearer the middle of m2's ranges than of m's)
        if len(p_fits) != 1 or not p_fits[0][1] < p_off[0]:
            continue
        q_fits_missing = any(
            link_fit(model, points, point_of, int(m2), np.array([q]), tol_mm, min_links)[0][0]
            for m2 in missing
        )
        if q_fits_missing:
            continue
        other = p_fits[0][0]
        labels[q], labels[p] = m, other
        point_of[m], point_of[other] = q, p
        changed = True
    return changed


def linked_labels(
    model: MarkerModel,
    points: FloatArray,
    labels: IntArray,
    point_of: IntArray,
    tol_mm: float,
    min_links: int,
    linkable: NDArray[np.bool_],
) -> bool:
    """Label free points by the distance ranges to labelled markers; True if any was.

    A free point fits a missing marker when its distances to at least ``min_links``
    labelled markers linked to it (segment mates included) are all within their ranges
    (``tol_mm`` beyond); a pair is taken only where the marker fits one point and the
    point fits one marker, so two candidates leave both unlabelled; two markers of one
    cluster taken in the same round must keep their cluster distance
    (:func:`.link_ranges.agreeing_labels`).
    """
    free = np.flatnonzero(labels < 0)
    missing = np.flatnonzero(point_of < 0)
    if free.size == 0 or missing.size == 0:
        return False
    # constraints of each missing marker m: a labelled partner n with its range
    m_all, n_all, lo2, hi2 = model.directed
    use = (point_of[m_all] < 0) & (point_of[n_all] >= 0)
    if not use.any():
        return False
    m_c, n_c, lo_c, hi_c = m_all[use], n_all[use], lo2[use], hi2[use]
    dist = length(points[free][:, None] - points[point_of[n_c]][None])  # (P, L)
    ok = (dist >= lo_c - tol_mm) & (dist <= hi_c + tol_mm)
    slot = np.searchsorted(missing, m_c)
    n_checks = np.bincount(slot, minlength=missing.size)
    bad = np.zeros((free.size, missing.size), dtype=np.intp)
    np.add.at(bad.T, slot, (~ok).T.astype(np.intp))
    fits = (bad == 0) & (n_checks >= min_links)[None]  # (P, missing)
    unique = fits & (fits.sum(axis=1, keepdims=True) == 1) & (fits.sum(axis=0) == 1)[None]
    unique &= linkable[free][:, None]  # the others count as candidates, never take one
    p, k = np.nonzero(unique)
    keep = agreeing_labels(model, points, free[p], missing[k], tol_mm)
    p, k = p[keep], k[keep]
    labels[free[p]] = missing[k]
    point_of[missing[k]] = free[p]
    return bool(p.size)
