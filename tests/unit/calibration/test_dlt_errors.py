"""dlt_calibrate and dlt_reconstruct_on_plane: one test per error path."""

from __future__ import annotations

import numpy as np
import pytest

from spotlab.calibration import dlt_calibrate, dlt_reconstruct_on_plane
from spotlab.core.errors import CalibrationError
from spotlab.geometry import Camera

_CORNERS = [[x, y, z] for x in (0.0, 500.0) for y in (0.0, 400.0) for z in (0.0, 300.0)]
CUBE = np.array(_CORNERS) - np.array([250.0, 200.0, 150.0])
CAMERA = Camera(
    [[1000.0, 0.0, 640.0], [0.0, 1000.0, 480.0], [0.0, 0.0, 1.0]],
    None,
    np.eye(3),
    [0.0, 0.0, 3000.0],
    (1280, 960),
)


def _uv(X: np.ndarray) -> np.ndarray:
    return CAMERA.project(X)


def test_fewer_than_six_points() -> None:
    with pytest.raises(CalibrationError, match="at least 6 control points, got 5"):
        dlt_calibrate(CUBE[:5], _uv(CUBE[:5]))


def test_too_few_points_for_distortion_terms() -> None:
    with pytest.raises(CalibrationError, match="16 parameters need at least 8"):
        dlt_calibrate(CUBE[:7], _uv(CUBE[:7]), distortion=True)


def test_nan_names_the_point() -> None:
    uv = _uv(CUBE)
    uv[3, 1] = np.nan
    with pytest.raises(
        CalibrationError, match=r"NaN or infinite coordinates at control points \[3\]"
    ):
        dlt_calibrate(CUBE, uv)


def test_coplanar_control() -> None:
    X = CUBE.copy()
    X[:, 2] = 7.0
    with pytest.raises(CalibrationError, match="coplanar"):
        dlt_calibrate(X, _uv(X))


def test_collinear_control() -> None:
    X = np.outer(np.arange(8.0), [10.0, 20.0, 30.0]) + np.array([0.0, 0.0, 100.0])
    with pytest.raises(CalibrationError, match="collinear"):
        dlt_calibrate(X, _uv(X))


def test_coincident_control() -> None:
    X = np.ones((8, 3))
    with pytest.raises(CalibrationError, match="coincide"):
        dlt_calibrate(X, np.random.default_rng(0).uniform(size=(8, 2)))


def test_collinear_image_points() -> None:
    uv = np.column_stack([np.arange(8.0), np.arange(8.0)])
    with pytest.raises(CalibrationError, match="image points are collinear"):
        dlt_calibrate(CUBE, uv)


def test_degenerate_linear_system() -> None:
    # Control on a plane plus a line through the camera centre: a critical configuration
    # (Hartley & Zisserman 2004, section 7.1.2), the DLT equations have a 2-D null space.
    rng = np.random.default_rng(1)
    plane = np.column_stack([rng.uniform(-400, 400, size=(6, 2)), np.zeros(6)])
    direction = np.array([0.1, 0.05, 1.0])
    line = CAMERA.center + np.outer([2500.0, 3300.0], direction)
    X = np.vstack([plane, line])
    with pytest.raises(CalibrationError, match="degenerate control configuration"):
        dlt_calibrate(X, _uv(X))


def test_shape_mismatch() -> None:
    with pytest.raises(CalibrationError, match="differ in length"):
        dlt_calibrate(CUBE, _uv(CUBE)[:7])
    with pytest.raises(CalibrationError, match=r"shape \(N, 3\)"):
        dlt_calibrate(CUBE[:, :2], _uv(CUBE))
    with pytest.raises(CalibrationError, match=r"shape \(N, 2\)"):
        dlt_calibrate(CUBE, CUBE)


def test_origin_in_principal_plane() -> None:
    # Move the world origin to the camera centre's depth: L12 = 1 is undefined.
    X = CUBE + np.array([0.0, 0.0, 3000.0])
    shifted = Camera(CAMERA.K, None, CAMERA.R, [0.0, 0.0, 0.0], CAMERA.size)
    with pytest.raises(CalibrationError, match="principal plane"):
        dlt_calibrate(X, shifted.project(X))


def test_left_handed_image_axes() -> None:
    uv = _uv(CUBE)
    uv[:, 1] = 960.0 - uv[:, 1]  # v measured upwards
    with pytest.raises(CalibrationError, match="opposite handedness"):
        dlt_calibrate(CUBE, uv)


def test_unknown_distortion_term() -> None:
    with pytest.raises(CalibrationError, match="unknown distortion terms"):
        dlt_calibrate(CUBE, _uv(CUBE), distortion=("k9",))


def test_distortion_needs_refine() -> None:
    with pytest.raises(CalibrationError, match="refine=True"):
        dlt_calibrate(CUBE, _uv(CUBE), distortion=True, refine=False)


def test_plane_errors() -> None:
    with pytest.raises(CalibrationError, match="zero vector"):
        dlt_reconstruct_on_plane(CAMERA, [[0.0, 0.0]], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    with pytest.raises(CalibrationError, match="finite 3-vectors"):
        dlt_reconstruct_on_plane(CAMERA, [[0.0, 0.0]], [0.0, np.nan, 0.0], [0.0, 0.0, 1.0])
