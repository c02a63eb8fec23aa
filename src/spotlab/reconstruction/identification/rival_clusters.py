"""Two clusters alike that would take the same points: which identity waits.

The smallest RMS decides between the candidate identities of one cluster, and a choice
whose runner-up is within ``margin_mm`` waits (Woltring & Huiskes 1990: the RMS is a
criterion, not a proof). Two clusters of the same shape (a body's two hands or feet)
can both fit the same three points; :func:`.labelling.assign_labels` then applies the
caveat across clusters:

* :func:`rivals`: other clusters whose best identity takes some of the same unlabelled
  points with an RMS within ``margin_mm`` of the best one. They and the best one wait,
  unless exactly one of them places every marker of its cluster (the others leave a
  marker missing, an assumption the complete one does not need);
* :func:`twin_leads`: a cluster is tried only on points near where it was last seen,
  so its twin (:func:`.twin_clusters.twin_partners`) may not even be a candidate for
  points that are its own. A new identity of a cluster none of whose markers is
  labelled waits where a twin, tried on every free point, fits some of the same points
  better by ``margin_mm``.

Found on ``read_NOTworking2.c3d`` (the two hands' triangles alike within 3 mm):
``docs/identification.md``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np
from numpy.typing import NDArray

__all__ = ["Offer", "rivals", "twin_leads"]

IntArray = NDArray[np.intp]
#: A cluster's best identity: its RMS (mm) and the point of each marker (or -1).
Offer = tuple[float, IntArray]


def _new_points(rows: IntArray, labels: IntArray) -> IntArray:
    """The points of ``rows`` not labelled yet."""
    taken = rows[rows >= 0]
    return taken[labels[taken] < 0]


def rivals(s: int, offers: dict[int, Offer], labels: IntArray, margin_mm: float) -> list[int]:
    """Segments whose offered identity takes some of the new points of segment ``s``'s
    with an RMS within ``margin_mm`` of it.

    Parameters
    ----------
    s : int
        The segment with the smallest RMS among ``offers``.
    offers : dict
        Acceptable best identity of each segment still pending.
    labels : ndarray of int, shape (K,)
        Labels of the frame's points so far (-1: unlabelled); only unlabelled points
        count as shared (a segment's own labelled points are no contest).
    margin_mm : float
        Smallest RMS lead of an identity taken.

    Returns
    -------
    list of int
        The rival segments (empty: ``s``'s identity may be taken).
    """
    rms, rows = offers[s]
    new = _new_points(rows, labels)
    return [
        t
        for t, (other_rms, other_rows) in offers.items()
        if t != s and other_rms - rms < margin_mm and np.isin(new, other_rows).any()
    ]


def twin_leads(
    offer: Offer,
    labels: IntArray,
    margin_mm: float,
    twins: Iterable[int],
    best_anywhere: Callable[[int], Offer | None],
) -> bool:
    """Whether a twin, tried on every free point, fits some of the new points of
    ``offer`` better by ``margin_mm``.

    Parameters
    ----------
    offer : Offer
        The identity about to be taken, of a segment none of whose markers is labelled.
    labels : ndarray of int, shape (K,)
        Labels of the frame's points so far (-1: unlabelled).
    margin_mm : float
        Smallest RMS lead of an identity taken.
    twins : iterable of int
        The segment's twins still pending.
    best_anywhere : callable
        The best identity of a segment among all free points (its anchor aside), with
        its RMS, or None.

    Returns
    -------
    bool
        True if the identity waits.
    """
    rms, rows = offer
    new = _new_points(rows, labels)
    for t in twins:
        other = best_anywhere(t)
        if other is not None and other[0] <= rms - margin_mm and np.isin(new, other[1]).any():
            return True
    return False
