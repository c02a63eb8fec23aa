"""A flat cluster's identity tried with the labels its links give, before it is taken.

A flat cluster none of whose references (:mod:`.handedness`) is labelled cannot be told
from its mirror image by its shape: a triangle with two sides alike is fitted by either
of its two alike markers, and the tree's distance tolerance may leave just one of the
two identities in by a fraction of a mm (``TYPE-2.C3D``: three pelvis markers 240, 242
and 251 mm apart). Its references are often markers on no cluster that the links label
once the cluster is labelled (the legs under a pelvis). An identity taken wrongly then
makes the links label the references as their mirror images too (the left leg's
markers as the right's), and the references, checked after the frame, refuse the
cluster: but the labels the links gave from it stay, and tracking carries them.

So each candidate identity is tried first: taken on copies of the frame's labels, the
link rounds run as they would after it, and the references so labelled checked against
it, by their cones (:func:`.handedness.wrong_way_round`) and their sides
(:func:`.handedness.misplaced_segments`). Handedness is no distance: relabelling by
distances cannot keep it, so the mirror identity's own references refuse it. The
identities refused are left out; the rest still need the clear lead a flat cluster
needs without its references (:func:`.labelling.assign_labels`). References labelled
by links in a trial only refuse, they never vouch: links that fit a wrong point (a
trial whose learnt ranges miss the motion) would then let a cluster be taken on a small
lead (``Sample_Jump2.c3d`` seed 2: 0.16 -> 3.7 % wrong both ways, tried and not kept).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from spotlab.reconstruction.identification.handedness import (
    misplaced_segments,
    wrong_way_round,
)
from spotlab.reconstruction.identification.model import MarkerModel

__all__ = [
    "BORNE_OUT",
    "REFUSED",
    "UNTOLD",
    "LinkRounds",
    "Trial",
    "identity_verdicts",
    "trial_of",
    "unrefused",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

#: Verdicts of :func:`identity_verdicts`.
REFUSED, UNTOLD, BORNE_OUT = -1, 0, 1

#: ``link_rounds(labels, point_of)``: label free points by links, in place.
LinkRounds = Callable[[IntArray, IntArray], None]
#: ``trial(table)``: :func:`unrefused` rows of one cluster's candidates in one frame.
Trial = Callable[[IntArray], IntArray]


def trial_of(
    model: MarkerModel,
    s: int,
    points: FloatArray,
    labels: IntArray,
    point_of: IntArray,
    link_rounds: LinkRounds | None,
) -> Trial | None:
    """The trial of segment ``s``'s candidate identities in this frame, or None when it
    has no references, one of them is labelled (they judge directly), or there are no
    ``link_rounds``."""
    refs = model.references_by_segment.get(s, [])
    if link_rounds is None or not refs or (point_of[[r.marker for r in refs]] >= 0).any():
        return None
    rounds = link_rounds

    def trial(table: IntArray) -> IntArray:
        return unrefused(model, s, points, labels, point_of, table, rounds)

    return trial


def unrefused(
    model: MarkerModel,
    s: int,
    points: FloatArray,
    labels: IntArray,
    point_of: IntArray,
    table: IntArray,
    link_rounds: LinkRounds,
) -> IntArray:
    """The candidate identities (rows of ``table``, shape (n, P)) the references the
    links label do not refuse (:func:`identity_verdicts`), shape (n', P)."""
    verdict = identity_verdicts(model, s, points, labels, point_of, table, link_rounds)
    return table[verdict != REFUSED]


def identity_verdicts(
    model: MarkerModel,
    s: int,
    points: FloatArray,
    labels: IntArray,
    point_of: IntArray,
    table: IntArray,
    link_rounds: LinkRounds,
) -> IntArray:
    """What segment ``s``'s references say of each candidate identity, once labelled.

    Parameters
    ----------
    model : MarkerModel
    s : int
        The cluster (index into ``model.segments``); its references none labelled yet.
    points : ndarray, shape (K, 3)
        Points of the frame (mm).
    labels : ndarray of int, shape (K,)
        Label of each point (marker index) or -1; left unchanged.
    point_of : ndarray of int, shape (M,)
        Point of each marker or -1; left unchanged.
    table : ndarray of int, shape (n, P)
        Candidate point of each of the cluster's markers (-1: missing).
    link_rounds : callable
        Labels free points by links in the copies it is given (``labels``,
        ``point_of``), as :func:`.labelling.assign_labels` does after the clusters.

    Returns
    -------
    ndarray of int, shape (n,)
        ``REFUSED`` where the references the links then label put the cluster the wrong
        way round, ``BORNE_OUT`` where they are labelled and do not, ``UNTOLD`` where
        the links label none of them.
    """
    seg = model.segments[s]
    refs = model.references_by_segment.get(s, [])
    out = np.full(table.shape[0], UNTOLD, dtype=np.intp)
    if not refs:
        return out
    ref_markers = np.array([r.marker for r in refs], dtype=np.intp)
    markers = np.asarray(seg.markers, dtype=np.intp)
    for n, row in enumerate(table):
        lab, where = labels.copy(), point_of.copy()
        new = (row >= 0) & (where[markers] < 0)
        lab[row[new]] = markers[new]
        where[markers[new]] = row[new]
        link_rounds(lab, where)
        ref_rows = where[ref_markers]
        if not (ref_rows >= 0).any():
            continue
        wrong = wrong_way_round(seg.coordinates, refs, points, row[None], ref_rows)[0]
        placed = np.full((len(model.labels), 3), np.nan)
        placed[lab[lab >= 0]] = points[lab >= 0]
        turned = misplaced_segments(model.segment_arrays, model.sides, placed)[markers].any()
        out[n] = REFUSED if wrong or turned else BORNE_OUT
    return out
