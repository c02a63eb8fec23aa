"""rigid_fit / rigid_pose: exact recovery, noise, reflection guard, weights, missing markers."""

from __future__ import annotations

import doctest

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from spotlab.core.errors import ReconstructionError
from spotlab.reconstruction import rigid
from spotlab.reconstruction.rigid import rigid_fit, rigid_pose

MODEL = np.array(
    [[0.0, 0.0, 0.0], [120.0, 0.0, 0.0], [0.0, 80.0, 0.0], [30.0, 20.0, 60.0], [-40.0, 50.0, 10.0]]
)


def _truth(n_frames: int, seed: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    R = Rotation.random(n_frames, random_state=seed).as_matrix()
    t = rng.uniform(-1000.0, 1000.0, (n_frames, 3))
    return R, t, np.einsum("fij,pj->fpi", R, MODEL) + t[:, None, :]


def test_exact_poses_are_recovered() -> None:
    R, t, obs = _truth(50)
    Rf, tf, rms = rigid_fit(MODEL, obs)
    assert Rf.shape == (50, 3, 3) and tf.shape == (50, 3) and rms.shape == (50,)
    assert_allclose(Rf, R, atol=1e-12)
    assert_allclose(tf, t, atol=1e-9)
    assert np.all(rms < 1e-9)
    assert_allclose(np.linalg.det(Rf), 1.0)


def test_noise_gives_rms_of_the_noise_floor() -> None:
    # RMS of 3-D distances with P markers and 6 fitted parameters: sigma^2 (3P - 6) / P
    R, t, obs = _truth(400, seed=3)
    sigma = 0.5
    noisy = obs + np.random.default_rng(4).normal(0.0, sigma, obs.shape)
    Rf, tf, rms = rigid_fit(MODEL, noisy)
    P = MODEL.shape[0]
    assert_allclose(np.mean(rms**2), sigma**2 * (3 * P - 6) / P, rtol=0.05)
    angle = Rotation.from_matrix(np.swapaxes(Rf, 1, 2) @ R).magnitude()
    # 0.5 mm on markers some 60 mm from their centroid: about 0.5 degrees
    assert np.degrees(np.sqrt(np.mean(angle**2))) < 0.6
    assert np.sqrt(np.mean(np.sum((tf - t) ** 2, axis=1))) < 0.5


def test_planar_body_with_noise_never_returns_a_reflection() -> None:
    # a flat body observed with noise: without the det guard the best orthogonal matrix
    # is sometimes a reflection (Arun et al. 1987); with it R is always proper
    flat = np.array([[0.0, 0, 0], [10, 0, 0], [0, 10, 0], [10, 10, 0]])
    rng = np.random.default_rng(5)
    R = Rotation.random(2000, random_state=6).as_matrix()
    obs = np.einsum("fij,pj->fpi", R, flat) + rng.normal(0.0, 3.0, (2000, 4, 3))
    Rf, _, _ = rigid_fit(flat, obs)
    assert_allclose(np.linalg.det(Rf), 1.0, atol=1e-12)


def test_mirrored_observation_gets_a_rotation_and_a_large_rms() -> None:
    mirrored = MODEL * [1.0, 1.0, -1.0]
    Rf, _, rms = rigid_fit(MODEL, mirrored[None])
    assert_allclose(np.linalg.det(Rf[0]), 1.0)
    assert rms[0] > 10.0


def test_missing_markers_and_degenerate_frames_are_flagged() -> None:
    R, _, obs = _truth(4)
    obs = obs.copy()
    obs[1, [0, 4]] = np.nan  # three left: still fitted
    obs[2, [0, 1, 4]] = np.nan  # two left: NaN pose
    obs[3, :] = obs[3, 0] + np.outer(np.arange(5.0), [1.0, 2.0, 3.0])  # collinear data
    pose = rigid_pose(MODEL, obs)
    assert pose.valid.tolist() == [True, True, False, False]
    assert pose.n_visible.tolist() == [5, 3, 2, 5]
    assert pose.collinear.tolist() == [False, False, False, True]
    assert_allclose(pose.R[1], R[1], atol=1e-12)
    assert np.all(np.isnan(pose.R[2:])) and np.all(np.isnan(pose.t[2:]))
    assert np.all(np.isnan(pose.rms[2:]))
    assert np.isnan(pose.residuals[1, 0]) and pose.residuals[1, 1] < 1e-9


def test_weights_pull_the_fit_towards_trusted_markers() -> None:
    _, _, obs = _truth(1)
    bad = obs.copy()
    bad[0, 0] += [0.0, 0.0, 20.0]  # one marker displaced by 20 mm
    plain = rigid_pose(MODEL, bad)
    weighted = rigid_pose(MODEL, bad, weights=[1e-6, 1.0, 1.0, 1.0, 1.0])
    assert weighted.residuals[0, 1:].max() < 1e-3 < plain.residuals[0, 1:].max()
    assert_allclose(weighted.residuals[0, 0], 20.0, rtol=1e-3)
    # a zero weight equals a missing marker
    zero = rigid_pose(MODEL, bad, weights=np.array([[0.0, 1, 1, 1, 1]]))
    gone = bad.copy()
    gone[0, 0] = np.nan
    assert_allclose(zero.R, rigid_pose(MODEL, gone).R, atol=1e-12)
    assert zero.n_visible[0] == 4


def test_weighted_fit_matches_duplicated_markers() -> None:
    # integer weights equal repeating the marker that many times
    _, _, obs = _truth(3, seed=8)
    noisy = obs + np.random.default_rng(9).normal(0.0, 1.0, obs.shape)
    w = np.array([1.0, 3.0, 1.0, 2.0, 1.0])
    reps = np.repeat(np.arange(5), w.astype(int))
    Rw, tw, _ = rigid_fit(MODEL, noisy, weights=w)
    Rd, td, _ = rigid_fit(MODEL[reps], noisy[:, reps])
    assert_allclose(Rw, Rd, atol=1e-12)
    assert_allclose(tw, td, atol=1e-9)


@pytest.mark.parametrize(
    ("model", "observed", "match"),
    [
        (np.outer(np.arange(4.0), [1.0, 1.0, 0.0]), np.zeros((1, 4, 3)), "collinear"),
        (MODEL[:2], np.zeros((1, 2, 3)), "at least 3"),
        (MODEL, np.full((3, 5, 3), np.nan), "NaN everywhere"),
        (MODEL, np.zeros((5, 3)), "shape"),
        (MODEL, np.zeros((1, 4, 3)), "shape"),
        (MODEL.T, np.zeros((1, 5, 3)), "shape"),
        (np.where(MODEL == 0, np.nan, MODEL), np.zeros((1, 5, 3)), "NaN"),
        (MODEL, np.full((1, 5, 3), np.inf), "infinite"),
        (np.zeros((4, 3)), np.zeros((1, 4, 3)), "collinear"),
    ],
)
def test_degenerate_input_raises_a_named_error(
    model: np.ndarray, observed: np.ndarray, match: str
) -> None:
    with pytest.raises(ReconstructionError, match=match):
        rigid_fit(model, observed)


def test_bad_weights_raise() -> None:
    _, _, obs = _truth(2)
    with pytest.raises(ReconstructionError, match="weights"):
        rigid_fit(MODEL, obs, weights=[1.0, 1.0])
    with pytest.raises(ReconstructionError, match=">= 0"):
        rigid_fit(MODEL, obs, weights=[1.0, -1.0, 1.0, 1.0, 1.0])


def test_docstring_example_runs() -> None:
    failures, tried = doctest.testmod(rigid, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert tried > 0 and failures == 0


def test_package_exports() -> None:
    import spotlab.reconstruction as rec

    for name in ("rigid_fit", "rigid_pose", "fit_body_to_images", "choose_identity"):
        assert name in rec.__all__ and callable(getattr(rec, name))


def test_kabsch_is_rigid_fit_for_one_frame() -> None:
    """The single-frame form gives rigid_fit's pose, noise and a flat body included
    (where the best orthogonal matrix could be a reflection)."""
    rng = np.random.default_rng(7)
    flat = np.array([[0.0, 0, 0], [120, 0, 0], [40, 90, 0]])
    for body in (rng.normal(size=(5, 3)) * 80.0, flat):
        R0 = Rotation.random(random_state=3).as_matrix()
        seen = body @ R0.T + [400.0, -50.0, 900.0] + rng.normal(scale=0.5, size=body.shape)
        R, t = rigid.kabsch(body, seen)
        R1, t1, _ = rigid_fit(body, seen[None])
        assert_allclose(R, R1[0], atol=1e-9)
        assert_allclose(t, t1[0], atol=1e-7)
        assert np.linalg.det(R) == pytest.approx(1.0)
