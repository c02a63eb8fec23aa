"""calibrate_intrinsics and fit_homography on synthetic views of a planar grid; error paths."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from spotlab.calibration import calibrate_intrinsics, fit_homography
from spotlab.core.errors import CalibrationError
from spotlab.geometry import Camera
from spotlab.simulators.rigs import ring_rig

SIZE = (1280, 1024)
K_TRUE = np.array([[1150.0, 0.0, 652.0], [0.0, 1148.0, 498.0], [0.0, 0.0, 1.0]])
DIST_TRUE = np.array([-0.18, 0.09, 3e-4, -2e-4, -0.01])


def _grid(n: int = 9, spacing: float = 40.0) -> np.ndarray:
    g = (np.arange(n) - (n - 1) / 2) * spacing
    return np.array([[x, y, 0.0] for y in g for x in g])


def _views(
    cam: Camera, model: np.ndarray, n_views: int, seed: int = 0, tilt: float = 0.6
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Grid-to-camera poses 1.2-1.8 m in front of ``cam`` and the pixels they give."""
    rng = np.random.default_rng(seed)
    Rs, ts, uv = [], [], []
    for _ in range(n_views):
        R = Rotation.from_rotvec([*rng.uniform(-tilt, tilt, 2), rng.uniform(-np.pi, np.pi)])
        t = np.array([*rng.uniform(-150.0, 150.0, 2), rng.uniform(1200.0, 1800.0)])
        Rs.append(R.as_matrix())
        ts.append(t)
        posed = Camera(cam.K, cam.dist, R.as_matrix(), t, cam.size)
        uv.append(posed.project(model))
    return np.array(Rs), np.array(ts), np.array(uv)


def _camera(K: np.ndarray = K_TRUE, dist: np.ndarray = DIST_TRUE) -> Camera:
    return Camera(K, dist, np.eye(3), np.zeros(3), SIZE)


def test_noise_free_views_give_the_exact_camera_and_poses() -> None:
    model = _grid()
    Rs, ts, uv = _views(_camera(), model, 6)
    result = calibrate_intrinsics(model, uv, SIZE, distortion=True)
    assert_allclose(result.camera.K, K_TRUE, atol=1e-6)
    assert_allclose(result.camera.dist, DIST_TRUE, atol=1e-9)
    assert_allclose(result.rotations, Rs, atol=1e-10)
    assert_allclose(result.translations, ts, atol=1e-6)
    assert result.rms_px < 1e-8


def test_skew_is_recovered_when_asked() -> None:
    K = K_TRUE.copy()
    K[0, 1] = 3.0
    model = _grid()
    _, _, uv = _views(_camera(K, np.zeros(5)), model, 5, seed=1)
    result = calibrate_intrinsics(model, uv, SIZE, distortion=False, skew=True)
    assert_allclose(result.camera.K, K, atol=1e-6)
    without = calibrate_intrinsics(model, uv, SIZE, distortion=False)
    assert without.camera.K[0, 1] == 0.0
    assert without.rms_px > 0.01  # a shear the model lacks shows in the residuals


def test_ring_rig_camera_with_noise_and_missing_points() -> None:
    """0.2 px noise: the residual RMS matches the noise; missing points are tolerated."""
    truth = ring_rig(1, seed=4)[0]
    cam = Camera(truth.K, truth.dist, np.eye(3), np.zeros(3), truth.size)
    model = _grid(10, 50.0)
    _, _, uv = _views(cam, model, 12, seed=2)
    rng = np.random.default_rng(7)
    uv = uv + 0.2 * rng.standard_normal(uv.shape)
    uv[rng.random(uv.shape[:2]) < 0.1] = np.nan
    result = calibrate_intrinsics(model, uv, truth.size, distortion=True)
    # 2 coordinates per point: the expected distance RMS is 0.2 sqrt(2) less the fit's dof.
    assert 0.24 < result.rms_px < 0.30
    assert np.isnan(result.residuals).any()
    assert_allclose(result.camera.K[[0, 1], [0, 1]], truth.K[[0, 1], [0, 1]], rtol=3e-3)
    assert_allclose(result.camera.K[:2, 2], truth.K[:2, 2], atol=3.0)
    errors = np.abs(
        result.camera.K[[0, 1, 0, 1], [0, 1, 2, 2]] - truth.K[[0, 1, 0, 1], [0, 1, 2, 2]]
    )
    stds = np.array([result.std[n] for n in ("fx", "fy", "cx", "cy")])
    assert np.all(errors < 4.0 * stds)


