"""calibrate_intrinsics on Zhang's own checkerboard data (shared/data/zhang1998, SOURCES.md 2a).

Published answer (Microsoft Research's completecalibration.txt): alpha = 832.5,
gamma = 0.204494, beta = 832.53, u0 = 303.959, v0 = 206.585, k1 = -0.228601,
k2 = 0.190353, and per image R and t (inches). SOURCES.md states that the published
calibration reproduces the corners with mean (max) residuals 0.33 (0.78), 0.20 (0.72),
0.52 (1.10), 0.22 (0.49), 0.19 (0.53) px for images 1-5.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from spotlab.calibration import calibrate_intrinsics
from spotlab.geometry import Camera

SIZE = (640, 480)
PUBLISHED_K = np.array([[832.5, 0.204494, 303.959], [0.0, 832.53, 206.585], [0.0, 0.0, 1.0]])
PUBLISHED_DIST = np.array([-0.228601, 0.190353, 0.0, 0.0, 0.0])
MEAN_RESIDUAL_PX = np.array([0.33, 0.20, 0.52, 0.22, 0.19])
MAX_RESIDUAL_PX = np.array([0.78, 0.72, 1.10, 0.49, 0.53])


def _load(shared_data: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    folder = shared_data / "zhang1998"
    model = np.loadtxt(folder / "Model.txt").reshape(-1, 2)
    uv = np.array([np.loadtxt(folder / f"data{i}.txt").reshape(-1, 2) for i in range(1, 6)])
    numbers = np.array((folder / "completecalibration.txt").read_text().split(), dtype=float)
    per_image = numbers[7:].reshape(5, 12)
    return model, uv, per_image[:, :9].reshape(5, 3, 3), per_image[:, 9:]


def _residual_distances(model: np.ndarray, uv: np.ndarray, cam: Camera) -> np.ndarray:
    X = np.column_stack([model, np.zeros(len(model))])
    return np.asarray(np.linalg.norm(uv - cam.project(X), axis=1))


def test_published_answer_is_opencv_radial_model(shared_data: Path) -> None:
    """Zhang's radial k1, k2 on ideal normalised coordinates are OpenCV's k1, k2."""
    model, uv, Rs, ts = _load(shared_data)
    for v in range(5):
        u, _, vt = np.linalg.svd(Rs[v])  # printed to 6 digits: re-orthonormalise
        cam = Camera(PUBLISHED_K, PUBLISHED_DIST, u @ vt, ts[v], SIZE)
        d = _residual_distances(model, uv[v], cam)
        assert abs(d.mean() - MEAN_RESIDUAL_PX[v]) < 0.01
        assert abs(d.max() - MAX_RESIDUAL_PX[v]) < 0.01


def test_with_skew_reproduces_published_calibration(shared_data: Path) -> None:
    model, uv, Rs, ts = _load(shared_data)
    result = calibrate_intrinsics(model, uv, SIZE, skew=True)
    K = result.camera.K
    assert_allclose(K[[0, 1], [0, 1]], PUBLISHED_K[[0, 1], [0, 1]], rtol=1e-4)
    assert_allclose(K[:2, 2], PUBLISHED_K[:2, 2], atol=0.05)
    assert abs(K[0, 1] - PUBLISHED_K[0, 1]) < 0.01
    assert_allclose(result.camera.dist[:2], PUBLISHED_DIST[:2], rtol=1e-3)
    assert np.all(result.camera.dist[2:] == 0.0)
    assert_allclose(result.rotations, Rs, atol=2e-4)
    assert_allclose(result.translations, ts, atol=2e-3)
    for v in range(5):
        cam = Camera(K, result.camera.dist, result.rotations[v], result.translations[v], SIZE)
        d = _residual_distances(model, uv[v], cam)
        assert d.mean() <= MEAN_RESIDUAL_PX[v] + 0.005
        assert d.max() <= MAX_RESIDUAL_PX[v] + 0.02
        assert_allclose(np.linalg.norm(result.residuals[v], axis=1), d, atol=1e-9)
    assert result.rms_px == pytest.approx(np.sqrt(np.mean(np.sum(result.residuals**2, -1))))
    # The camera is posed at the first view.
    assert_allclose(result.camera.R, result.rotations[0])
    assert_allclose(result.camera.t, result.translations[0])


def test_zero_skew_default_within_one_percent(shared_data: Path) -> None:
    model, uv, Rs, ts = _load(shared_data)
    result = calibrate_intrinsics(model, uv, SIZE)
    K = result.camera.K
    assert K[0, 1] == 0.0
    assert_allclose(K[[0, 1], [0, 1]], PUBLISHED_K[[0, 1], [0, 1]], rtol=0.01)
    assert_allclose(K[:2, 2], PUBLISHED_K[:2, 2], atol=2.0)
    assert_allclose(result.camera.dist[:2], PUBLISHED_DIST[:2], rtol=0.01)
    assert_allclose(result.rotations, Rs, atol=1e-3)
    assert_allclose(result.translations, ts, atol=0.01)
    assert np.all(result.view_rms_px < 0.6)
    # The closed form (distortion ignored) is the right start, not the answer.
    assert_allclose(result.linear_K[[0, 1], [0, 1]], K[[0, 1], [0, 1]], rtol=0.06)
    assert set(result.std) == {"fx", "fy", "cx", "cy", "k1", "k2"}
    assert 0.1 < result.std["fx"] < 5.0


def test_all_five_distortion_terms_stay_small(shared_data: Path) -> None:
    """Zhang's lens needs only k1, k2: freeing p1, p2, k3 must not change the answer much."""
    model, uv, _, _ = _load(shared_data)
    base = calibrate_intrinsics(model, uv, SIZE)
    full = calibrate_intrinsics(model, uv, SIZE, distortion=True)
    assert full.rms_px <= base.rms_px
    assert np.all(np.abs(full.camera.dist[2:4]) < 2e-3)
    assert_allclose(full.camera.K, base.camera.K, rtol=0.01, atol=2.0)
