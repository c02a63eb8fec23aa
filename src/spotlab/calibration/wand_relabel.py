"""The ends of a 2-marker wand named again with a first calibration.

Two identical markers carry no name: :func:`~spotlab.calibration.wand_finder.find_wand`
takes the upper one in the image as end A and drops images where the wand lies level,
and a wand held level and pointing at a camera can still swap its ends between cameras.
A first calibration from those images places each frame's wand ends in space
(:attr:`WandCalibration.wand_ends`); :func:`relabel_two_ends` then projects the ends into
every image and names the blob nearest to each end's image when it lies within
``MATCH_PX`` of it, the two ends take different blobs, and every other blob is at
least ``SWAP_MARGIN`` times (and ``MATCH_PX``) farther. Level images come back this way,
swapped ones are put right, and images with a ghost or noise blob beside the wand are
used; a second calibration from the named ends follows.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from spotlab.calibration.wand_finder import MAX_BLOBS, WandImages, checked_blobs
from spotlab.core.errors import CalibrationError
from spotlab.geometry import Rig

__all__ = ["MATCH_PX", "SWAP_MARGIN", "relabel_two_ends"]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]

#: Largest distance (px) between a blob and the projection of the end it is named for.
MATCH_PX = 3.0
#: The other naming must be at least this many times worse.
SWAP_MARGIN = 3.0


def relabel_two_ends(
    uv: FloatArray,
    offsets: IntArray,
    rig: Rig,
    wand_ends: FloatArray,
    *,
    usable_blob: BoolArray | None = None,
    usable_image: BoolArray | None = None,
) -> WandImages:
    """Name the two blobs of every image by the wand ends of a first calibration.

    Parameters
    ----------
    uv : ndarray, shape (N, 2)
        Blob centroids (px) of all frames and cameras, flat.
    offsets : ndarray of int, shape (F * C + 1,)
        Blobs of frame ``f`` and camera ``c`` are ``uv[offsets[f*C + c]:offsets[f*C + c + 1]]``.
    rig : Rig
        The first calibration (C cameras).
    wand_ends : ndarray, shape (F, 2, 3)
        Ends A and B of each frame's wand from that calibration (mm), NaN where the frame
        was not used.
    usable_blob, usable_image : ndarray of bool, optional
        As for :func:`~spotlab.calibration.wand_finder.find_wand`.

    Returns
    -------
    WandImages
        ``used``: images named; ``ambiguous``: blobs that do not single out the ends (or
        a frame without ends in space, or more than ``MAX_BLOBS`` blobs); ``missing``:
        fewer than two blobs; ``unusable``: as the camera flagged.

    Raises
    ------
    CalibrationError
        When the arrays' sizes do not match the rig or each other.
    """
    C = len(rig)
    uv, offsets, C, F, blob_ok, image_ok = checked_blobs(uv, offsets, C, usable_blob, usable_image)
    wand_ends = np.asarray(wand_ends, dtype=np.float64)
    if wand_ends.shape != (F, 2, 3):
        raise CalibrationError(f"wand_ends must have shape ({F}, 2, 3), got {wand_ends.shape}")
    proj = rig.project(wand_ends.reshape(-1, 3)).reshape(C, F, 2, 2)
    ends = np.full((F, C, 2, 2), np.nan)
    counts = {k: np.zeros(C, np.int64) for k in ("used", "ambiguous", "missing", "unusable")}
    for f in range(F):
        for c in range(C):
            if not image_ok[f, c]:
                counts["unusable"][c] += 1
                continue
            lo, hi = int(offsets[f * C + c]), int(offsets[f * C + c + 1])
            pts = uv[lo:hi][blob_ok[lo:hi]]
            if pts.shape[0] < 2:
                counts["missing"][c] += 1
                continue
            if pts.shape[0] > MAX_BLOBS or not np.isfinite(proj[c, f]).all():
                counts["ambiguous"][c] += 1  # too many blobs, or no wand in space
                continue
            d = np.linalg.norm(pts[None, :, :] - proj[c, f][:, None, :], axis=2)  # (2, n)
            near = np.argmin(d, axis=1)
            first = d[[0, 1], near]
            second = np.sort(d, axis=1)[:, 1]
            if (
                near[0] == near[1]
                or first.max() > MATCH_PX
                or (second < np.maximum(SWAP_MARGIN * first, MATCH_PX)).any()
            ):
                counts["ambiguous"][c] += 1
                continue
            counts["used"][c] += 1
            ends[f, c] = pts[near]
    return WandImages(ends, np.full((F, C, 2), np.nan), **counts)
