"""Which side of a candidate identity's triangle its references stand on.

A flat cluster's candidate identities are checked against the cones of its references
(:func:`.handedness.wrong_way_round`) when they are chosen, and its labels against the
sides of its references (:func:`.handedness.misplaced_segments`) every frame after.
The cone test is blind where a reference lies near the cluster's axis of symmetry: the
mirror identity of a triangle with two sides alike (the two alike markers exchanged) is
fitted by a half turn about that axis, which moves a direction at an angle ``a`` to it
by ``2 a`` only, within the cone's margin for ``a`` up to some 15°. Exchanging two
markers always turns the triangle's normal over, so the side test sees it; an identity
that test would drop in the next frame is not taken (:func:`turned_over`).
``Sample_Jump2.c3d``'s head band (``THEA``, ``FHEA``, ``RHEA``: sides 131 and 129 mm
from ``THEA``) and its references (the knees below the head, near that axis) are where
this was found (docs/identification.md).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from spotlab.reconstruction.identification.handedness import SIDE_NOISE_MM, Reference

__all__ = ["turned_over"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def turned_over(
    markers: IntArray,
    refs: list[Reference],
    points: FloatArray,
    rows: IntArray,
    ref_rows: IntArray,
) -> NDArray[np.bool_]:
    """Candidate identities of one cluster on whose triangle more labelled references
    stand on the wrong side than on their own, as
    :func:`.handedness.misplaced_segments` judges labels (more than
    :data:`.handedness.SIDE_NOISE_MM` off the plane).

    Parameters
    ----------
    markers : ndarray of int, shape (P,)
        The cluster's markers (indices into the model's labels).
    refs : list of Reference
        The cluster's references (those without a side, or without a triangle, say
        nothing).
    points : ndarray, shape (K, 3)
        Points of the frame (mm).
    rows : ndarray of int, shape (n, P)
        Candidate point of each marker (-1: missing).
    ref_rows : ndarray of int, shape (len(refs),)
        Point labelled as each reference marker, -1 where unlabelled.

    Returns
    -------
    ndarray of bool, shape (n,)
        True for the identities to leave out.
    """
    n = rows.shape[0]
    wrong = np.zeros(n, dtype=np.intp)
    right = np.zeros(n, dtype=np.intp)
    slot = {int(m): p for p, m in enumerate(markers)}
    for ref, k in zip(refs, ref_rows, strict=True):
        if ref.side == 0 or len(ref.triple) != 3 or k < 0:
            continue
        corners = rows[:, [slot[int(m)] for m in ref.triple]]  # (n, 3)
        have = (corners >= 0).all(axis=1)
        q = points[np.maximum(corners, 0)]  # (n, 3, 3)
        normal = np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0])
        along = np.einsum("ij,ij->i", normal, points[k] - q[:, 0]) * ref.side
        far = have & (along * along > SIDE_NOISE_MM**2 * np.einsum("ij,ij->i", normal, normal))
        wrong += far & (along < 0.0)
        right += far & (along > 0.0)
    return np.asarray(wrong > right)
