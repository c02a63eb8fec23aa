"""Synthetic camera rigs: cameras on a ring looking at the middle of a capture volume.

The reference scene of ``design/TARGETS.md``: 8 cameras of 1280 x 1024 px on a ring of
4 m radius, lenses with radial and tangential distortion, principal points a little off
the image centre. Every parameter is drawn from a seeded generator so a scene can be
rebuilt exactly from its seed.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from spotlab.geometry import Camera, Rig

__all__ = ["look_at", "ring_rig"]

FloatArray = NDArray[np.float64]


def look_at(center: ArrayLike, target: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Rotation and translation of a camera at ``center`` aimed at ``target``.

    Parameters
    ----------
    center, target : array_like, shape (3,)
        Perspective centre and aim point in world coordinates (mm); world z is up.

    Returns
    -------
    R : ndarray, shape (3, 3)
        World-to-camera rotation; camera z along the line of sight, camera y pointing
        down in the image (OpenCV convention).
    t : ndarray, shape (3,)
        Translation (mm) so that ``x_cam = R @ X + t``.
    """
    c = np.asarray(center, dtype=np.float64)
    z = np.asarray(target, dtype=np.float64) - c
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    if np.linalg.norm(x) < 1e-9:
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.vstack([x, y, z])
    return R, -R @ c


def ring_rig(
    n_cameras: int = 8,
    *,
    radius_mm: float = 4000.0,
    height_mm: float = 2200.0,
    aim_mm: Sequence[float] = (0.0, 0.0, 900.0),
    size: tuple[int, int] = (1280, 1024),
    focal_px: float = 1150.0,
    distortion: bool = True,
    seed: int = 0,
) -> Rig:
    """Cameras evenly spaced on a horizontal ring, all aimed at one point.

    Parameters
    ----------
    n_cameras : int
        Number of cameras (>= 2).
    radius_mm, height_mm : float
        Ring radius and camera height above the floor (mm).
    aim_mm : sequence of 3 floats
        Point every camera looks at (mm).
    size : (width, height)
        Image size (px).
    focal_px : float
        Nominal principal distance (px); each camera differs by up to +-3 %.
    distortion : bool
        Radial (k1, k2, k3) and tangential (p1, p2) distortion of a wide-angle
        machine-vision lens when true, none when false.
    seed : int
        Seed of the per-camera variations (focal length, principal point, aim,
        distortion, height).

    Returns
    -------
    Rig
        Cameras named ``cam1`` ... ``camN``.
    """
    rng = np.random.default_rng(seed)
    w, h = size
    cameras = []
    for k in range(n_cameras):
        angle = 2.0 * np.pi * k / n_cameras + rng.uniform(-0.1, 0.1)
        center = (
            radius_mm * np.cos(angle),
            radius_mm * np.sin(angle),
            height_mm + rng.uniform(-300.0, 300.0),
        )
        target = np.asarray(aim_mm, dtype=np.float64) + rng.uniform(-150.0, 150.0, 3)
        R, t = look_at(center, target)
        f = focal_px * (1.0 + rng.uniform(-0.03, 0.03))
        K = np.array(
            [
                [f * (1.0 + rng.uniform(-0.002, 0.002)), 0.0, w / 2 + rng.uniform(-25.0, 25.0)],
                [0.0, f, h / 2 + rng.uniform(-25.0, 25.0)],
                [0.0, 0.0, 1.0],
            ]
        )
        if distortion:
            dist = np.array(
                [
                    rng.uniform(-0.22, -0.12),
                    rng.uniform(0.05, 0.12),
                    rng.uniform(-5e-4, 5e-4),
                    rng.uniform(-5e-4, 5e-4),
                    rng.uniform(-0.02, 0.0),
                ]
            )
        else:
            dist = np.zeros(5)
        cameras.append(Camera(K, dist, R, t, size, name=f"cam{k + 1}"))
    return Rig(cameras)
