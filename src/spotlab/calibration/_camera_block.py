"""Cameras as parameter blocks for bundle adjustment: projection with analytic Jacobians.

Each camera is a block of 15 numbers, ``(w1, w2, w3, t1, t2, t3, fx, fy, cx, cy, k1, k2,
p1, p2, k3)``: a rotation increment ``w`` (rad) applied on the left of a reference
rotation (``R = exp([w]x) R0``), the translation (mm), the principal distances and
principal point (px) and the Brown distortion in OpenCV's order. Rotations are carried as
matrices between iterations, so the increment is always small and the parametrisation
has no singularity.

All functions are vectorised over observations: ``cam`` gives the camera index of each.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from spotlab.geometry import Camera

__all__ = [
    "BLOCK",
    "INTRINSIC_NAMES",
    "blocks_from_cameras",
    "cameras_from_blocks",
    "project",
    "project_with_jacobians",
    "rotate_blocks",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

#: Parameters per camera block.
BLOCK = 15
#: Names of block entries 6..14.
INTRINSIC_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


def blocks_from_cameras(cameras: Sequence[Camera]) -> tuple[FloatArray, FloatArray]:
    """Parameter blocks (C, 15) with zero rotation increments, and rotations (C, 3, 3)."""
    blocks = np.zeros((len(cameras), BLOCK))
    rotations = np.zeros((len(cameras), 3, 3))
    for c, cam in enumerate(cameras):
        blocks[c, 3:6] = cam.t
        blocks[c, 6:10] = cam.K[0, 0], cam.K[1, 1], cam.K[0, 2], cam.K[1, 2]
        blocks[c, 10:15] = cam.dist
        rotations[c] = cam.R
    return blocks, rotations


def rotate_blocks(blocks: FloatArray, rotations: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Fold the rotation increments into the rotations; returns blocks with ``w = 0``."""
    new_rot = Rotation.from_rotvec(blocks[:, 0:3]).as_matrix() @ rotations
    # Re-orthonormalise so round-off does not accumulate over many iterations.
    u, _, vt = np.linalg.svd(new_rot)
    out = blocks.copy()
    out[:, 0:3] = 0.0
    return out, u @ vt


def cameras_from_blocks(
    blocks: FloatArray,
    rotations: FloatArray,
    sizes: Sequence[tuple[int, int]],
    names: Sequence[str],
) -> list[Camera]:
    """Cameras of the given blocks (rotation increments folded in)."""
    blocks, rotations = rotate_blocks(blocks, rotations)
    cameras = []
    for c in range(blocks.shape[0]):
        fx, fy, cx, cy = blocks[c, 6:10]
        K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        cameras.append(
            Camera(K, blocks[c, 10:15], rotations[c], blocks[c, 3:6], sizes[c], names[c])
        )
    return cameras


