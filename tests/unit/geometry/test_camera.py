"""Camera: projection, OpenCV distortion mapping, undistortion, DLT round trip, validation."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from spotlab.core.errors import CalibrationError
from spotlab.geometry import Camera, distort_normalized, undistort_normalized

K0 = np.array([[1000.0, 2.0, 320.0], [0.0, 1100.0, 240.0], [0.0, 0.0, 1.0]])


def _random_camera(rng: np.random.Generator, dist: object = None) -> Camera:
    K = np.array(
        [
            [rng.uniform(400, 3000), rng.uniform(-10, 10), rng.uniform(100, 1500)],
            [0.0, rng.uniform(400, 3000), rng.uniform(100, 1000)],
            [0.0, 0.0, 1.0],
        ]
    )
    R = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
    t = rng.normal(size=3) * 1000.0
    t[2] += 3000.0
    return Camera(K, dist, R, t, (1920, 1080), "cam")


def test_project_hand_derived() -> None:
    # Camera 2000 mm from the origin looking along +Z; a 90-degree turn about z.
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    cam = Camera(K0, None, R, [0.0, 0.0, 2000.0], (640, 480))
    # X = (100, 50, 500): x_cam = (-50, 100, 2500); x = -0.02, y = 0.04
    # u = 1000 * -0.02 + 2 * 0.04 + 320 = 300.08; v = 1100 * 0.04 + 240 = 284
    assert_allclose(cam.project([100.0, 50.0, 500.0]), [300.08, 284.0], rtol=0, atol=1e-12)
    assert_allclose(cam.center, [0.0, 0.0, -2000.0], atol=1e-12)


def test_project_is_vectorised_and_nan_behind() -> None:
    cam = _random_camera(np.random.default_rng(0))
    X = np.random.default_rng(1).normal(size=(4, 5, 3)) * 100.0
    uv = cam.project(X)
    assert uv.shape == (4, 5, 2)
    assert_allclose(uv[2, 3], cam.project(X[2, 3]))
    behind = cam.center + 10.0 * (cam.center - np.zeros(3))  # beyond the centre, away from 0
    assert np.all(np.isnan(cam.project(behind)))


def test_distortion_matches_opencv() -> None:
    """Projection with the five OpenCV terms equals cv2.projectPoints itself (the dev
    extra installs opencv-python-headless)."""
    import cv2

    rng = np.random.default_rng(2)
    K = K0.copy()
    K[0, 1] = 0.0  # OpenCV's camera matrix has no skew
    dist = np.array([-0.3, 0.12, 0.001, -0.002, -0.03])
    R = Rotation.from_rotvec([0.1, -0.2, 0.05]).as_matrix()
    t = np.array([10.0, -20.0, 1500.0])
    X = rng.uniform(-300, 300, size=(50, 3))
    cam = Camera(K, dist, R, t, (640, 480))
    rvec = Rotation.from_matrix(R).as_rotvec()
    expected = cv2.projectPoints(X, rvec, t, K, dist)[0][:, 0, :]
    # OpenCV rounds the rotation through Rodrigues' formula: 1e-9 px is double precision
    assert_allclose(cam.project(X), expected, rtol=0, atol=1e-9)
    # and the distortion alone: the terms in OpenCV's order (k1, k2, p1, p2, k3)
    xy = rng.uniform(-0.4, 0.4, size=(50, 2))
    expected_xy = cv2.projectPoints(
        np.column_stack([xy, np.ones(len(xy))]), np.zeros(3), np.zeros(3), np.eye(3), dist
    )[0][:, 0, :]
    assert_allclose(distort_normalized(xy, dist), expected_xy, rtol=0, atol=1e-12)
    # and its inverse: cv2.undistortPoints iterates as spotlab does; both converge to
    # well under 1e-6 of a normalised unit (about 1e-3 px at f = 1000 px)
    back = cv2.undistortPoints(
        expected_xy[:, None, :], np.eye(3), dist,
        criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14),
    )[:, 0, :]  # fmt: skip
    assert_allclose(undistort_normalized(expected_xy, dist), back, rtol=0, atol=1e-6)
    assert_allclose(back, xy, rtol=0, atol=1e-6)


def test_woltring_brown_model_maps_to_opencv_order() -> None:
    # Woltring Eq. 12 with b1, b2, b3, p, q equals OpenCV's with k = b, p1 = q, p2 = p.
    b1, b2, b3, p, q = -0.2, 0.05, 0.01, 0.003, -0.004
    x, y = 0.3, -0.2
    r2 = x * x + y * y
    b = 1 + b1 * r2 + b2 * r2**2 + b3 * r2**3
    ref = [
        b * x + p * (r2 + 2 * x * x) + 2 * q * x * y,
        b * y + q * (r2 + 2 * y * y) + 2 * p * x * y,
    ]
    K = np.eye(3)
    cam = Camera(K, [b1, b2, q, p, b3], np.eye(3), [0.0, 0.0, 1.0], (1, 1))
    assert_allclose(cam.distort([x, y]), ref, rtol=0, atol=1e-15)


def test_undistort_inverts_distort() -> None:
    K = [[1200.0, 0.0, 950.0], [0.0, 1210.0, 530.0], [0.0, 0.0, 1.0]]
    R = Rotation.from_rotvec([0.1, 0.2, -0.3]).as_matrix()
    cam = Camera(K, [-0.25, 0.08, 0.001, 0.002, -0.01], R, [0, 0, 1.0], (1920, 1080))
    uv = np.random.default_rng(4).uniform([0, 0], cam.size, size=(500, 2))
    assert_allclose(cam.distort(cam.undistort(uv)), uv, rtol=0, atol=1e-8)
    ideal = np.random.default_rng(5).uniform([0, 0], cam.size, size=(500, 2))
    assert_allclose(cam.undistort(cam.distort(ideal)), ideal, rtol=0, atol=1e-8)
    uv[3] = np.nan
    assert np.all(np.isnan(cam.undistort(uv)[3]))


def test_undistort_raises_beyond_the_invertible_region() -> None:
    cam = Camera(np.eye(3), [-0.5, 0.0, 0.0, 0.0, 0.0], np.eye(3), [0, 0, 1.0], (1, 1))
    # x (1 - 0.5 x^2) peaks at 0.544 for x = 0.816: 0.8 has no inverse.
    with pytest.raises(CalibrationError, match="undistortion"):
        cam.undistort([[0.8, 0.0]])


def test_dlt_round_trip_exact() -> None:
    rng = np.random.default_rng(6)
    for _ in range(100):
        cam = _random_camera(rng)
        L = cam.to_dlt()
        back = Camera.from_dlt(L, cam.size)
        assert_allclose(back.K, cam.K, rtol=1e-9, atol=1e-9)
        assert_allclose(back.R, cam.R, rtol=0, atol=1e-9)
        assert_allclose(back.t, cam.t, rtol=1e-9, atol=1e-9)
        assert_allclose(back.to_dlt(), L, rtol=1e-9, atol=1e-12)


def test_dlt_projects_like_the_camera() -> None:
    cam = _random_camera(np.random.default_rng(7))
    X = np.random.default_rng(8).uniform(-500, 500, size=(20, 3))
    L = cam.to_dlt()
    den = X @ L[8:11] + 1
    uv = np.column_stack([(X @ L[0:3] + L[3]) / den, (X @ L[4:7] + L[7]) / den])
    assert_allclose(uv, cam.project(X), rtol=1e-12)


def test_to_dlt_origin_in_principal_plane() -> None:
    cam = Camera(K0, None, np.eye(3), [0.0, 0.0, 0.0], (640, 480))
    with pytest.raises(CalibrationError, match="principal plane"):
        cam.to_dlt()


def test_from_dlt_degenerate() -> None:
    with pytest.raises(CalibrationError, match="degenerate"):
        Camera.from_dlt(np.zeros(11), (640, 480))
    with pytest.raises(CalibrationError, match="NaN"):
        Camera.from_dlt([np.nan] * 11, (640, 480))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"K": np.diag([1.0, 1.0, 2.0])}, "K\\[2,2\\] = 1"),
        ({"K": [[1.0, 0, 0], [0.5, 1.0, 0], [0, 0, 1]]}, "upper triangular"),
        ({"K": np.diag([-1.0, 1.0, 1.0])}, "positive principal distances"),
        ({"K": np.eye(2)}, "shape"),
        ({"R": np.diag([1.0, 1.0, -1.0])}, "reflection"),
        ({"R": np.diag([1.0, 2.0, 1.0])}, "not orthonormal"),
        ({"t": [0.0, np.nan, 1.0]}, "NaN"),
        ({"dist": [0.1, 0.2, 0.3]}, "4 or 5"),
        ({"dist": [0.1, 0.2, 0.3, np.inf]}, "NaN or infinite"),
        ({"size": (640, 0)}, "positive"),
        ({"size": "big"}, "width, height"),
    ],
)
def test_invalid_camera(kwargs: dict[str, object], message: str) -> None:
    args: dict[str, object] = {"K": K0, "dist": None, "R": np.eye(3), "t": [0, 0, 1.0]}
    args["size"] = (640, 480)
    args.update(kwargs)
    with pytest.raises(CalibrationError, match=message):
        Camera(**args)  # type: ignore[arg-type]


def test_attributes_are_read_only() -> None:
    cam = Camera(K0, [0.1, 0, 0, 0], np.eye(3), [0, 0, 1.0], (640, 480), name="a")
    assert cam.dist.shape == (5,)
    assert cam.name == "a"
    with pytest.raises(ValueError, match="read-only"):
        cam.K[0, 0] = 5.0
