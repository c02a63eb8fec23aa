"""fit_body_to_images (Woltring 1982) and choose_identity: partial views, ambiguity, errors."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from spotlab.core.errors import ReconstructionError
from spotlab.reconstruction._rigid_identity import choose_identity
from spotlab.reconstruction._rigid_images import fit_body_to_images
from spotlab.reconstruction.rigid import rigid_fit
from spotlab.simulators.rigs import ring_rig

MODEL = np.array(
    [
        [0.0, 0.0, 0.0],
        [120.0, 0.0, 0.0],
        [0.0, 80.0, 0.0],
        [30.0, 20.0, 60.0],
        [-50.0, 40.0, 20.0],
        [60.0, -40.0, -30.0],
    ]
)
RIG = ring_rig()


def _scene(n_frames: int = 12, seed: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    R = Rotation.random(n_frames, random_state=seed).as_matrix()
    t = rng.uniform(-400.0, 400.0, (n_frames, 3)) + np.array([0.0, 0.0, 900.0])
    X = np.einsum("fij,pj->fpi", R, MODEL) + t[:, None, :]
    return R, t, RIG.project(X)


def _one_camera_per_marker(uv: np.ndarray, n_markers: int) -> np.ndarray:
    seen = np.zeros(uv.shape[:-1], dtype=bool)
    for p in range(n_markers):
        seen[p % len(RIG), :, p] = True
    return np.where(seen[..., None], uv, np.nan)


def test_no_marker_seen_twice_still_gives_the_exact_pose() -> None:
    R, t, uv = _scene()
    pose = fit_body_to_images(RIG, MODEL, _one_camera_per_marker(uv, 6))
    assert pose.valid.all()
    assert pose.n_observations.tolist() == [6] * 12
    assert_allclose(pose.R, R, atol=1e-8)
    assert_allclose(pose.t, t, atol=1e-5)
    assert np.all(pose.rms_px < 1e-6)


def test_one_camera_alone_gives_the_exact_pose_without_noise() -> None:
    R, t, uv = _scene(seed=2)
    only_first = np.where(np.arange(len(RIG))[:, None, None, None] == 0, uv, np.nan)
    pose = fit_body_to_images(RIG, MODEL, only_first)
    ok = pose.valid
    assert ok.sum() >= 10  # frames where the body leaves camera 1's view may drop out
    assert_allclose(pose.R[ok], R[ok], atol=1e-7)
    assert_allclose(pose.t[ok], t[ok], atol=1e-4)


def test_noisy_partial_views_reach_the_noise_floor() -> None:
    R, t, uv = _scene(n_frames=30, seed=3)
    noisy = uv + np.random.default_rng(4).normal(0.0, 0.2, uv.shape)
    pose = fit_body_to_images(RIG, MODEL, _one_camera_per_marker(noisy, 6))
    assert pose.valid.all()
    # 12 image coordinates, 6 parameters: RMS image distance near 0.2 sqrt(2) sqrt(6/12)
    assert 0.1 < np.sqrt(np.mean(pose.rms_px**2)) < 0.3
    angle = Rotation.from_matrix(np.swapaxes(pose.R, 1, 2) @ R).magnitude()
    assert np.degrees(np.max(angle)) < 3.0
    assert np.median(np.linalg.norm(pose.t - t, axis=1)) < 3.0


def test_all_views_agree_with_rigid_fit_of_the_true_points() -> None:
    R, t, uv = _scene(seed=5)
    pose = fit_body_to_images(RIG, MODEL, uv)
    X = np.einsum("fij,pj->fpi", R, MODEL) + t[:, None, :]
    Rf, tf, _ = rigid_fit(MODEL, X)
    assert_allclose(pose.R, Rf, atol=1e-8)
    assert_allclose(pose.t, tf, atol=1e-5)


def test_four_rays_need_a_starting_pose_and_converge_from_one() -> None:
    R, t, uv = _scene(seed=6)
    partial = _one_camera_per_marker(uv, 4)[:, :, :4]
    with pytest.raises(ReconstructionError, match="initial"):
        fit_body_to_images(RIG, MODEL[:4], partial)
    start = (Rotation.from_rotvec([0.15, -0.1, 0.1]).as_matrix() @ R, t + 40.0)
    pose = fit_body_to_images(RIG, MODEL[:4], partial, initial=start)
    assert pose.valid.all()
    assert_allclose(pose.R, R, atol=1e-7)


def test_frames_with_too_few_points_are_flagged_not_guessed() -> None:
    _, _, uv = _scene(seed=7)
    uv = uv.copy()
    uv[:, 3, 2:] = np.nan  # frame 3: two markers seen by all cameras (a free axis)
    uv[:, 5, :] = np.nan  # frame 5: nothing
    uv[1:, 6, :] = np.nan  # frame 6: camera 1 only, but all markers: fine
    pose = fit_body_to_images(RIG, MODEL, uv)
    assert pose.valid.tolist() == [i not in (3, 5) for i in range(12)]
    assert np.all(np.isnan(pose.R[[3, 5]])) and np.all(np.isnan(pose.rms_px[[3, 5]]))
    assert pose.n_observations[[3, 5, 6]].tolist() == [16, 0, 6]


def test_image_fit_errors() -> None:
    _, _, uv = _scene(n_frames=2)
    with pytest.raises(ReconstructionError, match="shape"):
        fit_body_to_images(RIG, MODEL, uv[:3])
    with pytest.raises(ReconstructionError, match="NaN everywhere"):
        fit_body_to_images(RIG, MODEL, np.full_like(uv, np.nan))
    with pytest.raises(ReconstructionError, match="Rig"):
        fit_body_to_images(list(RIG), MODEL, uv)  # type: ignore[arg-type]
    with pytest.raises(ReconstructionError, match="collinear"):
        fit_body_to_images(RIG, np.outer(np.arange(6.0), [1, 0, 0]), uv)


def test_identity_is_recovered_from_shuffled_points() -> None:
    R, t, _ = _scene(n_frames=1)
    X = MODEL[:5] @ R[0].T + t[0]
    shuffle = [3, 0, 4, 1, 2]
    noisy = X[shuffle] + np.random.default_rng(8).normal(0.0, 0.3, (5, 3))
    choice = choose_identity(MODEL[:5], noisy)
    # marker p was put at position shuffle.index(p)
    assert choice.assignment == tuple(shuffle.index(p) for p in range(5))
    assert choice.candidates == 120
    assert choice.rms < 1.0 < choice.margin
    assert_allclose(choice.R, R[0], atol=0.02)


def test_extra_and_missing_points() -> None:
    R, t, _ = _scene(n_frames=1, seed=9)
    X = MODEL[:4] @ R[0].T + t[0]
    ghost = np.vstack([X[[1, 2, 3]], X[0] + [300.0, 0.0, 0.0]])  # marker 0 lost, a ghost
    choice = choose_identity(MODEL[:4], ghost, candidates=[(-1, 0, 1, 2), (3, 0, 1, 2)])
    assert choice.assignment == (-1, 0, 1, 2)
    assert choice.margin > 50.0


def test_symmetric_body_is_reported_as_ambiguous() -> None:
    square = np.array([[0.0, 0, 0], [100, 0, 0], [100, 100, 0], [0, 100, 0]])
    choice = choose_identity(square, square[[1, 2, 3, 0]])
    assert choice.rms < 1e-9
    assert choice.margin < 1e-9  # four rotations of the square fit equally well


def test_identity_errors() -> None:
    with pytest.raises(ReconstructionError, match="at least 3"):
        choose_identity(MODEL, MODEL[:2])
    with pytest.raises(ReconstructionError, match="twice"):
        choose_identity(MODEL[:3], MODEL[:3], candidates=[(0, 0, 1)])
    with pytest.raises(ReconstructionError, match="-1 or in"):
        choose_identity(MODEL[:3], MODEL[:3], candidates=[(0, 1, 7)])
    with pytest.raises(ReconstructionError, match="pass the plausible"):
        choose_identity(np.random.default_rng(0).normal(size=(12, 3)), np.zeros((12, 3)))
    with pytest.raises(ReconstructionError, match="no candidate"):
        choose_identity(MODEL[:4], MODEL[:4], candidates=[(0, 1, -1, -1)])
