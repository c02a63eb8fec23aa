"""smac_calibrate on a synthetic ring rig and a planar grid moved through the volume."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from spotlab.calibration import smac_calibrate
from spotlab.core.errors import CalibrationError
from spotlab.geometry import Camera, Rig
from spotlab.simulators.rigs import ring_rig

SIZE = (1280, 1024)


def _scene(
    n_views: int, noise: float, seed: int, n_cameras: int = 4, parallel: bool = False
) -> tuple[Rig, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Ring rig, a 10 x 10 grid of 80 mm pitch at ``n_views`` poses, and its pixels.

    A camera does not see a view held more edge-on than 75 degrees, nor points outside
    its image. Returns the rig, grid (P, 3), grid-to-world R (V, 3, 3), t (V, 3) and the
    pixels (C, V, P, 2).
    """
    rig = ring_rig(n_cameras, radius_mm=3000.0, height_mm=2400.0, seed=seed)
    rng = np.random.default_rng(seed)
    g = (np.arange(10) - 4.5) * 80.0
    grid = np.array([[x, y, 0.0] for y in g for x in g])
    tilt = 0.0 if parallel else 0.8
    Rs = np.array(
        [
            Rotation.from_rotvec([*rng.uniform(-tilt, tilt, 2), rng.uniform(-np.pi, np.pi)])
            .as_matrix()
            .tolist()
            for _ in range(n_views)
        ]
    )
    ts = np.array([0.0, 0.0, 900.0]) + rng.uniform(-400.0, 400.0, (n_views, 3))
    uv = rig.project(np.einsum("vij,pj->vpi", Rs, grid) + ts[:, None])
    for c, cam in enumerate(rig):
        d = cam.center - ts
        cos = np.abs(np.einsum("vi,vi->v", d, Rs[:, :, 2])) / np.linalg.norm(d, axis=1)
        inside = (uv[c] >= 0.0).all(-1) & (uv[c] < SIZE).all(-1)
        uv[c][(cos < np.cos(np.radians(75.0)))[:, None] | ~inside] = np.nan
    return rig, grid, Rs, ts, uv + noise * rng.standard_normal(uv.shape)


def _in_frame(rig: Rig, R: np.ndarray, t: np.ndarray) -> Rig:
    """The rig with the world frame moved to the grid pose ``X = R P + t``."""
    return Rig(Camera(c.K, c.dist, c.R @ R, c.R @ t + c.t, c.size, c.name) for c in rig)


def _triangulate(rig: Rig, uv: np.ndarray) -> np.ndarray:
    """Point nearest to the observed rays (least squares), (N, 3); uv (C, N, 2)."""
    A = np.zeros((uv.shape[1], 3, 3))
    b = np.zeros((uv.shape[1], 3))
    for cam, q in zip(rig, uv, strict=True):
        ok = np.isfinite(q).all(-1)
        xy = cam.normalize(np.where(ok[:, None], q, 0.0))
        d = np.column_stack([xy, np.ones(len(q))]) @ cam.R
        d /= np.linalg.norm(d, axis=1)[:, None]
        M = (np.eye(3) - d[:, :, None] * d[:, None, :]) * ok[:, None, None]
        A += M
        b += M @ cam.center
    return np.linalg.solve(A, b[..., None])[..., 0]


@pytest.mark.parametrize("reference", [0, 5])
def test_noise_free_exact_recovery_in_the_named_pose_frame(reference: int) -> None:
    rig, grid, Rs, ts, uv = _scene(16, 0.0, seed=3)
    result = smac_calibrate(grid, uv, SIZE, distortion=True, reference_view=reference)
    truth = _in_frame(rig, Rs[reference], ts[reference])
    for cam, true in zip(result.rig, truth, strict=True):
        assert_allclose(cam.K, true.K, atol=1e-6)
        assert_allclose(cam.dist, true.dist, atol=1e-9)
        assert_allclose(cam.R, true.R, atol=1e-10)
        assert_allclose(cam.t, true.t, atol=1e-6)
    assert_allclose(result.grid_poses[reference], np.eye(4), atol=1e-15)
    # Every grid pose, expressed in the reference pose's frame.
    R0, t0 = Rs[reference], ts[reference]
    assert_allclose(result.grid_poses[:, :3, :3], np.einsum("ji,vjk->vik", R0, Rs), atol=1e-10)
    assert_allclose(result.grid_poses[:, :3, 3], (ts - t0) @ R0, atol=1e-6)
    assert np.all(result.rms_px < 1e-8)
    assert result.report["reference_view"] == reference
    assert result.report["unused_views"] == []


