"""cage_calibrate and Selvik's 180-degree rotation check on a synthetic two-plane cage."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from spotlab.calibration import cage_calibrate, rotation_check
from spotlab.core.errors import CalibrationError
from spotlab.geometry import Camera
from spotlab.simulators.rigs import look_at

_LOWER = [[x, y, 0.0] for x in np.linspace(-200, 200, 5) for y in np.linspace(-200, 200, 5)]
_UPPER = [[x, y, 300.0] for x in np.linspace(-150, 150, 4) for y in np.linspace(-150, 150, 4)]
CAGE = np.array(_LOWER + _UPPER)
UPPER = CAGE[:, 2] > 150.0
#: Second position: a half turn (plus 1 degree) about the vertical, a little off centre.
TURN = Rotation.from_euler("z", 181.0, degrees=True).as_matrix()
OFFSET = np.array([30.0, -20.0, 0.0])


def _cameras() -> list[Camera]:
    cameras = []
    for angle in np.radians([-35.0, 35.0]):
        centre = [2500.0 * np.sin(angle), -2500.0 * np.cos(angle), 900.0]
        R, t = look_at(centre, [0.0, 0.0, 150.0])
        K = [[1500.0, 0.0, 640.0], [0.0, 1500.0, 512.0], [0.0, 0.0, 1.0]]
        cameras.append(Camera(K, None, R, t, (1280, 1024)))
    return cameras


def _images(
    true_cage: np.ndarray, noise_px: float = 0.0, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """Image points (C, P, 2) of the cage in position 1 and after the half turn."""
    rng = np.random.default_rng(seed)
    out = []
    for Y in (true_cage, true_cage @ TURN.T + OFFSET):
        uv = np.stack([camera.project(Y) for camera in _cameras()])
        out.append(uv + rng.normal(0.0, noise_px, uv.shape))
    return out[0], out[1]


def _cage_with_error(shift: tuple[float, float] = (0.0, 0.0), turn_deg: float = 0.0) -> np.ndarray:
    true = CAGE.copy()
    true[UPPER] = true[UPPER] @ Rotation.from_euler("z", turn_deg, degrees=True).as_matrix().T
    true[UPPER, :2] += shift
    return true


def test_exact_cage_calibrates_the_cameras() -> None:
    uv1, _ = _images(CAGE)
    result = cage_calibrate(CAGE, uv1, image_size=(1280, 1024))
    assert result.rms_px.shape == (2,) and np.all(result.rms_px < 1e-8)
    assert result.upper.tolist() == UPPER.tolist()
    for fitted, truth in zip(result.rig.cameras, _cameras(), strict=True):
        assert_allclose(fitted.K, truth.K, atol=1e-6)
        assert_allclose(fitted.center, truth.center, atol=1e-6)


def test_exact_cage_passes_the_rotation_check() -> None:
    check = rotation_check(CAGE, *_images(CAGE), tolerance_mm=0.01)
    assert check.passed and check.verdict.startswith("passed")
    assert check.max_mm < 1e-6
    assert abs(check.turn_deg - 179.0) < 1e-6  # 181 degrees about +z is 179 about -z
    assert check.axis_tilt_deg < 1e-6


def test_shifted_upper_plane_is_invisible_in_one_position_but_flagged_by_the_turn() -> None:
    true = _cage_with_error(shift=(2.0, 0.0))
    uv1, uv2 = _images(true)
    # Calibrating from the wrong coordinates leaves no residual at all ...
    assert np.all(cage_calibrate(CAGE, uv1).rms_px < 1e-8)
    # ... but after the half turn the upper plane is off by twice the error.
    check = rotation_check(CAGE, uv1, uv2, tolerance_mm=0.5)
    assert not check.passed and check.verdict.startswith("failed")
    # (to 1 - cos(1 degree): the turn is 181 degrees, not exactly a half turn)
    assert_allclose(check.discrepancy_mm[UPPER, 0].mean(), 4.0, atol=1e-3)
    assert_allclose(check.upper_plane_shift_mm, [2.0, 0.0], atol=1e-3)
    assert check.max_mm > 3.0
    # The corrected coordinates pass.
    again = rotation_check(check.corrected_cage_points, uv1, uv2, tolerance_mm=0.01)
    assert again.passed
    assert_allclose(check.corrected_cage_points, true, atol=1e-3)


def test_turned_upper_plane_is_flagged_and_estimated() -> None:
    check = rotation_check(CAGE, *_images(_cage_with_error(turn_deg=0.5)), tolerance_mm=0.5)
    assert not check.passed
    assert abs(check.upper_plane_rotation_deg - 0.5) < 0.05
    assert np.all(np.abs(check.upper_plane_shift_mm) < 0.05)


def test_with_image_noise_the_check_separates_a_2_mm_error_from_noise() -> None:
    good = rotation_check(CAGE, *_images(CAGE, 0.2, seed=1), tolerance_mm=1.5)
    bad = rotation_check(
        CAGE, *_images(_cage_with_error(shift=(0.0, 2.0)), 0.2, seed=1), tolerance_mm=1.5
    )
    assert good.passed and good.rms_mm < 1.0
    assert not bad.passed and bad.max_mm > 3.0
    assert np.hypot(*(bad.upper_plane_shift_mm - [0.0, 2.0])) < 0.6


def test_wrong_plane_spacing_stays_invisible() -> None:
    # Documented limit: a scaling along the turn axis commutes with the turn.
    true = CAGE.copy()
    true[UPPER, 2] += 2.0
    assert rotation_check(CAGE, *_images(true), tolerance_mm=0.01).passed


def test_nan_image_points_leave_markers_out() -> None:
    uv1, uv2 = _images(CAGE)
    uv1[0, 3] = np.nan
    uv2[1, 30] = np.nan
    check = rotation_check(CAGE, uv1, uv2, tolerance_mm=0.01)
    assert check.passed
    assert check.first.used[0, 3] == np.False_ and check.first.used.sum() == 2 * 41 - 1
    assert np.isnan(check.discrepancy_norm_mm[[3, 30]]).all()


def test_one_plane_only_is_coplanar() -> None:
    lower = CAGE[~UPPER]
    with pytest.raises(CalibrationError, match="coplanar"):
        cage_calibrate(lower, _images(lower)[0])


def test_fewer_than_six_markers() -> None:
    few = CAGE[[0, 4, 20, 25, 40]]
    with pytest.raises(CalibrationError, match="at least 6 markers, got 5"):
        cage_calibrate(few, _images(few)[0])


def test_plane_with_too_few_markers() -> None:
    cage = CAGE[[*range(25), 25, 40]]
    with pytest.raises(CalibrationError, match="upper plane needs at least 3 markers"):
        cage_calibrate(cage, _images(cage)[0])


def test_markers_off_the_two_planes() -> None:
    cage = CAGE.copy()
    cage[30, 2] = 250.0
    with pytest.raises(CalibrationError, match="two parallel planes"):
        cage_calibrate(cage, _images(CAGE)[0])


def test_camera_seeing_too_few_markers_is_named() -> None:
    uv1, _ = _images(CAGE)
    uv1[1, 5:] = np.nan
    with pytest.raises(CalibrationError, match="camera 'cam2': the 3-D DLT needs at least 6"):
        cage_calibrate(CAGE, uv1)


def test_rotation_check_needs_two_cameras_and_a_half_turn() -> None:
    uv1, uv2 = _images(CAGE)
    with pytest.raises(CalibrationError, match="at least 2 cameras, got 1"):
        rotation_check(CAGE, uv1[:1], uv2[:1], tolerance_mm=1.0)
    with pytest.raises(CalibrationError, match=r"turned by 0\.0 degrees"):
        rotation_check(CAGE, uv1, uv1, tolerance_mm=1.0)
    with pytest.raises(CalibrationError, match="tolerance_mm must be positive"):
        rotation_check(CAGE, uv1, uv2, tolerance_mm=0.0)


def test_nan_cage_coordinates() -> None:
    cage = CAGE.copy()
    cage[2, 0] = np.nan
    with pytest.raises(CalibrationError, match="NaN"):
        cage_calibrate(cage, _images(CAGE)[0])
