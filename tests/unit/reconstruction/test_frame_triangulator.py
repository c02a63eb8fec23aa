"""FrameTriangulator: the live path's per-frame triangulation equals triangulate()."""

from __future__ import annotations

import numpy as np
import pytest

from spotlab.core.errors import ReconstructionError
from spotlab.geometry import Camera, Rig
from spotlab.reconstruction import triangulate
from spotlab.reconstruction.frame_triangulator import FrameTriangulator
from spotlab.simulators.rigs import ring_rig


def _scene(seed: int = 0) -> tuple[Rig, np.ndarray, np.ndarray]:
    rig = ring_rig(8)
    rng = np.random.default_rng(seed)
    X = rng.uniform(-600.0, 600.0, (128, 3)) + np.array([0.0, 0.0, 1000.0])
    uv = rig.project(X) + rng.normal(0.0, 0.2, (8, 128, 2))
    return rig, X, uv


def test_points_equal_triangulate_with_unseen_markers() -> None:
    rig, X, uv = _scene()
    uv[2, :10] = np.nan
    uv[1:, 5] = np.nan  # one view only
    uv[3, 7, 1] = np.nan  # half an observation
    got, rms, n_views = FrameTriangulator(rig)(uv)
    want = triangulate(rig, uv)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    assert np.isnan(got[5]).all() and np.isnan(rms[5]) and n_views[5] == 1
    assert n_views[7] == 6 and n_views[0] == 7 and n_views[20] == 8
    ok = np.isfinite(got[:, 0])
    assert np.sqrt(np.mean(np.sum((got[ok] - X[ok]) ** 2, axis=1))) < 2.0  # mm, 0.2 px noise
    # Ray errors of 0.2 px noise: an RMS of the order of the noise.
    assert 0.05 < float(np.nanmedian(rms)) < 0.4


def test_rms_grows_with_a_bad_ray() -> None:
    rig, _, uv = _scene(1)
    tri = FrameTriangulator(rig)
    _, rms0, _ = tri(uv)
    uv[0, 3] += 30.0
    _, rms1, _ = tri(uv)
    assert rms1[3] > 5.0 > rms0[3]
    np.testing.assert_array_equal(rms1[4:], rms0[4:])


def test_skewed_and_undistorted_cameras_take_the_same_result() -> None:
    rig, _, _ = _scene(2)
    cams = list(rig.cameras)
    K = cams[0].K.copy()
    K[0, 1] = 0.5
    cams[0] = Camera(K, cams[0].dist, cams[0].R, cams[0].t, cams[0].size, "skewed")
    cams[1] = Camera(cams[1].K, np.zeros(5), cams[1].R, cams[1].t, cams[1].size, "pinhole")
    mixed = Rig(cams)
    X = np.array([[0.0, 0.0, 900.0], [120.0, -300.0, 1500.0]])
    uv = mixed.project(X)
    np.testing.assert_allclose(FrameTriangulator(mixed)(uv)[0], X, atol=1e-6)
    plain = Rig([cams[1], *rig.cameras[2:]])
    np.testing.assert_allclose(FrameTriangulator(plain)(uv[1:])[0], X, atol=1e-6)


def test_stacked_blobs_normalise_as_the_padded_table() -> None:
    rig, _, uv = _scene(3)
    cams = list(rig.cameras)
    cams[1] = Camera(cams[1].K, np.zeros(5), cams[1].R, cams[1].t, cams[1].size, "pinhole")
    uv[:, :, 0] += np.linspace(-500.0, 500.0, 128)  # some far out: more Newton steps
    rng = np.random.default_rng(3)
    for rig_ in (rig, Rig(cams)):
        tri = FrameTriangulator(rig_)
        for n in (0, 1, 37, 300):
            camera = np.sort(rng.integers(0, 8, n))
            slot = np.zeros(n, dtype=np.intp)
            for c in range(8):
                slot[camera == c] = np.arange(np.sum(camera == c))
            width = max(1, int(slot.max()) + 1 if n else 1)
            pixels = uv.reshape(-1, 2)[rng.integers(0, 8 * 128, n)]
            table = np.full((8, width, 2), np.nan)
            table[camera, slot] = pixels
            x, y, _ = tri.normalize(table)
            got_x, got_y = tri.normalize_slots(pixels, camera, slot, width)
            np.testing.assert_array_equal(got_x, x[camera, slot])  # to the last bit
            np.testing.assert_array_equal(got_y, y[camera, slot])


def test_bad_input_is_refused() -> None:
    rig, _, uv = _scene()
    tri = FrameTriangulator(rig)
    with pytest.raises(ReconstructionError, match="shape"):
        tri(uv[:3])
    with pytest.raises(ReconstructionError, match="shape"):
        tri(uv[:, :, :1])
    uv[0, 0, 0] = np.inf
    with pytest.raises(ReconstructionError, match="infinite"):
        tri(uv)
    with pytest.raises(ReconstructionError, match="Rig"):
        FrameTriangulator("rig")  # type: ignore[arg-type]


def test_observations_outside_the_fitted_start_take_more_newton_steps() -> None:
    rig, _, uv = _scene(3)
    # Beyond the 3 % margin of the start fit: the slow path, camera by camera.
    uv[2, 4] = [-150.0, -120.0]
    uv[5, 9] = [1280.0 + 140.0, 1024.0 + 100.0]
    x, y, seen = FrameTriangulator(rig).normalize(uv)
    assert seen.all()
    for c, n in ((2, 4), (5, 9), (0, 0)):
        want = rig.cameras[c].normalize(uv[c, n][None])[0]
        np.testing.assert_allclose([x[c, n], y[c, n]], want, atol=1e-10)
