"""A static trial's blobs -> the subject's unlabelled markers (one point each).

Each frame's blobs are undistorted (:meth:`RigGeometry.normalize`) and matched into
3-D points by the epipolar constraint (:func:`.match_blobs`, merged blobs left out);
points below the floor are reflections and are dropped. The points of all frames are
then clustered: each frame's points are assigned to the running means of the clusters
so far (Hungarian, within ``radius_mm``), points left over start new clusters. A
standing subject sways a few mm, so each marker makes one cluster; a cluster seen in
fewer than ``min_seen`` of the frames (a ghost, a marker seen now and then) is left
out. A cluster whose points spread farther than ``max_spread_mm`` from its median means
the subject moved: the trial is refused as not static.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from spotlab.core.errors import ReconstructionError
from spotlab.reconstruction.identification.blobs import BlobFrame
from spotlab.reconstruction.identification.correspondence import match_blobs
from spotlab.reconstruction.identification.geometry import RigGeometry

__all__ = ["StaticCloud", "static_cloud"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class StaticCloud:
    """The markers of a static trial, unlabelled.

    Attributes
    ----------
    points : ndarray, shape (K, 3)
        Median position of each kept cluster (mm).
    seen : ndarray, shape (K,)
        Fraction of the frames in which each was found.
    spread_mm : ndarray, shape (K,)
        Largest distance of a cluster's points from its median (mm).
    frames : int
        Frames used.
    dropped : int
        Clusters left out (seen in too few frames).
    reflections : int
        Points dropped below the floor, over all frames.
    """

    points: FloatArray
    seen: FloatArray
    spread_mm: FloatArray
    frames: int
    dropped: int
    reflections: int


def static_cloud(
    frames: Sequence[BlobFrame],
    geom: RigGeometry,
    *,
    floor_mm: float | None = 0.0,
    radius_mm: float = 12.0,
    min_seen: float = 0.6,
    max_spread_mm: float = 30.0,
    epipolar_px: float = 1.5,
    min_cameras: int = 3,
    max_frames: int = 60,
) -> StaticCloud:
    """The subject's markers in a static trial (see the module docstring).

    Parameters
    ----------
    frames : sequence of BlobFrame
        Blobs of each frame, camera indices in the rig's order.
    geom : RigGeometry
        The calibrated rig.
    floor_mm : float or None
        Points below this height are reflections; None keeps them.
    radius_mm : float
        Largest distance of a point from its cluster's running mean (mm).
    min_seen : float
        Fraction of the frames a cluster must be found in to be kept.
    max_spread_mm : float
        Largest spread of a kept cluster (mm); beyond, the trial is not static.
    epipolar_px, min_cameras :
        As :func:`.match_blobs` (``gate_px``, ``min_cameras``).
    max_frames : int
        At most this many frames are used, evenly spread over the trial (matching blobs
        without a model costs some 0.05 s a frame).

    Returns
    -------
    StaticCloud

    Raises
    ------
    ReconstructionError
        For no frames, no marker seen in most frames, or a subject that moved.
    """
    sums: list[FloatArray] = []  # per cluster: running sum of its points
    members: list[list[FloatArray]] = []
    n_frames = reflections = 0
    pick = np.unique(np.linspace(0, len(frames) - 1, min(len(frames), max_frames)).round())
    for f in pick.astype(int):
        frame = frames[f]
        n_frames += 1
        xy, ok = geom.normalize(frame.uv, frame.camera)
        use = ok & ~frame.merged
        pts = match_blobs(
            geom, xy[use], frame.camera[use], gate_px=epipolar_px, min_cameras=min_cameras
        ).points
        if floor_mm is not None:
            below = pts[:, 2] < floor_mm
            reflections += int(below.sum())
            pts = pts[~below]
        taken = np.zeros(pts.shape[0], dtype=bool)
        if sums and pts.shape[0]:
            means = np.stack([s / len(m) for s, m in zip(sums, members, strict=True)])
            d = np.linalg.norm(pts[:, None, :] - means[None], axis=2)
            rows, cols = linear_sum_assignment(np.minimum(d, 10 * radius_mm))
            for r, c in zip(rows, cols, strict=True):
                if d[r, c] < radius_mm:
                    sums[c] = sums[c] + pts[r]
                    members[c].append(pts[r])
                    taken[r] = True
        for p in pts[~taken]:
            sums.append(p.copy())
            members.append([p])
    if n_frames == 0:
        raise ReconstructionError("the static trial has no frames")
    count = np.array([len(m) for m in members], dtype=np.float64)
    keep = np.flatnonzero(count >= min_seen * n_frames)
    if keep.size < 3:
        raise ReconstructionError(
            f"the trial is not static: {keep.size} points stay in place in {min_seen:.0%} of "
            f"the {n_frames} frames, need 3 or more (the subject moved, or the calibration "
            "is another rig's)"
        )
    points = np.stack([np.median(np.stack(members[k]), axis=0) for k in keep])
    spread = np.array(
        [np.linalg.norm(np.stack(members[k]) - points[i], axis=1).max() for i, k in enumerate(keep)]
    )
    # A moving marker makes a trail of clusters, each seen in few frames: a static
    # trial's points are (almost) all in the kept clusters.
    in_kept = float(count[keep].sum() / max(count.sum(), 1.0))
    if float(np.median(spread)) > max_spread_mm or in_kept < 0.5:
        raise ReconstructionError(
            f"the trial is not static: its markers spread {np.median(spread):.0f} mm "
            f"(median; at most {max_spread_mm:g}) and {in_kept:.0%} of the points stay in "
            "place; record the subject standing still"
        )
    return StaticCloud(
        points=points, seen=count[keep] / n_frames, spread_mm=spread, frames=n_frames,
        dropped=int(count.size - keep.size), reflections=reflections,
    )  # fmt: skip
