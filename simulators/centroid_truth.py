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

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from spotlab.simulators.blobs import CameraBlobs
from spotlab.simulators.truth import TruthRow

if TYPE_CHECKING:
    from spotlab.simulators.centroid import CentroidDevice

CameraTruth = tuple[CameraBlobs, int, int, float] | None


class CentroidTruth:
    """Collects the truth of every frame taken and writes it (see the module docstring)."""

    def __init__(self, path: str | Path, device: CentroidDevice) -> None:
        self.path = Path(path)
        self.device = device
        self.rows: list[TruthRow] = []
        self.time_s: list[float] = []
        self.markers: list[npt.NDArray[np.float64]] = []
        self.cams: list[list[tuple[int, CameraTruth]]] = []

    def add(
        self,
        row: TruthRow,
        time_s: float,
        markers: npt.NDArray[np.float64],
        cameras: list[int],
        per_camera: list[CameraTruth],
    ) -> None:
        """One frame taken: its truth row (seq and fate filled in later), markers, blobs."""
        self.rows.append(row)
        self.time_s.append(time_s)
        self.markers.append(np.asarray(markers, dtype=np.float64))
        self.cams.append(list(zip(cameras, per_camera, strict=True)))

    def arrays(self) -> dict[str, Any]:
        """The npz fields."""
        dev = self.device
        f, c, m = len(self.rows), len(dev.rig.cameras), dev.n_markers
        cam_time = np.full((f, c), np.nan)
        cam_tick = np.full((f, c), -1, dtype=np.int64)
        n_found = np.zeros((f, c), dtype=np.int64)
        seen = np.zeros((f, c, m), dtype=np.int8)
        counts = np.zeros((f, c), dtype=np.int64)
        marker, kind, uv = [], [], []
        for k, cams in enumerate(self.cams):
            for cam, ct in cams:
                if ct is None:
                    continue
                blobs, keep, tick, t_s = ct
                cam_time[k, cam], cam_tick[k, cam] = t_s, tick
                n_found[k, cam] = blobs.uv.shape[0]
                seen[k, cam] = blobs.seen
                counts[k, cam] = keep
                marker.append(blobs.marker[:keep])
                kind.append(blobs.kind[:keep])
                uv.append(blobs.true_uv[:keep])
        cat = np.concatenate
        return {
            "time_s": np.asarray(self.time_s),
            "markers_mm": np.stack(self.markers) if self.markers else np.zeros((0, m, 3)),
            "labels": np.asarray(dev.labels),
            "frame_no": np.array([r.frame_no for r in self.rows], dtype=np.int64),
            "stream": np.array([r.stream for r in self.rows], dtype=np.int64),
            "hub_tick_us": np.array([r.device_us for r in self.rows], dtype=np.int64),
            "seq": np.array([r.seq if r.sent is not False else -1 for r in self.rows], np.int64),
            "sent": np.array([bool(r.sent) for r in self.rows], dtype=bool),
            "camera_time_s": cam_time,
            "camera_tick_us": cam_tick,
            "camera_offset_s": np.array([k.offset_s for k in dev.camera_clocks]),
            "camera_drift_ppm": np.array([k.drift_ppm for k in dev.camera_clocks]),
            "marker_seen": seen,
            "n_found": n_found,
            "blob_offsets": np.concatenate([[0], np.cumsum(counts.reshape(-1))]).astype(np.int64),
            "blob_marker": cat(marker).astype(np.int32) if marker else np.zeros(0, np.int32),
            "blob_kind": cat(kind).astype(np.int8) if kind else np.zeros(0, np.int8),
            "blob_uv_true": cat(uv).astype(np.float32) if uv else np.zeros((0, 2), np.float32),
        }

    def write(self) -> None:
        """Write the npz (atomically: a temporary file renamed)."""
        tmp = self.path.with_name(self.path.name + ".tmp.npz")
        np.savez_compressed(tmp, **self.arrays())
        tmp.replace(self.path)
