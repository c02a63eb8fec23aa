"""The blobs of one frame of a video-centroid rig: unidentified image points per camera."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import ReconstructionError

__all__ = ["BlobFrame"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class BlobFrame:
    """Blob centroids of all cameras of one frame, stacked.

    Parameters
    ----------
    uv : array_like, shape (N, 2)
        Centroids in distorted pixel coordinates (px).
    camera : array_like of int, shape (N,)
        Camera index (rig order) of each blob.
    merged : array_like of bool, shape (N,), optional
        The camera flagged the blob as two or more markers run together; such a blob
        explains the markers near it but is not used to triangulate (its centroid is
        a mixture). Default: none merged.

    Raises
    ------
    ReconstructionError
        For arrays of the wrong shape, non-finite centroids or negative camera indices.
    """

    uv: FloatArray
    camera: NDArray[np.intp]
    merged: NDArray[np.bool_]

    def __init__(self, uv: Any, camera: Any, merged: Any = None) -> None:
        xy = np.asarray(uv, dtype=np.float64)
        if xy.size == 0:
            xy = xy.reshape(0, 2)
        if xy.ndim != 2 or xy.shape[1] != 2:
            raise ReconstructionError(f"blob uv must have shape (N, 2), got {xy.shape}")
        cam = np.asarray(camera).reshape(-1)
        if cam.shape != (xy.shape[0],) or (cam.size and cam.dtype.kind not in "iu"):
            raise ReconstructionError(f"camera must be {xy.shape[0]} integer camera indices")
        cam = cam.astype(np.intp)
        if cam.size and cam.min() < 0:
            raise ReconstructionError("camera indices must not be negative")
        if not np.isfinite(xy).all():
            raise ReconstructionError("blob centroids must be finite (leave missing blobs out)")
        flag = np.zeros(cam.size, bool) if merged is None else np.asarray(merged, bool).ravel()
        if flag.shape != cam.shape:
            raise ReconstructionError(f"merged must have shape ({cam.size},)")
        object.__setattr__(self, "uv", xy)
        object.__setattr__(self, "camera", cam)
        object.__setattr__(self, "merged", flag)

    def __len__(self) -> int:
        return int(self.camera.size)

    def counts(self, n_cameras: int) -> NDArray[np.intp]:
        """Blobs per camera, shape (n_cameras,); blobs of cameras beyond are an error."""
        if self.camera.size and int(self.camera.max()) >= n_cameras:
            raise ReconstructionError(
                f"blob of camera {int(self.camera.max())} but the calibration has "
                f"{n_cameras} cameras"
            )
        return np.bincount(self.camera, minlength=n_cameras)
