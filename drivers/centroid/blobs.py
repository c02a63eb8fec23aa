"""Blob frames of a ``blobs2d`` stream in a compact ragged form (offsets + flat arrays).

:func:`blobs_from_blocks` joins decoded :class:`FrameBlock` objects (whose blob
axis varies from block to block) into one :class:`BlobFrames`: per frame and
camera, the hub and camera timing, and the blobs as slices of flat arrays.
Blob ``i`` of camera ``c`` in frame ``f`` is flat index
``offsets[f * C + c] + i``, in the order the camera sent them (the order of
the simulator's truth ``blob_marker``).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from spotlab.core.errors import ConfigurationError
from spotlab.core.frames import FrameBlock
from spotlab.drivers.centroid.protocol import BLOB_USED, CAM_OFFLINE, CAM_OVERFLOW, RECORD_PRESENT

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
U8 = npt.NDArray[np.uint8]


@dataclass(frozen=True)
class BlobFrames:
    """Blobs of F frames and C cameras.

    Attributes
    ----------
    seq : ndarray of int64, shape (F,)
        Unwrapped sequence numbers.
    ticks : ndarray of int64, shape (F,)
        Hub tick (µs) at each frame's trigger.
    arrival_ns : ndarray of int64, shape (F,)
        Host arrival times.
    camera_frame : ndarray of int64, shape (F, C)
        Each camera's frame counter (-1 where the camera is not enabled).
    exposure_us : ndarray of float64, shape (F, C)
        Each camera's own clock at the exposure mid-point (µs); NaN where the
        camera is offline or not enabled.
    camera_flags : ndarray of uint8, shape (F, C)
        ``CAM_OVERFLOW`` (0x01), ``CAM_OFFLINE`` (0x02); ``RECORD_PRESENT`` (0x80)
        for an enabled camera.
    n_found : ndarray of int64, shape (F, C)
        Blobs each camera found (more than it sent when it overflowed).
    offsets : ndarray of int64, shape (F * C + 1,)
        Start of each (frame, camera) in the flat arrays, row-major.
    uv : ndarray of float64, shape (N, 2)
        Blob centroids (x, y) in px.
    area : ndarray of float64, shape (N,)
        Pixels above threshold.
    peak : ndarray of float64, shape (N,)
        Brightest pixel (grey level).
    flags : ndarray of uint8, shape (N,)
        ``BLOB_SATURATED`` (0x01), ``BLOB_EDGE`` (0x02), ``BLOB_MERGED`` (0x04).
    """

    seq: I64
    ticks: I64
    arrival_ns: I64
    camera_frame: I64
    exposure_us: F64
    camera_flags: U8
    n_found: I64
    offsets: I64
    uv: F64
    area: F64
    peak: F64
    flags: U8

    @property
    def n_frames(self) -> int:
        """F."""
        return int(self.seq.shape[0])

    @property
    def n_cameras(self) -> int:
        """C."""
        return int(self.camera_frame.shape[1])

    @property
    def counts(self) -> I64:
        """Blobs per frame and camera, shape (F, C)."""
        return np.diff(self.offsets).reshape(self.n_frames, self.n_cameras)

    @property
    def offline(self) -> npt.NDArray[np.bool_]:
        """Cameras that delivered no frame, shape (F, C)."""
        return (self.camera_flags & CAM_OFFLINE) != 0

    @property
    def overflow(self) -> npt.NDArray[np.bool_]:
        """Cameras that found more blobs than they sent, shape (F, C)."""
        return (self.camera_flags & CAM_OVERFLOW) != 0

    def slice(self, frame: int, camera: int) -> slice:
        """The flat-array slice of one frame and camera."""
        k = frame * self.n_cameras + camera
        return slice(int(self.offsets[k]), int(self.offsets[k + 1]))

    def frame(self, frame: int) -> list[F64]:
        """Blob centroids of one frame: one (n_c, 2) array in px per camera."""
        return [self.uv[self.slice(frame, c)] for c in range(self.n_cameras)]


def blobs_from_blocks(blocks: Iterable[FrameBlock]) -> BlobFrames:
    """Join decoded ``blobs2d`` blocks into one :class:`BlobFrames`.

    Parameters
    ----------
    blocks : iterable of FrameBlock
        Blocks of one CEN stream (layout in :mod:`spotlab.drivers.centroid.protocol`).

    Raises
    ------
    ConfigurationError
        If the blocks are not of one ``blobs2d`` stream (camera columns or values differ).
    """
    blocks = [b for b in blocks if len(b)]
    shapes = {(b.data.shape[2], b.data.shape[3]) for b in blocks}
    if len(shapes) > 1 or any(s[1] != 4 for s in shapes):
        raise ConfigurationError(f"blocks of one blobs2d stream are needed, got shapes {shapes}")
    c = next(iter(shapes))[0] if shapes else 0
    parts: list[tuple[F64, U8]] = []
    counts = []
    for b in blocks:
        used = (b.flags[:, 1:, :] & BLOB_USED) != 0  # (F, B, C)
        order = np.transpose(used, (0, 2, 1))  # (F, C, B): frame, camera, blob
        vals = np.transpose(b.data[:, 1:, :, :], (0, 2, 1, 3))[order]
        fl = np.transpose(b.flags[:, 1:, :], (0, 2, 1))[order]
        parts.append((vals, fl))
        counts.append(order.sum(axis=2).reshape(-1))
    flat = np.concatenate([p[0] for p in parts]) if parts else np.zeros((0, 4))
    cat = np.concatenate
    cam = [b.data[:, 0] for b in blocks]
    cam_flags = cat([b.flags[:, 0] for b in blocks]) if blocks else np.zeros((0, c), np.uint8)
    present = (cam_flags & RECORD_PRESENT) != 0
    cam_vals = cat(cam) if cam else np.zeros((0, c, 4))
    n_counts = cat(counts) if counts else np.zeros(0, np.int64)
    return BlobFrames(
        seq=cat([b.seq for b in blocks]) if blocks else np.zeros(0, np.int64),
        ticks=cat([b.ticks for b in blocks]) if blocks else np.zeros(0, np.int64),
        arrival_ns=cat([b.arrival_ns for b in blocks]) if blocks else np.zeros(0, np.int64),
        camera_frame=np.where(present, np.nan_to_num(cam_vals[..., 1], nan=-1), -1).astype(
            np.int64
        ),
        exposure_us=np.where(present, cam_vals[..., 0], np.nan),
        camera_flags=cam_flags.astype(np.uint8),
        n_found=np.where(present, np.nan_to_num(cam_vals[..., 2]), 0).astype(np.int64),
        offsets=np.concatenate([[0], np.cumsum(n_counts)]).astype(np.int64),
        uv=flat[:, :2].copy(),
        area=flat[:, 2].copy(),
        peak=flat[:, 3].copy(),
        flags=np.bitwise_and(
            cat([p[1] for p in parts]) if parts else np.zeros(0, np.uint8), 0x7F, dtype=np.uint8
        ),
    )
