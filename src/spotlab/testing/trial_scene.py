"""Blob frames of a real labelled trial seen by a simulated camera rig, with its truth.

:func:`trial_scene` places the markers of a trial (a C3D or TRC file's trajectories)
in the capture volume of the reference ring rig (:func:`spotlab.simulators.rigs.ring_rig`)
and renders every camera's blobs with :func:`spotlab.simulators.blobs.render_camera`:
marker discs that merge, floor-reflection ghosts, noise blobs, Gaussian centroid noise.
There is no body to hide markers, so occlusion is drawn at random instead:

* ``occlusion``: the share of time a (camera, marker) pair is hidden, in episodes of
  5-60 frames (an arm or the other leg crossing the line of sight);
* ``dropouts``: episodes per marker and second in which a marker is hidden from every
  camera for 10-90 frames (a hand over it), as in ``benchmarks/identification.py``.

The trial is only moved, never reshaped: its vertical axis (the axis of the largest
spread of markers within a frame: the body is taller than it is wide or deep) becomes
z, its mean horizontal position the middle of the volume, its lowest marker 15 mm above
the floor. Distances between markers are the file's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spotlab.geometry import Rig
from spotlab.reconstruction.identification import BlobFrame
from spotlab.simulators.blobs import MERGED, OWN_BLOB, BlobModel, render_camera
from spotlab.simulators.rigs import ring_rig

__all__ = ["TrialScene", "place_in_volume", "trial_scene"]

FloatArray = NDArray[np.float64]

#: Height of the lowest marker of a placed trial above the floor (mm).
LOWEST_MM = 15.0


@dataclass(frozen=True)
class TrialScene:
    """Blob frames of a trial and the marker positions they image.

    Attributes
    ----------
    rig : Rig
        The simulated cameras (mm).
    frames : list of BlobFrame, length F
    labels : tuple of str, length M
    markers_mm : ndarray, shape (F, M, 3)
        Marker positions in the volume (mm), NaN where the file has none.
    own_blobs : ndarray of int, shape (F, M)
        Cameras that saw each marker as a blob of its own (not merged).
    """

    rig: Rig
    frames: list[BlobFrame]
    labels: tuple[str, ...]
    markers_mm: FloatArray
    own_blobs: NDArray[np.intp]

    def __len__(self) -> int:
        return len(self.frames)


def place_in_volume(points: FloatArray) -> FloatArray:
    """Move trajectories (F, M, 3) mm into the ring rig's volume (see the module notes).

    Returns
    -------
    ndarray, shape (F, M, 3)
        The same trajectories with axes cyclically permuted so that the vertical one is
        z, shifted to the middle of the volume and onto the floor (mm).
    """
    X = np.asarray(points, dtype=np.float64)
    present: NDArray[np.bool_] = np.asarray(np.isfinite(X).all(axis=2))
    seen = np.asarray(present.any(axis=1))
    if not seen.any():
        raise ValueError("no marker is seen in any frame")
    spread = np.nanmax(X[seen], axis=1) - np.nanmin(X[seen], axis=1)  # (F', 3)
    up = int(np.argmax(np.nanmedian(spread, axis=0)))
    X = np.roll(X, 2 - up, axis=2)  # cyclic: keeps the handedness
    centre = np.nanmean(X.reshape(-1, 3), axis=0)
    floor = np.nanmin(X[..., 2])
    return X - np.array([centre[0], centre[1], floor - LOWEST_MM])


def _episodes(
    rng: np.random.Generator, shape: tuple[int, ...], n: int, lengths: tuple[int, int]
) -> NDArray[np.bool_]:
    """(F, ...) True inside ``n`` random episodes of ``lengths`` frames of random cells."""
    F = shape[0]
    hidden = np.zeros(shape, dtype=bool)
    cells = int(np.prod(shape[1:]))
    flat = hidden.reshape(F, cells)
    for f, length, cell in zip(
        rng.integers(0, F, n), rng.integers(lengths[0], lengths[1] + 1, n),
        rng.integers(0, cells, n), strict=True,
    ):  # fmt: skip
        flat[f : f + length, cell] = True
    return hidden


def trial_scene(
    points: FloatArray,
    labels: tuple[str, ...] | list[str],
    rate_hz: float,
    *,
    cameras: int = 8,
    seed: int = 0,
    centroid_noise_px: float = 0.07,
    ghost_rate: float = 0.02,
    noise_blobs: float = 0.02,
    occlusion: float = 0.05,
    dropouts: float = 0.1,
    place: bool = True,
) -> TrialScene:
    """Render a trial's markers as the blobs of ``cameras`` ring cameras.

    Parameters
    ----------
    points : ndarray, shape (F, M, 3)
        Marker trajectories (mm), NaN where missing.
    labels : sequence of str, length M
    rate_hz : float
        Frame rate of the trial (Hz): sets the number of dropout episodes.
    cameras : int
        Cameras of the ring (the rig does not depend on ``seed``).
    seed : int
        Seed of noise, ghosts, occlusions and dropouts.
    centroid_noise_px, ghost_rate, noise_blobs : float
        As :class:`~spotlab.simulators.blobs.BlobModel`.
    occlusion : float
        Share of frames a (camera, marker) pair is hidden, in 5-60 frame episodes.
    dropouts : float
        Episodes per marker and second hiding it from every camera for 10-90 frames.
    place : bool
        Move the trial into the volume first (:func:`place_in_volume`).

    Returns
    -------
    TrialScene
    """
    X = place_in_volume(points) if place else np.asarray(points, dtype=np.float64)
    F, M = X.shape[:2]
    rig = ring_rig(cameras)
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x7121]))
    model = BlobModel(
        centroid_noise_px=centroid_noise_px, ghost_rate=ghost_rate, noise_blobs=noise_blobs
    )
    ghosts = rng.random((cameras, M)) < ghost_rate
    n_occ = rng.poisson(occlusion * F * cameras * M / 32.5) if occlusion > 0 else 0
    hidden_cam = _episodes(rng, (F, cameras, M), n_occ, (5, 60))
    n_drop = rng.poisson(dropouts * F / rate_hz * M) if dropouts > 0 else 0
    hidden_all = _episodes(rng, (F, M), n_drop, (10, 90))
    frames = []
    own = np.zeros((F, M), dtype=np.intp)
    for f in range(F):
        uv, cam, merged = [], [], []
        for c in range(cameras):
            b = render_camera(
                rig[c], X[f], model, rng, hidden=hidden_cam[f, c] | hidden_all[f], ghosts=ghosts[c]
            )
            uv.append(b.uv)
            cam.append(np.full(b.uv.shape[0], c))
            merged.append((b.flags & MERGED) != 0)
            own[f] += b.seen == OWN_BLOB
        frames.append(BlobFrame(np.concatenate(uv), np.concatenate(cam), np.concatenate(merged)))
    return TrialScene(rig, frames, tuple(labels), X, own)
