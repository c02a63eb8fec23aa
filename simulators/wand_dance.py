"""Synthetic wand-dance calibration data: a wand waved through a rig, a floor frame,
and body markers, with the truth.

This is the reference scene of ``design/TARGETS.md`` (a 500 mm wand waved for 3000
frames, a floor L-frame, 20 body markers, 0.2 px image noise). Held-out wand frames and
body-marker frames are drawn independently of the calibration frames so that a
calibration can be scored on data it never saw.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spotlab.geometry import Rig

__all__ = ["FRAME_POINTS", "WandDance", "wand_dance"]

FloatArray = NDArray[np.float64]

#: Known marker positions (mm) of the static reference objects. The L-frame lies on the
#: floor with three markers on its x arm and three on its y arm (origin shared), so the
#: ratios along each arm are known; the triad adds a vertical arm.
FRAME_POINTS: dict[str, FloatArray] = {
    "L": np.array(
        [
            [0.0, 0.0, 0.0],
            [300.0, 0.0, 0.0],
            [800.0, 0.0, 0.0],
            [0.0, 200.0, 0.0],
            [0.0, 500.0, 0.0],
        ]
    ),
    "triad": np.array(
        [
            [0.0, 0.0, 0.0],
            [300.0, 0.0, 0.0],
            [800.0, 0.0, 0.0],
            [0.0, 200.0, 0.0],
            [0.0, 500.0, 0.0],
            [0.0, 0.0, 250.0],
            [0.0, 0.0, 600.0],
        ]
    ),
}


@dataclass(frozen=True)
class WandDance:
    """Observations and truth of one simulated wand calibration.

    Attributes
    ----------
    rig : Rig
        The true cameras.
    wand : ndarray, shape (F, C, 2, 2)
        Observed pixel coordinates of both wand ends, NaN where unseen.
    wand_true : ndarray, shape (F, 2, 3)
        True wand ends (mm).
    wand_length : float
        Wand length (mm).
    frame : ndarray, shape (C, P, 2)
        Observed pixel coordinates of the static frame's markers (averaged over
        ``frame_samples`` noisy samples, as a static recording is), NaN where unseen.
    frame_points : ndarray, shape (P, 3)
        Known world coordinates of the frame's markers (mm).
    held_out_wand, held_out_true : ndarray, shapes (H, C, 2, 2) and (H, 2, 3)
        Independent wand frames for scoring.
    body, body_true : ndarray, shapes (B, C, M, 2) and (B, M, 3)
        Body-marker observations and truth for scoring 3-D error.
    noise_px : float
        Standard deviation of the image noise per coordinate (px).
    """

    rig: Rig
    wand: FloatArray
    wand_true: FloatArray
    wand_length: float
    frame: FloatArray
    frame_points: FloatArray
    held_out_wand: FloatArray
    held_out_true: FloatArray
    body: FloatArray
    body_true: FloatArray
    noise_px: float


def _smooth_walk(rng: np.random.Generator, n: int, dim: int, step: float) -> FloatArray:
    """A random walk low-passed by a moving average, shape (n, dim), unit-free."""
    raw = np.cumsum(rng.normal(0.0, step, (n + 40, dim)), axis=0)
    kernel = np.ones(40) / 40.0
    return np.stack([np.convolve(raw[:, k], kernel, mode="valid")[:n] for k in range(dim)], 1)


def _wand_motion(
    rng: np.random.Generator, n: int, length: float, radius: float, z_range: tuple[float, float]
) -> FloatArray:
    """Wand end positions, shape (n, 2, 3), filling a cylinder of the given radius."""
    walk = _smooth_walk(rng, n, 3, 1.0)
    walk -= walk.min(axis=0)
    walk /= np.maximum(walk.max(axis=0), 1e-9)
    # Uniform-ish cover: map the walk onto the cylinder, then add per-frame scatter.
    r = radius * np.sqrt(np.clip(walk[:, 0] * 0.6 + rng.uniform(0, 0.4, n), 0, 1))
    phi = 2.0 * np.pi * (walk[:, 1] + rng.uniform(0, 1, n) * 0.3)
    z = z_range[0] + (z_range[1] - z_range[0]) * np.clip(
        walk[:, 2] * 0.7 + rng.uniform(0, 0.3, n), 0, 1
    )
    centre = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    direction = rng.normal(size=(n, 3)) + _smooth_walk(rng, n, 3, 0.3)
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    half = 0.5 * length * direction
    return np.stack([centre - half, centre + half], axis=1)


def _observe(
    rig: Rig,
    X: FloatArray,
    noise_px: float,
    rng: np.random.Generator,
    dropout: float,
    margin_px: float = 2.0,
) -> FloatArray:
    """Noisy image points of world points X (..., 3) -> (C, ..., 2), NaN where unseen."""
    uv = rig.project(X)
    for c, cam in enumerate(rig):
        w, h = cam.size
        u, v = uv[c, ..., 0], uv[c, ..., 1]
        out = ~((u > margin_px) & (u < w - margin_px) & (v > margin_px) & (v < h - margin_px))
        out |= rng.uniform(size=u.shape) < dropout
        uv[c][out] = np.nan
    return uv + rng.normal(0.0, noise_px, uv.shape)


def wand_dance(
    rig: Rig,
    *,
    n_frames: int = 3000,
    wand_length: float = 500.0,
    noise_px: float = 0.2,
    frame: str = "L",
    frame_samples: int = 100,
    held_out_frames: int = 1000,
    body_frames: int = 300,
    body_markers: int = 20,
    dropout: float = 0.03,
    radius_mm: float = 1600.0,
    z_range_mm: tuple[float, float] = (100.0, 2200.0),
    seed: int = 0,
) -> WandDance:
    """Simulate a wand dance, a static frame and body markers seen by ``rig``.

    Parameters
    ----------
    rig : Rig
        True cameras.
    n_frames : int
        Calibration wand frames.
    wand_length : float
        Distance between the two wand markers (mm).
    noise_px : float
        Gaussian image noise per coordinate (px).
    frame : {"L", "triad"}
        Static reference object on the floor at the world origin.
    frame_samples : int
        Number of static samples averaged into each frame observation.
    held_out_frames, body_frames, body_markers : int
        Sizes of the scoring sets.
    dropout : float
        Probability that a camera misses a visible marker (occlusion).
    radius_mm, z_range_mm
        The capture volume the wand and the body fill: a vertical cylinder (mm).
    seed : int
        Seed of the whole data set.

    Returns
    -------
    WandDance
    """
    if frame not in FRAME_POINTS:
        raise ValueError(f"unknown frame {frame!r}: expected one of {sorted(FRAME_POINTS)}")
    rng = np.random.default_rng(seed)
    wand_true = _wand_motion(rng, n_frames, wand_length, radius_mm, z_range_mm)
    wand = _observe(rig, wand_true, noise_px, rng, dropout).transpose(1, 0, 2, 3)
    held_true = _wand_motion(rng, held_out_frames, wand_length, radius_mm, z_range_mm)
    held = _observe(rig, held_true, noise_px, rng, dropout).transpose(1, 0, 2, 3)

    frame_points = FRAME_POINTS[frame].copy()
    frame_uv = _observe(rig, frame_points, noise_px / np.sqrt(frame_samples), rng, 0.0)

    # Body: markers scattered on a person-sized box that walks across the volume.
    offsets = rng.uniform([-150.0, -120.0, 0.0], [150.0, 120.0, 1700.0], (body_markers, 3))
    s = np.linspace(-1.0, 1.0, body_frames)
    path = np.stack([0.8 * radius_mm * s, 0.3 * radius_mm * np.sin(3 * s), 80.0 + 0 * s], 1)
    heading = 0.4 * np.sin(2 * s)
    ch, sh = np.cos(heading), np.sin(heading)
    rot = np.zeros((body_frames, 3, 3))
    rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1] = ch, -sh, sh, ch
    rot[:, 2, 2] = 1.0
    body_true = np.einsum("fij,mj->fmi", rot, offsets) + path[:, None, :]
    body = _observe(rig, body_true, noise_px, rng, dropout).transpose(1, 0, 2, 3)
    return WandDance(
        rig=rig,
        wand=wand,
        wand_true=wand_true,
        wand_length=float(wand_length),
        frame=frame_uv,
        frame_points=frame_points,
        held_out_wand=held,
        held_out_true=held_true,
        body=body,
        body_true=body_true,
        noise_px=float(noise_px),
    )
