"""Input validation shared by the geometry classes: every failure names its cause."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import CalibrationError

FloatArray = NDArray[np.float64]


def finite_array(value: Any, shape: tuple[int, ...], what: str) -> FloatArray:
    """A float64 copy of ``value`` with exactly ``shape``, all values finite."""
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise CalibrationError(f"{what} must be numeric: {exc}") from None
    if arr.shape != shape:
        raise CalibrationError(f"{what} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise CalibrationError(f"{what} holds NaN or infinite values")
    return arr


def intrinsic_matrix(value: Any) -> FloatArray:
    """K: 3x3, upper triangular, positive principal distances, K[2, 2] = 1."""
    K = finite_array(value, (3, 3), "K (intrinsic matrix)")
    scale = float(np.max(np.abs(K)))
    lower = np.abs(K[[1, 2, 2], [0, 0, 1]])
    if np.any(lower > 1e-9 * scale):
        raise CalibrationError(
            "K (intrinsic matrix) must be upper triangular: K[1,0], K[2,0], K[2,1] = "
            f"{K[1, 0]:g}, {K[2, 0]:g}, {K[2, 1]:g}"
        )
    if abs(K[2, 2] - 1.0) > 1e-12:
        raise CalibrationError(f"K (intrinsic matrix) must have K[2,2] = 1, got {K[2, 2]!r}")
    if not (K[0, 0] > 0.0 and K[1, 1] > 0.0):
        raise CalibrationError(
            "K (intrinsic matrix) must have positive principal distances "
            f"fx = {K[0, 0]:g}, fy = {K[1, 1]:g}"
        )
    K[1, 0] = K[2, 0] = K[2, 1] = 0.0
    K[2, 2] = 1.0
    return K


def rotation_matrix(value: Any) -> FloatArray:
    """R: 3x3 orthonormal with determinant +1 (to 1e-6)."""
    R = finite_array(value, (3, 3), "R (rotation matrix)")
    err = float(np.max(np.abs(R @ R.T - np.eye(3))))
    if err > 1e-6:
        raise CalibrationError(
            f"R (rotation matrix) is not orthonormal: max |R R' - I| = {err:.3g}"
        )
    det = float(np.linalg.det(R))
    if det < 0.0:
        raise CalibrationError(
            f"R (rotation matrix) has determinant {det:.6g}: a reflection, not a rotation"
        )
    return R


def distortion_vector(value: Any) -> FloatArray:
    """dist in OpenCV order; None or () mean no distortion, 4 terms mean k3 = 0."""
    if value is None:
        return np.zeros(5)
    arr = np.array(value, dtype=np.float64).ravel()
    if arr.size == 0:
        return np.zeros(5)
    if arr.size == 4:
        arr = np.append(arr, 0.0)
    if arr.size != 5:
        raise CalibrationError(
            f"dist must hold 4 or 5 coefficients (k1, k2, p1, p2[, k3]), got {arr.size}: "
            "the rational and thin-prism models are not supported"
        )
    if not np.all(np.isfinite(arr)):
        raise CalibrationError("dist holds NaN or infinite values")
    return arr


def image_size(value: Any) -> tuple[int, int]:
    """(width, height) in pixels, positive integers."""
    try:
        w, h = (int(v) for v in value)
        exact = all(float(v) == int(v) for v in value)
    except (TypeError, ValueError, OverflowError):  # OverflowError: int(inf)
        raise CalibrationError(f"size must be (width, height) in pixels, got {value!r}") from None
    if not exact or w <= 0 or h <= 0:
        raise CalibrationError(f"size must be positive whole pixels (width, height), got {value!r}")
    return w, h


def points(value: Any, dim: int, what: str) -> FloatArray:
    """A float64 array of shape (..., dim); NaN allowed (missing points)."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0 or arr.shape[-1] != dim:
        raise CalibrationError(f"{what} must have shape (..., {dim}), got {arr.shape}")
    return arr