def test_two_views_are_enough_without_skew() -> None:
    model = _grid()
    _, _, uv = _views(_camera(dist=np.zeros(5)), model, 2, seed=3)
    result = calibrate_intrinsics(model, uv, SIZE, distortion=False)
    assert_allclose(result.camera.K, K_TRUE, atol=1e-5)


def test_fit_homography_is_exact() -> None:
    H = np.array([[1.1, 0.2, 300.0], [-0.1, 0.9, 200.0], [1e-4, -2e-4, 1.0]])
    X = np.random.default_rng(0).uniform(-100.0, 100.0, (7, 2))
    h = np.column_stack([X, np.ones(7)]) @ H.T
    assert_allclose(fit_homography(X, h[:, :2] / h[:, 2:]), H, rtol=1e-9, atol=1e-12)


# --- error paths -------------------------------------------------------------------------


@pytest.fixture
def scene() -> tuple[np.ndarray, np.ndarray]:
    model = _grid(5)
    _, _, uv = _views(_camera(), model, 4, seed=5)
    return model, uv


def test_too_few_views(scene: tuple[np.ndarray, np.ndarray]) -> None:
    model, uv = scene
    with pytest.raises(CalibrationError, match="at least 2 views"):
        calibrate_intrinsics(model, uv[:1], SIZE)
    with pytest.raises(CalibrationError, match="at least 3 views"):
        calibrate_intrinsics(model, uv[:2], SIZE, skew=True)


def test_view_with_fewer_than_four_points(scene: tuple[np.ndarray, np.ndarray]) -> None:
    model, uv = scene
    uv = uv.copy()
    uv[2, 3:] = np.nan
    with pytest.raises(CalibrationError, match="view 2 has 3 observed points"):
        calibrate_intrinsics(model, uv, SIZE)


def test_collinear_points(scene: tuple[np.ndarray, np.ndarray]) -> None:
    model, uv = scene
    uv = uv.copy()
    uv[1, 5:] = np.nan  # only the first row of the grid is left: collinear
    with pytest.raises(CalibrationError, match="view 1: the observed points are collinear"):
        calibrate_intrinsics(model, uv, SIZE)
    line = np.column_stack([np.arange(6.0), np.zeros(6)])
    with pytest.raises(CalibrationError, match="collinear"):
        calibrate_intrinsics(line, np.zeros((3, 6, 2)), SIZE)


def test_parallel_views() -> None:
    """Grid moved and turned in its own plane only: the intrinsics are not determined."""
    model = _grid()
    cam = _camera(dist=np.zeros(5))
    tilt = Rotation.from_rotvec([0.4, 0.0, 0.0])
    uv = []
    for k in range(5):
        R = tilt * Rotation.from_rotvec([0.0, 0.0, 0.5 * k])
        posed = Camera(cam.K, None, R.as_matrix(), [20.0 * k, -10.0 * k, 1500.0 + 50 * k], SIZE)
        uv.append(posed.project(model))
    with pytest.raises(CalibrationError, match="parallel"):
        calibrate_intrinsics(model, np.array(uv), SIZE, distortion=False)
    # With image noise the closed form gives some answer; the adjustment must refuse it.
    noisy = np.array(uv) + 0.2 * np.random.default_rng(0).standard_normal(np.shape(uv))
    for distortion in (False, True):
        with pytest.raises(CalibrationError, match="do not determine the intrinsics"):
            calibrate_intrinsics(model, noisy, SIZE, distortion=distortion)


def test_nan_and_bad_grids(scene: tuple[np.ndarray, np.ndarray]) -> None:
    model, uv = scene
    bad = model.copy()
    bad[3, 0] = np.nan
    with pytest.raises(CalibrationError, match="NaN"):
        calibrate_intrinsics(bad, uv, SIZE)
    bent = model.copy()
    bent[0, 2] = 5.0
    with pytest.raises(CalibrationError, match="Z = 0"):
        calibrate_intrinsics(bent, uv, SIZE)
    inf = uv.copy()
    inf[0, 0, 0] = np.inf
    with pytest.raises(CalibrationError, match="infinite"):
        calibrate_intrinsics(model, inf, SIZE)
    with pytest.raises(CalibrationError, match="shape"):
        calibrate_intrinsics(model, uv[:, :-1], SIZE)
    with pytest.raises(CalibrationError, match="unknown distortion terms"):
        calibrate_intrinsics(model, uv, SIZE, distortion=("k1", "k4"))
    with pytest.raises(CalibrationError, match="4 points"):
        fit_homography(model[:3, :2], uv[0, :3])
    for size in ((0, 480), (640.5, 480), "640x480"):
        with pytest.raises(CalibrationError, match="image_size"):
            calibrate_intrinsics(model, uv, size)  # type: ignore[arg-type]
