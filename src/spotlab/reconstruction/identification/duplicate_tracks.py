"""Two tracks on one marker: the one to delete.

A track whose prediction misses its marker's blobs in some cameras (a fast wrist at a
low frame rate, a new track that starts at rest) leaves those blobs free, and three of
them make a new point where the marker already has one. From then on the marker's blobs
are shared between two tracks, camera by camera, and nothing joins them again: two
points within a millimetre, which the cluster choice sees as two identities of equal
fit (no lead, so no label) and the labelling by links as two candidates (none taken).
Two passive markers' centres cannot come closer than their diameter, so two current
points closer than ``apart_mm`` are one marker. Where one of the two tracks is labelled,
the other is deleted: its blobs go to the labelled one from the next frame on, and the
copy can take no second label. Two unlabelled tracks are both kept: deleting one lets a
cold cluster choice take an identity the copies had left without a lead (measured on
``read_NOTworking2``, whose wrist clusters have near-symmetric identities:
``docs/identification.md``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["duplicate_tracks"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def duplicate_tracks(
    position: FloatArray,
    current: NDArray[np.bool_],
    label: IntArray,
    apart_mm: float,
) -> NDArray[np.bool_]:
    """Unlabelled tracks on the same marker as a labelled track.

    Of two current tracks closer than ``apart_mm``, one labelled and one not, the
    unlabelled one is deleted; two labelled tracks are both kept (the label checks judge
    them), and so are two unlabelled ones.

    Parameters
    ----------
    position : ndarray, shape (K, 3)
        Track positions (mm).
    current : ndarray of bool, shape (K,)
        Tracks measured in this frame (the others are not compared).
    label : ndarray of int, shape (K,)
        Marker of each track, -1 for none.
    apart_mm : float
        Points closer than this are one marker (mm): less than the smallest passive
        marker's diameter; 0 turns the rule off.

    Returns
    -------
    ndarray of bool, shape (K,)
        True for the tracks to delete.
    """
    drop = np.zeros(position.shape[0], dtype=bool)
    rows = np.flatnonzero(current)
    labelled = label[rows] >= 0
    if apart_mm <= 0 or labelled.all() or not labelled.any():
        return drop
    free, held = rows[~labelled], rows[labelled]
    d = np.linalg.norm(position[free][:, None] - position[held][None], axis=2)
    drop[free[(d < apart_mm).any(axis=1)]] = True
    return drop
