"""Two link-only markers exchanged: told apart by the directions a cluster sees them in.

Markers on no rigid cluster are labelled by their distance ranges to labelled markers
(:mod:`.link_labels`). Two such markers near each other (the two metatarsal markers of
a foot) may have ranges so wide and alike that either fits the other's point, and once
taken the wrong way round tracking carries the exchange to the end of the trial. The
ranges cannot undo it; a cluster nearby can. Seen from a flat cluster's own frame, a
marker off it keeps to a narrow cone of directions (:class:`.handedness.Reference`:
the shank's cluster sees each forefoot marker within a few degrees as the ankle moves).
Where two link-only markers are both references of one labelled cluster, the sum of
their angles to their cones' axes is compared with the sum with their points exchanged;
when the exchange brings them nearer their axes by more than the wider of the two cones,
their labels are exchanged (:func:`exchanged_references`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spotlab.reconstruction.identification.model import MarkerModel
from spotlab.reconstruction.rigid import kabsch

__all__ = ["ClusterPairs", "exchanged_references", "reference_pairs"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


@dataclass(frozen=True)
class ClusterPairs:
    """The link-only references of one cluster that form pairs, as arrays.

    Attributes
    ----------
    segment : int
        Index of the cluster in :attr:`.MarkerModel.segments`.
    marker : ndarray of int, shape (U,)
        The references' markers.
    axes : ndarray, shape (U, 3)
        Their cones' axes in the cluster's frame.
    spread : ndarray, shape (U,)
        Their cones' half-angles (degrees).
    first, second : ndarray of int, shape (k,)
        The pairs, as rows of the arrays above.
    """

    segment: int
    marker: IntArray
    axes: FloatArray
    spread: FloatArray
    first: IntArray
    second: IntArray


def reference_pairs(model: MarkerModel) -> tuple[ClusterPairs, ...]:
    """The pairs of link-only references of each cluster (built once per model)."""
    owner = model.segment_of
    refs = model.references
    out = []
    for s in sorted({r.segment for r in refs}):
        loose = [r for r in refs if r.segment == s and owner[r.marker] < 0]
        if len(loose) < 2:
            continue
        first, second = np.triu_indices(len(loose), k=1)
        out.append(
            ClusterPairs(
                s,
                np.array([r.marker for r in loose], dtype=np.intp),
                np.array([r.direction for r in loose]),
                np.array([r.spread_deg for r in loose]),
                first.astype(np.intp),
                second.astype(np.intp),
            )
        )
    return tuple(out)


def exchanged_references(
    model: MarkerModel, table: tuple[ClusterPairs, ...], points: FloatArray
) -> list[tuple[int, int]]:
    """Pairs of labelled link-only markers whose labels are the wrong way round.

    Parameters
    ----------
    model : MarkerModel
    table : tuple of ClusterPairs
        :func:`reference_pairs` of ``model``.
    points : ndarray, shape (M, 3)
        Labelled points of one frame in model order (mm), NaN where missing.

    Returns
    -------
    list of (int, int)
        Marker pairs to exchange: for each, the angles of the two points to their cones'
        axes (seen from the cluster fitted to its labelled markers, three at least) sum
        to more than with the points exchanged, by more than the wider cone's half-angle.
        A marker in two such pairs is left as it is.
    """
    found: list[tuple[int, int]] = []
    for c in table:
        held = np.isfinite(points[c.marker, 0])
        if not (held[c.first] & held[c.second]).any():
            continue  # no pair with both markers labelled
        markers, coords = model.segment_arrays[c.segment]
        observed = points[markers]
        seen = np.isfinite(observed[:, 0])
        if seen.sum() < 3:
            continue
        R, t = kabsch(coords[seen], observed[seen])
        local = (points[c.marker] - t) @ R  # rows: R^T (x - t)
        with np.errstate(invalid="ignore", divide="ignore"):
            u = local / np.linalg.norm(local, axis=1, keepdims=True)
        angle = np.degrees(np.arccos(np.clip(u @ c.axes.T, -1.0, 1.0)))  # [point, axis]
        i, j = c.first, c.second
        own = angle[i, i] + angle[j, j]
        exchanged = angle[j, i] + angle[i, j]
        with np.errstate(invalid="ignore"):
            hit = own - exchanged > np.maximum(c.spread[i], c.spread[j])  # False where NaN
        if hit.any():
            found.extend(zip(c.marker[i[hit]].tolist(), c.marker[j[hit]].tolist(), strict=True))
    if not found:
        return found
    count = np.bincount(np.array(found, dtype=np.intp).ravel(), minlength=len(model.labels))
    return [(m, n) for m, n in found if count[m] == 1 and count[n] == 1]
