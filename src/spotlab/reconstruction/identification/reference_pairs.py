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

import numpy as np
from numpy.typing import NDArray

from spotlab.reconstruction.identification.model import MarkerModel
from spotlab.reconstruction.rigid import rigid_fit

__all__ = ["exchanged_references", "reference_pairs"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

#: Per cluster: its index and the pairs (k, 2) of its references (indices into
#: :attr:`.MarkerModel.references`) whose markers are on no cluster.
PairTable = tuple[tuple[int, IntArray], ...]


def reference_pairs(model: MarkerModel) -> PairTable:
    """The pairs of link-only references of each cluster (built once per model)."""
    owner = model.segment_of
    out = []
    refs = model.references
    for s in sorted({r.segment for r in refs}):
        loose = [k for k, r in enumerate(refs) if r.segment == s and owner[r.marker] < 0]
        pairs = [(a, b) for i, a in enumerate(loose) for b in loose[i + 1 :]]
        if pairs:
            out.append((s, np.array(pairs, dtype=np.intp)))
    return tuple(out)


def exchanged_references(
    model: MarkerModel, table: PairTable, points: FloatArray
) -> list[tuple[int, int]]:
    """Pairs of labelled link-only markers whose labels are the wrong way round.

    Parameters
    ----------
    model : MarkerModel
    table : PairTable
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
    refs = model.references
    for s, pairs in table:
        markers, coords = model.segment_arrays[s]
        observed = points[markers]
        if np.isfinite(observed[:, 0]).sum() < 3:
            continue
        R, t, _ = rigid_fit(coords, observed[None])
        if not np.isfinite(R).all():
            continue
        for a, b in pairs:
            ra, rb = refs[a], refs[b]
            p, q = points[ra.marker], points[rb.marker]
            if not (np.isfinite(p).all() and np.isfinite(q).all()):
                continue
            local = (np.stack([p, q]) - t[0]) @ R[0]  # rows: R^T (x - t)
            u = local / np.linalg.norm(local, axis=1, keepdims=True)
            axes = np.stack([ra.direction, rb.direction])
            cos = np.clip(u @ axes.T, -1.0, 1.0)  # [point, axis]
            angle = np.degrees(np.arccos(cos))
            own = angle[0, 0] + angle[1, 1]
            exchanged = angle[1, 0] + angle[0, 1]
            if own - exchanged > max(ra.spread_deg, rb.spread_deg):
                found.append((ra.marker, rb.marker))
    count = np.bincount(np.array(found, dtype=np.intp).ravel(), minlength=len(model.labels))
    return [(m, n) for m, n in found if count[m] == 1 and count[n] == 1]
