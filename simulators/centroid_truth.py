"""Ground truth of a simulated CEN hub, written as one npz file on close.

Fields (F frames taken, C cameras of the rig, M markers, N blobs sent):

* ``time_s`` (F,): scene time of each frame's exposure mid-point (hub trigger
  + half the exposure), s since the hub's power-up;
* ``markers_mm`` (F, M, 3): every marker at ``time_s``; ``labels`` (M,);
* ``frame_no``, ``stream``, ``hub_tick_us`` (F,); ``seq`` (F,): the frame's
  16-bit header seq, -1 if it was never sent; ``sent`` (F,) bool: it left the
  device whole (not dropped by the FIFO or a fault, not cut by a reset);
* ``camera_time_s`` (F, C): each camera's true exposure mid-point (scene s), NaN
  where it was offline or not enabled; ``camera_tick_us`` (F, C): what the
  camera stamped (its own clock), -1 there; ``camera_offset_s``,
  ``camera_drift_ppm`` (C,): the camera clocks;
* ``marker_seen`` (F, C, M) int8: 0 hidden (occluded, out of view, camera off),
  1 its own blob, 2 part of a merged blob;
* ``blob_offsets`` (F * C + 1,): blobs *as sent* (after the cap) of frame f and
  camera c are ``blob_offsets[f*C + c] : blob_offsets[f*C + c + 1]`` of
  ``blob_marker`` (N,) int32 (the marker imaged, the largest one of a merge; -1
  for ghosts, noise and sunlight), ``blob_kind`` (N,) int8 (0 marker, 1 merged,
  2 ghost reflection, 3 noise, 4 sunlight) and ``blob_uv_true`` (N, 2) float32
  (the centroid before noise, px), in the order of the wire — the order of
  :class:`~spotlab.drivers.centroid.BlobFrames` for a decoded frame of the same
  ``frame_no``; ``n_found`` (F, C): blobs the camera found (more than sent on
  overflow).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from spotlab.simulators.blobs import CameraBlobs
from spotlab.simulators.truth import TruthRow

if TYPE_CHECKING:
    from spotlab.simulators.centroid import CentroidDevice

CameraTruth = tuple[CameraBlobs, int, int, float] | None


@dataclass
class _FrameTruth:
    """One frame's truth, packed (all cameras of the rig)."""

    cam_time: npt.NDArray[np.float64]  # (C,)
    cam_tick: npt.NDArray[np.int64]  # (C,)
    n_found: npt.NDArray[np.int64]  # (C,)
    counts: npt.NDArray[np.int64]  # (C,) blobs sent
    seen: npt.NDArray[np.int8]  # (C, M)
    marker: npt.NDArray[np.int32]  # (n,)
    kind: npt.NDArray[np.int8]  # (n,)
    uv: npt.NDArray[np.float32]  # (n, 2)


class CentroidTruth:
    """Collects the truth of every frame taken and writes it (see the module docstring)."""

    def __init__(self, path: str | Path, device: CentroidDevice) -> None:
        self.path = Path(path)
        self.device = device
        self.rows: list[TruthRow] = []
        self.time_s: list[float] = []
        self.markers: list[npt.NDArray[np.float32]] = []
        self.frames: list[_FrameTruth] = []

    def add(
        self,
        row: TruthRow,
        time_s: float,
        markers: npt.NDArray[np.float64],
        cameras: list[int],
        per_camera: list[CameraTruth],
    ) -> None:
        """One frame taken: its truth row (seq and fate filled in later), markers, blobs."""
        c, m = len(self.device.rig.cameras), self.device.n_markers
        ft = _FrameTruth(
            np.full(c, np.nan), np.full(c, -1, np.int64), np.zeros(c, np.int64),
            np.zeros(c, np.int64), np.zeros((c, m), np.int8), np.zeros(0, np.int32),
            np.zeros(0, np.int8), np.zeros((0, 2), np.float32),
        )  # fmt: skip
        marker, kind, uv = [], [], []
        for cam, ct in zip(cameras, per_camera, strict=True):
            if ct is None:
                continue
            blobs, keep, tick, t_s = ct
            ft.cam_time[cam], ft.cam_tick[cam] = t_s, tick
            ft.n_found[cam], ft.counts[cam] = blobs.uv.shape[0], keep
            ft.seen[cam] = blobs.seen
            marker.append(blobs.marker[:keep])
            kind.append(blobs.kind[:keep])
            uv.append(blobs.true_uv[:keep])
        if marker:
            ft.marker = np.concatenate(marker).astype(np.int32)
            ft.kind = np.concatenate(kind).astype(np.int8)
            ft.uv = np.concatenate(uv).astype(np.float32)
        self.rows.append(row)
        self.time_s.append(time_s)
        self.markers.append(np.asarray(markers, dtype=np.float32))
        self.frames.append(ft)

    def arrays(self) -> dict[str, Any]:
        """The npz fields."""
        dev = self.device
        c, m = len(dev.rig.cameras), dev.n_markers
        fr = self.frames
        cat = np.concatenate
        counts = np.stack([f.counts for f in fr]) if fr else np.zeros((0, c), np.int64)
        return {
            "time_s": np.asarray(self.time_s),
            "markers_mm": (
                np.stack(self.markers).astype(np.float64) if self.markers else np.zeros((0, m, 3))
            ),
            "labels": np.asarray(dev.labels),
            "frame_no": np.array([r.frame_no for r in self.rows], dtype=np.int64),
            "stream": np.array([r.stream for r in self.rows], dtype=np.int64),
            "hub_tick_us": np.array([r.device_us for r in self.rows], dtype=np.int64),
            "seq": np.array([r.seq if r.sent is not False else -1 for r in self.rows], np.int64),
            "sent": np.array([bool(r.sent) for r in self.rows], dtype=bool),
            "camera_time_s": np.stack([f.cam_time for f in fr]) if fr else np.zeros((0, c)),
            "camera_tick_us": (
                np.stack([f.cam_tick for f in fr]) if fr else np.zeros((0, c), np.int64)
            ),
            "camera_offset_s": np.array([k.offset_s for k in dev.camera_clocks]),
            "camera_drift_ppm": np.array([k.drift_ppm for k in dev.camera_clocks]),
            "marker_seen": np.stack([f.seen for f in fr]) if fr else np.zeros((0, c, m), np.int8),
            "n_found": np.stack([f.n_found for f in fr]) if fr else np.zeros((0, c), np.int64),
            "blob_offsets": np.concatenate([[0], np.cumsum(counts.reshape(-1))]).astype(np.int64),
            "blob_marker": cat([f.marker for f in fr]) if fr else np.zeros(0, np.int32),
            "blob_kind": cat([f.kind for f in fr]) if fr else np.zeros(0, np.int8),
            "blob_uv_true": cat([f.uv for f in fr]) if fr else np.zeros((0, 2), np.float32),
        }

    def write(self) -> None:
        """Write the npz (atomically: a temporary file renamed)."""
        tmp = self.path.with_name(self.path.name + ".tmp.npz")
        np.savez(tmp, **self.arrays())
        tmp.replace(self.path)