def _camera_frame(
    blocks: FloatArray, rotations: FloatArray, cam: IntArray, X: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Points in the camera frame (n, 3) and the rotated world points ``R X`` (n, 3)."""
    R = Rotation.from_rotvec(blocks[:, 0:3]).as_matrix() @ rotations
    RX = np.einsum("nij,nj->ni", R[cam], X)
    return RX + blocks[cam, 3:6], RX


def _distort(b: FloatArray, x: FloatArray, y: FloatArray) -> tuple[FloatArray, ...]:
    k1, k2, p1, p2, k3 = b[:, 10], b[:, 11], b[:, 12], b[:, 13], b[:, 14]
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return xd, yd, r2, radial


def project(blocks: FloatArray, rotations: FloatArray, cam: IntArray, X: FloatArray) -> FloatArray:
    """Pixel coordinates (n, 2) of world points ``X`` (n, 3) in cameras ``cam`` (n,)."""
    xc, _ = _camera_frame(blocks, rotations, cam, X)
    b = blocks[cam]
    x = xc[:, 0] / xc[:, 2]
    y = xc[:, 1] / xc[:, 2]
    xd, yd, _, _ = _distort(b, x, y)
    return np.stack([b[:, 6] * xd + b[:, 8], b[:, 7] * yd + b[:, 9]], axis=1)


def project_with_jacobians(
    blocks: FloatArray, rotations: FloatArray, cam: IntArray, X: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Projection and its derivatives.

    Parameters
    ----------
    blocks : ndarray, shape (C, 15)
    rotations : ndarray, shape (C, 3, 3)
    cam : ndarray of int, shape (n,)
        Camera of each observation.
    X : ndarray, shape (n, 3)
        World points (mm).

    Returns
    -------
    uv : ndarray, shape (n, 2)
        Pixel coordinates.
    d_block : ndarray, shape (n, 2, 15)
        Derivative with respect to the observation's camera block.
    d_point : ndarray, shape (n, 2, 3)
        Derivative with respect to the world point.
    depth : ndarray, shape (n,)
        ``z`` in the camera frame (mm); the projection is meaningless where it is <= 0.
    """
    xc, RX = _camera_frame(blocks, rotations, cam, X)
    b = blocks[cam]
    z = xc[:, 2]
    iz = 1.0 / z
    x = xc[:, 0] * iz
    y = xc[:, 1] * iz
    xd, yd, r2, radial = _distort(b, x, y)
    fx, fy = b[:, 6], b[:, 7]
    k1, k2, p1, p2, k3 = b[:, 10], b[:, 11], b[:, 12], b[:, 13], b[:, 14]
    n = x.shape[0]

    # d(xd, yd)/d(x, y)
    dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
    dd = np.empty((n, 2, 2))
    dd[:, 0, 0] = radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x
    dd[:, 0, 1] = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
    dd[:, 1, 0] = dd[:, 0, 1]
    dd[:, 1, 1] = radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x
    # d(u, v)/d(x, y) = diag(fx, fy) @ dd
    duv_dxy = dd * np.stack([fx, fy], axis=1)[:, :, None]
    # d(x, y)/d(xc)
    dxy_dxc = np.zeros((n, 2, 3))
    dxy_dxc[:, 0, 0] = iz
    dxy_dxc[:, 1, 1] = iz
    dxy_dxc[:, 0, 2] = -x * iz
    dxy_dxc[:, 1, 2] = -y * iz
    duv_dxc = np.einsum("nij,njk->nik", duv_dxy, dxy_dxc)

    d_block = np.zeros((n, 2, BLOCK))
    # Rotation increment on the left: d(xc)/dw = -[R X]x.
    rx, ry, rz = RX[:, 0], RX[:, 1], RX[:, 2]
    skew = np.zeros((n, 3, 3))
    skew[:, 0, 1], skew[:, 0, 2] = rz, -ry
    skew[:, 1, 0], skew[:, 1, 2] = -rz, rx
    skew[:, 2, 0], skew[:, 2, 1] = ry, -rx
    d_block[:, :, 0:3] = np.einsum("nij,njk->nik", duv_dxc, skew)
    d_block[:, :, 3:6] = duv_dxc
    d_block[:, 0, 6] = xd
    d_block[:, 1, 7] = yd
    d_block[:, 0, 8] = 1.0
    d_block[:, 1, 9] = 1.0
    r4 = r2 * r2
    for col, (gx, gy) in zip(
        (10, 11, 12, 13, 14),
        (
            (x * r2, y * r2),
            (x * r4, y * r4),
            (2.0 * x * y, r2 + 2.0 * y * y),
            (r2 + 2.0 * x * x, 2.0 * x * y),
            (x * r4 * r2, y * r4 * r2),
        ),
        strict=True,
    ):
        d_block[:, 0, col] = fx * gx
        d_block[:, 1, col] = fy * gy
    R = Rotation.from_rotvec(blocks[:, 0:3]).as_matrix() @ rotations
    d_point = np.einsum("nij,njk->nik", duv_dxc, R[cam])
    uv = np.stack([fx * xd + b[:, 8], fy * yd + b[:, 9]], axis=1)
    return uv, d_block, d_point, z
