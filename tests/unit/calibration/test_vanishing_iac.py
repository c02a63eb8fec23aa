"""intrinsics_from_orthogonal_vanishing_points on a triad waved in front of ring_rig cameras."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from spotlab.calibration import intrinsics_from_orthogonal_vanishing_points, vanishing_point
from spotlab.core.errors import CalibrationError
from spotlab.geometry import Camera
from spotlab.simulators.rigs import ring_rig

#: Markers per triad arm (mm from the triad's origin), as on a 600 mm arm.
ARM = np.array([0.0, 200.0, 600.0])
SIZE = (1280, 1024)


def _triad_pairs(
    camera: Camera, n_frames: int, noise_px: float, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """Orthogonal vanishing-point pairs (3 F, 3) of a triad at F random attitudes."""
    rng = np.random.default_rng(seed)
    axes = Rotation.random(n_frames, random_state=rng).as_matrix().transpose(0, 2, 1)  # rows
    origin = rng.uniform([-800.0, -800.0, 300.0], [800.0, 800.0, 1600.0], (n_frames, 3))
    X = origin[:, None, None, :] + ARM[None, None, :, None] * axes[:, :, None, :]
    uv = camera.project(X) + rng.normal(0.0, noise_px, (n_frames, 3, ARM.size, 2))
    vp = vanishing_point(uv, ARM)  # (F, 3 axes, 3)
    first, second = [0, 0, 1], [1, 2, 2]
    return vp[:, first].reshape(-1, 3), vp[:, second].reshape(-1, 3)


def _camera(K: np.ndarray) -> Camera:
    ref = ring_rig(1, distortion=False, seed=2)[0]
    return Camera(K, None, ref.R, ref.t, SIZE)


def test_noise_free_triad_gives_the_exact_general_K() -> None:
    K = np.array([[1150.0, 1.5, 652.0], [0.0, 1141.0, 497.0], [0.0, 0.0, 1.0]])
    v1, v2 = _triad_pairs(_camera(K), 4, 0.0, seed=1)
    result = intrinsics_from_orthogonal_vanishing_points(v1, v2, image_size=SIZE)
    assert_allclose(result.K, K, rtol=1e-8, atol=1e-6)
    assert result.n_pairs == 12
    assert result.rms_angle_error_deg < 1e-6
    Kinv = np.linalg.inv(K)
    assert_allclose(result.omega, Kinv.T @ Kinv / (Kinv.T @ Kinv)[2, 2], rtol=1e-7)


@pytest.mark.parametrize(
    ("assume", "needed"), [("none", 5), ("zero_skew", 4), ("square_pixels", 3)]
)
def test_noise_free_minimal_pairs(assume: str, needed: int) -> None:
    f = 1150.0
    fy = f if assume == "square_pixels" else 1138.0
    K = np.array([[f, 0.0, 652.0], [0.0, fy, 497.0], [0.0, 0.0, 1.0]])
    v1, v2 = _triad_pairs(_camera(K), 2, 0.0, seed=2)
    result = intrinsics_from_orthogonal_vanishing_points(
        v1[:needed], v2[:needed], assume=assume, image_size=SIZE
    )
    assert result.n_pairs == needed
    assert_allclose(result.K, K, rtol=1e-8, atol=1e-6)
    if assume != "none":
        assert result.K[0, 1] == 0.0


def test_real_ring_rig_cameras_with_noise() -> None:
    rig = ring_rig(3, distortion=False, seed=0)
    for k, camera in enumerate(rig):
        v1, v2 = _triad_pairs(camera, 300, 0.2, seed=10 + k)
        result = intrinsics_from_orthogonal_vanishing_points(v1, v2, image_size=SIZE)
        K, Kt = result.K, camera.K
        # Tolerances from docs/calibration-objects.md (300 attitudes, 0.2 px noise).
        assert abs(K[0, 0] / Kt[0, 0] - 1.0) < 0.015
        assert abs(K[1, 1] / Kt[1, 1] - 1.0) < 0.015
        assert abs(K[0, 1]) < 15.0
        assert np.hypot(*(K[:2, 2] - Kt[:2, 2])) < 25.0
        assert 0.5 < result.rms_angle_error_deg < 10.0


def test_nan_pairs_are_left_out() -> None:
    K = _camera(np.array([[1150.0, 0.0, 640.0], [0.0, 1150.0, 512.0], [0.0, 0.0, 1.0]])).K
    v1, v2 = _triad_pairs(_camera(K), 3, 0.0, seed=3)
    v1[4] = np.nan
    result = intrinsics_from_orthogonal_vanishing_points(v1, v2, image_size=SIZE)
    assert result.n_pairs == 8
    assert_allclose(result.K, K, atol=1e-6)


def test_too_few_pairs() -> None:
    v1, v2 = _triad_pairs(_camera(np.diag([1150.0, 1150.0, 1.0])), 2, 0.0, seed=4)
    with pytest.raises(CalibrationError, match="needs at least 5, got 4"):
        intrinsics_from_orthogonal_vanishing_points(v1[:4], v2[:4], image_size=SIZE)


def test_pairs_from_one_attitude_are_degenerate() -> None:
    v1, v2 = _triad_pairs(_camera(np.diag([1150.0, 1150.0, 1.0])), 1, 0.0, seed=5)
    # The same attitude seen again and again: three independent constraints only.
    with pytest.raises(CalibrationError, match="do not determine omega"):
        intrinsics_from_orthogonal_vanishing_points(
            np.tile(v1, (10, 1)), np.tile(v2, (10, 1)), image_size=SIZE
        )


def test_pairs_that_are_not_orthogonal_give_no_positive_definite_omega() -> None:
    # Vanishing points of directions 45 degrees apart on a frontal camera:
    # v1' omega v2 = 0 cannot hold with a positive definite omega for such pairs.
    K = np.array([[1000.0, 0.0, 640.0], [0.0, 1000.0, 512.0], [0.0, 0.0, 1.0]])
    rng = np.random.default_rng(6)
    rows = []
    for _ in range(12):
        d1 = rng.normal(size=3)
        d1 /= np.linalg.norm(d1)
        e = np.cross(d1, rng.normal(size=3))
        e /= np.linalg.norm(e)
        d2 = np.cos(np.pi / 4) * d1 + np.sin(np.pi / 4) * e
        rows.append((K @ d1, K @ d2))
    v1, v2 = (np.array(r) for r in zip(*rows, strict=True))
    with pytest.raises(CalibrationError, match="not positive definite"):
        intrinsics_from_orthogonal_vanishing_points(v1, v2, image_size=SIZE)


def test_bad_inputs() -> None:
    v = np.ones((6, 3))
    with pytest.raises(CalibrationError, match="assume must be one of"):
        intrinsics_from_orthogonal_vanishing_points(v, v, assume="unit")  # type: ignore[arg-type]
    with pytest.raises(CalibrationError, match="same pairs"):
        intrinsics_from_orthogonal_vanishing_points(v, v[:5])
    with pytest.raises(CalibrationError, match=r"shape \(N, 3\)"):
        intrinsics_from_orthogonal_vanishing_points(np.ones((6, 4)), np.ones((6, 4)))