def test_noisy_grid_reprojection_and_held_out_3d_error_near_the_floor() -> None:
    rig, grid, Rs, ts, uv = _scene(21, 0.2, seed=3)
    result = smac_calibrate(grid, uv[:, :20], SIZE, distortion=True)
    # Distance RMS of 2-D Gaussian noise of 0.2 px per axis: 0.283 px, less the dof used.
    assert np.all((result.rms_px > 0.25) & (result.rms_px < 0.30))
    assert set(result.report["rms_px"]) == {"cam1", "cam2", "cam3", "cam4"}
    for name, initial in result.report["initial_rms_px"].items():
        assert result.report["rms_px"][name] <= initial + 0.01
    truth = _in_frame(rig, Rs[0], ts[0])
    held_out = uv[:, 20]
    assert np.count_nonzero(np.isfinite(held_out).all(-1).any(-1)) >= 2
    X_true = (np.einsum("ij,pj->pi", Rs[20], grid) + ts[20] - ts[0]) @ Rs[0]
    err = np.sqrt(np.mean(np.sum((_triangulate(result.rig, held_out) - X_true) ** 2, -1)))
    floor = np.sqrt(np.mean(np.sum((_triangulate(truth, held_out) - X_true) ** 2, -1)))
    assert err < 1.35 * floor
    for cam, true in zip(result.rig, truth, strict=True):
        assert_allclose(cam.K[[0, 1], [0, 1]], true.K[[0, 1], [0, 1]], rtol=0.01)
        assert np.linalg.norm(cam.center - true.center) < 15.0  # mm, cameras 3 m away


def test_errors() -> None:
    _, grid, _, _, uv = _scene(12, 0.0, seed=3)
    with pytest.raises(CalibrationError, match="at least 2 cameras"):
        smac_calibrate(grid, uv[:1], SIZE)
    few = uv.copy()
    seen = np.flatnonzero(np.isfinite(few[1]).all(-1).any(-1))
    few[1, seen[2:]] = np.nan
    with pytest.raises(CalibrationError, match="camera cam2 sees the grid in 2 usable views"):
        smac_calibrate(grid, few, SIZE)
    nan_grid = grid.copy()
    nan_grid[0, 0] = np.nan
    with pytest.raises(CalibrationError, match="NaN"):
        smac_calibrate(nan_grid, uv, SIZE)
    with pytest.raises(CalibrationError, match=r"shape \(C, V, P, 2\)"):
        smac_calibrate(grid, uv[0], SIZE)
    with pytest.raises(CalibrationError, match="reference_view 12"):
        smac_calibrate(grid, uv, SIZE, reference_view=12)


def test_cameras_that_share_no_view() -> None:
    _, grid, _, _, uv = _scene(12, 0.0, seed=3)
    split = uv.copy()
    split[:2, 6:] = np.nan  # cam1, cam2 see views 0-5 only, cam3, cam4 views 6-11 only
    split[2:, :6] = np.nan
    with pytest.raises(CalibrationError, match=r"cameras \['cam3', 'cam4'\] share no grid view"):
        smac_calibrate(grid, split, SIZE, distortion=False)


def test_parallel_grid_poses() -> None:
    _, grid, _, _, uv = _scene(12, 0.2, seed=3, parallel=True)
    with pytest.raises(CalibrationError, match=r"camera cam1: .*parallel"):
        smac_calibrate(grid, uv, SIZE)
