"""Points two cameras alone see whose rays may belong to other markers.

Two rays always come close somewhere: a blob of one marker in one camera and a blob of
another marker in a second camera can cross within the ray error and make a point where
no marker is (``bmc/Gait.c3d`` seed 2: the ankle's blob in one camera and the other
ankle marker's in another, a point 51 mm beside the hidden heel, that the heel's links
took). A third camera refutes such a point; with two, what gives it away is a blob that
another point of the frame explains as well: it lies on that point's projection. Such a
point may be a marker still, but it is no evidence for a label by distance ranges alone,
nor for one tracking carried onto it: the identifier drops that label, to be earned again
(``read_NOTworking2``'s wrist labels carried onto points 19-109 mm from any marker).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from spotlab.reconstruction.identification.geometry import RigGeometry

__all__ = ["crossed_rays"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def crossed_rays(
    geom: RigGeometry,
    position: FloatArray,
    current: NDArray[np.bool_],
    index: IntArray,
    kept: NDArray[np.bool_],
    xy: FloatArray,
    gate_px: float,
    apart_mm: float,
) -> NDArray[np.bool_]:
    """Points measured by two cameras one of whose blobs another point explains.

    Parameters
    ----------
    geom : RigGeometry
    position : ndarray, shape (K, 3)
        The points (mm) of this frame's tracks.
    current : ndarray of bool, shape (K,)
        Points measured in this frame (not reflections): those that may explain a blob.
    index : ndarray of int, shape (C, K)
        Blob of each point in each camera (:func:`.associate`), -1 for none.
    kept : ndarray of bool, shape (C, K)
        Rays kept by the triangulation.
    xy : ndarray, shape (N, 2)
        Normalised blob coordinates.
    gate_px : float
        A blob within this distance (undistorted px) of another point's projection is
        explained by it.
    apart_mm : float
        Points nearer each other than this (mm) are one marker's (two tracks of it).

    Returns
    -------
    ndarray of bool, shape (K,)
        True for a point of two kept rays, one of whose blobs lies within ``gate_px`` of
        the projection of another current point more than ``apart_mm`` from it (not a
        second track of the same marker).
    """
    K = position.shape[0]
    out = np.zeros(K, dtype=bool)
    two = np.flatnonzero(current & (kept.sum(axis=0) == 2))
    others = np.flatnonzero(current)
    if two.size == 0 or others.size < 2:
        return out
    proj = geom.project(position[others])  # (C, J, 2)
    for k in two:
        apart = np.linalg.norm(position[others] - position[k], axis=1) > apart_mm  # (J,)
        for c in np.flatnonzero(kept[:, k]):
            d = np.linalg.norm(proj[c, apart] - xy[index[c, k]], axis=1) * geom.f[c]
            if np.any(d < gate_px):
                out[k] = True
                break
    return out
