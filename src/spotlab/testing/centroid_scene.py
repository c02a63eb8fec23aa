"""Blob frames of the simulated CEN video-centroid hub, in process, with their truth.

:func:`centroid_scene` powers up a :class:`~spotlab.simulators.centroid.CentroidDevice`
(the 40-marker walking body of :mod:`spotlab.simulators.centroid_body` before the
reference ring rig: body-segment occlusion, merges, floor-reflection ghosts, noise blobs),
starts it and takes its output bytes frame period by frame period on the device's own
time axis (no pty, no pacing), decodes them with the host driver's
:class:`~spotlab.drivers.centroid.CentroidDecoder` and joins them into
:class:`~spotlab.drivers.centroid.BlobFrames`: the blobs exactly as a recording of the
device holds them (quantised on the wire, in the cameras' scan order). The device's
truth (:mod:`spotlab.simulators.centroid_truth`) names the origin of every blob sent,
so identification can be scored.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.drivers.centroid import (
    BLOB_MERGED,
    BlobFrames,
    CentroidConfig,
    CentroidDecoder,
    blobs_from_blocks,
)
from spotlab.geometry import Rig
from spotlab.reconstruction.identification import BlobFrame
from spotlab.simulators import wire
from spotlab.simulators.blobs import KIND_MARKER
from spotlab.simulators.centroid_service import CentroidSimOptions, build_centroid_device

__all__ = ["CentroidScene", "centroid_scene"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class CentroidScene:
    """Decoded blob frames of a simulated hub and the truth of each frame.

    Attributes
    ----------
    rig : Rig
        The simulated cameras' true calibration (mm).
    blobs : BlobFrames
        What the host decoded (F frames, C cameras).
    labels : tuple of str, length M
    markers_mm : ndarray, shape (F, M, 3)
        True marker positions at each frame's exposure mid-point (mm).
    blob_marker : ndarray of int, shape (N,)
        Marker imaged by each blob of ``blobs`` (the largest one of a merge), -1 for
        ghosts, noise and sunlight.
    blob_kind : ndarray of int8, shape (N,)
        0 marker, 1 merged, 2 ghost reflection, 3 noise, 4 sunlight.
    """

    rig: Rig
    blobs: BlobFrames
    labels: tuple[str, ...]
    markers_mm: FloatArray
    blob_marker: NDArray[np.intp]
    blob_kind: NDArray[np.int8]

    def __len__(self) -> int:
        return self.blobs.n_frames

    def frame(self, f: int) -> BlobFrame:
        """The blobs of frame ``f``, as an Identifier takes them."""
        b = self.blobs
        C = b.n_cameras
        lo, hi = int(b.offsets[f * C]), int(b.offsets[(f + 1) * C])
        camera = np.repeat(np.arange(C), b.counts[f])
        return BlobFrame(b.uv[lo:hi], camera, (b.flags[lo:hi] & BLOB_MERGED) != 0)

    def unusable(self, f: int) -> NDArray[np.bool_]:
        """Cameras (C,) the hub flagged offline or overflowing in frame ``f``."""
        return np.asarray(self.blobs.offline[f] | self.blobs.overflow[f])

    def hidden(self, hidden: NDArray[np.bool_]) -> CentroidScene:
        """The scene with markers hidden from every camera where ``hidden`` (F, M) is True
        (a hand over a marker): their blobs, merged ones included, are left out."""
        b = self.blobs
        F, C = b.n_frames, b.n_cameras
        if hidden.shape != (F, len(self.labels)):
            raise ValueError(f"hidden must have shape ({F}, {len(self.labels)})")
        cell = np.searchsorted(b.offsets, np.arange(b.uv.shape[0]), side="right") - 1
        marker = np.maximum(self.blob_marker, 0)
        keep = (self.blob_marker < 0) | ~hidden[cell // C, marker]
        counts = np.bincount(cell[keep], minlength=F * C)
        blobs = BlobFrames(
            seq=b.seq, ticks=b.ticks, arrival_ns=b.arrival_ns, camera_frame=b.camera_frame,
            exposure_us=b.exposure_us, camera_flags=b.camera_flags, n_found=b.n_found,
            offsets=np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
            uv=b.uv[keep], area=b.area[keep], peak=b.peak[keep], flags=b.flags[keep],
        )  # fmt: skip
        return CentroidScene(
            self.rig, blobs, self.labels, self.markers_mm, self.blob_marker[keep],
            self.blob_kind[keep],
        )  # fmt: skip

    def oracle_uv(self) -> FloatArray:
        """Each marker's own unmerged blob, shape (C, F, M, 2) px, NaN where it has none.

        The rays of correctly matched blobs: triangulating them gives the reference
        3-D accuracy of identification.
        """
        b = self.blobs
        F, C, M = b.n_frames, b.n_cameras, len(self.labels)
        out = np.full((C, F, M, 2), np.nan)
        own = np.flatnonzero((self.blob_kind == KIND_MARKER) & (self.blob_marker >= 0))
        cell = np.searchsorted(b.offsets, own, side="right") - 1  # f * C + c
        out[cell % C, cell // C, self.blob_marker[own]] = b.uv[own]
        return out


def centroid_scene(
    seconds: float, rate_hz: float = 300.0, *, seed: int = 0, **options: Any
) -> CentroidScene:
    """Run a simulated CEN hub for ``seconds`` at ``rate_hz`` and decode what it sent.

    Parameters
    ----------
    seconds : float
        Duration (s).
    rate_hz : float
        Frame rate (Hz).
    seed : int
        Seed of the simulator (noise, ghosts, clocks).
    **options
        Further :class:`~spotlab.simulators.centroid_service.CentroidSimOptions`
        (``cameras``, ``markers``, ``ghost_rate``, ``noise_blobs``, ``sunlight``,
        ``camera_off``, ``occlusion``, ...).

    Returns
    -------
    CentroidScene

    Raises
    ------
    ValueError
        For bad simulator options, or frames lost on the way (the blobs could not be
        matched to the truth).
    """
    with tempfile.TemporaryDirectory() as tmp:
        sim = CentroidSimOptions(
            rate_hz=rate_hz, seed=seed, truth=Path(tmp) / "truth.npz", **options
        )
        dev = build_centroid_device(sim, now_ns=0)
    if dev.truth is None:  # pragma: no cover - the truth path was given
        raise ValueError("the simulator keeps no truth")
    t = 1_000_000_000
    dev.receive(wire.command("COMM:11"), t)
    t += 50_000_000
    dev.output(t)
    dev.receive(wire.command("START:"), t, line_baud=12_000_000)
    config = CentroidConfig.create(cameras=sim.cameras, rate_hz=rate_hz)
    decoder = CentroidDecoder(config)
    period = 1e9 / rate_hz
    n_frames = round(seconds * rate_hz)
    blocks = []
    k = 0
    while decoder.stats.frames < n_frames and k < n_frames + 100:
        k += 1
        now = t + round(k * period)
        blocks.append(decoder.feed(dev.output(now), now))
    blobs = blobs_from_blocks(blocks)
    truth = dev.truth.arrays()
    F = min(blobs.n_frames, n_frames)
    C = blobs.n_cameras
    sent = np.asarray(truth["blob_offsets"])
    if F < n_frames or not np.array_equal(np.diff(sent[: F * C + 1]), blobs.counts[:F].ravel()):
        raise ValueError("frames were lost between the simulator and the decoder")
    n = int(sent[F * C])
    return CentroidScene(
        rig=dev.rig,
        blobs=_first_frames(blobs, F),
        labels=tuple(str(x) for x in truth["labels"]),
        markers_mm=np.asarray(truth["markers_mm"][:F], dtype=np.float64),
        blob_marker=np.asarray(truth["blob_marker"][:n], dtype=np.intp),
        blob_kind=np.asarray(truth["blob_kind"][:n], dtype=np.int8),
    )


def _first_frames(b: BlobFrames, F: int) -> BlobFrames:
    """The first ``F`` frames of ``b``."""
    C = b.n_cameras
    n = int(b.offsets[F * C])
    return BlobFrames(
        seq=b.seq[:F], ticks=b.ticks[:F], arrival_ns=b.arrival_ns[:F],
        camera_frame=b.camera_frame[:F], exposure_us=b.exposure_us[:F],
        camera_flags=b.camera_flags[:F], n_found=b.n_found[:F], offsets=b.offsets[: F * C + 1],
        uv=b.uv[:n], area=b.area[:n], peak=b.peak[:n], flags=b.flags[:n],
    )  # fmt: skip
