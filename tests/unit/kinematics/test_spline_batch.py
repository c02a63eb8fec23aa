"""Many channels in one SmoothingSpline call equal the channel-by-channel fits; smooth_trial."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spotlab.io import Trial, read_trc
from spotlab.kinematics import KinematicsError, SmoothingSpline, smooth_trial
from spotlab.kinematics.gcv import PenalisedSpline, gcv_fit

REL = 1e-9


def _channels(n: int, k: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Uneven sample times and k channels of different signals and noise levels."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.008, 0.012, n))
    freq = rng.uniform(0.2, 2.0, k)
    noise = 10.0 ** rng.uniform(-3.0, -1.0, k)
    y = np.sin(2 * np.pi * freq[None, :] * t[:, None]) * rng.uniform(0.5, 50.0, k)
    return t, y + noise * rng.standard_normal((n, k))


def _close(a: float | np.ndarray, b: float | np.ndarray) -> bool:
    return bool(np.all(np.abs(np.asarray(a) - np.asarray(b)) <= REL * np.abs(np.asarray(b))))


def test_many_channels_with_gaps_equal_the_per_channel_gcv_fits() -> None:
    t, y = _channels(800, 7, seed=4)
    y[100:130, 1] = np.nan  # channels 1 and 2 miss the same samples, 4 others
    y[100:130, 2] = np.nan
    y[::17, 4] = np.nan
    y[:5, 5] = np.nan
    both = SmoothingSpline(t, y)
    for j in range(y.shape[1]):
        keep = np.isfinite(y[:, j])
        col = y[keep, j][:, None]
        # the per-channel search as it runs for one channel (spotlab.kinematics.gcv)
        p, fitted, stats = gcv_fit(PenalisedSpline(t[keep], np.ones(keep.sum()), 3), col, x=t[keep])
        assert _close(both.p[j], p), j
        values = both(t[keep])[:, j]
        scale = np.max(np.abs(fitted))
        assert np.max(np.abs(values - fitted[:, 0])) <= REL * scale, j
        assert _close(both.gcv[j], stats.gcv[0]) and _close(both.msr[j], stats.msr[0])
        assert _close(both.dof[j], stats.dof) and _close(both.variance[j], stats.variance[0])
        assert _close(both.residual_dof[j], keep.sum() - stats.dof)
        # and equal one-channel calls of the same class, derivatives and the gaps too
        alone = SmoothingSpline(t, y[:, j])
        assert _close(both.p[j], alone.p)
        for nu in (0, 2):
            ref = alone(t, nu=nu)
            assert np.max(np.abs(both(t, nu=nu)[:, j] - ref)) <= REL * np.max(np.abs(ref))
    # outside the record: each channel's own natural extension
    outside = np.array([t[0] - 0.5, t[-1] + 0.3])
    for j in range(y.shape[1]):
        ref = SmoothingSpline(t, y[:, j])(outside, nu=1)
        assert np.allclose(both(outside, nu=1)[:, j], ref, rtol=REL, atol=0.0)


@pytest.mark.parametrize("mode", ["fixed", "wood_jennings", "cubic"])
def test_fixed_p_wood_jennings_and_cubic_equal_the_per_channel_fits(mode: str) -> None:
    t, y = _channels(300, 4, seed=9)
    y[40:44, 3] = np.nan
    kwargs: dict[str, object] = {}
    if mode == "fixed":
        kwargs["p"] = 1e-7
    elif mode == "wood_jennings":
        kwargs["sigma"] = np.full(t.size, 0.05)
    else:
        kwargs["degree"] = 3
    both = SmoothingSpline(t, y, **kwargs)  # type: ignore[arg-type]
    for j in range(y.shape[1]):
        alone = SmoothingSpline(t, y[:, j], **kwargs)  # type: ignore[arg-type]
        assert _close(both.p[j], alone.p) and _close(both.dof[j], alone.dof)
        assert _close(both.variance[j], alone.variance)
        ref = alone(t)
        assert np.max(np.abs(both(t)[:, j] - ref)) <= REL * np.max(np.abs(ref))


def test_a_failing_channel_is_one_kinematics_error() -> None:
    t, y = _channels(50, 3, seed=2)
    y[:46, 1] = np.nan  # 4 samples left: too few for a quintic
    with pytest.raises(KinematicsError, match="non-missing samples"):
        SmoothingSpline(t, y)


def test_smooth_trial_is_each_coordinate_smoothed_gaps_kept() -> None:
    rng = np.random.default_rng(5)
    frames, markers = 400, 5
    t = np.arange(frames) / 200.0
    truth = 100.0 * np.sin(2 * np.pi * rng.uniform(0.5, 2.0, (1, markers, 3)) * t[:, None, None])
    points = truth + rng.normal(0.0, 1.0, truth.shape)
    points[50:80, 1] = np.nan
    points[5:, 4] = np.nan  # 5 frames: too few to fit, left as they were
    trial = Trial(points, [f"m{i}" for i in range(markers)], 200.0)
    out = smooth_trial(trial)
    assert out is not trial and out.labels == trial.labels and out.point_rate == 200.0
    assert np.array_equal(np.isnan(out.points), np.isnan(points))
    assert np.array_equal(out.points[:5, 4], points[:5, 4])
    seen = np.isfinite(points[:, :4])
    raw = np.sqrt(np.mean((points[:, :4] - truth[:, :4])[seen] ** 2))
    smooth = np.sqrt(np.mean((out.points[:, :4] - truth[:, :4])[seen] ** 2))
    assert smooth < 0.5 * raw  # 1 mm noise on 0.5-2 Hz motion at 200 Hz
    # every coordinate is its own GCV spline, with the gaps bridged on request
    filled = smooth_trial(trial, fill_gaps=True)
    assert np.all(np.isfinite(filled.points[:, :4]))
    for marker, axis in ((0, 2), (1, 0), (3, 1)):
        col = points[:, marker, axis]
        ref = SmoothingSpline(t, col)(t)
        got = filled.points[:, marker, axis]
        assert np.max(np.abs(got - ref)) <= REL * np.max(np.abs(ref))
        assert np.max(np.abs(truth[60:70, 1, axis] - filled.points[60:70, 1, axis])) < 5.0
    with pytest.raises(KinematicsError, match="point rate"):
        smooth_trial(Trial(points, trial.labels, 0.0))


def test_smooth_trial_of_a_real_walking_trial_equals_per_coordinate_fits(
    shared_data: Path,
) -> None:
    trial = read_trc(shared_data / "opensim_models" / "subject01_walk1.trc")
    out = smooth_trial(trial)
    frames = trial.n_frames
    t = np.arange(frames) / trial.point_rate
    coords = trial.points.reshape(frames, -1)
    assert coords.shape[1] == 123
    got = out.points.reshape(frames, -1)
    worst = 0.0
    for j in range(0, coords.shape[1], 7):  # a spread of markers and axes
        keep = np.isfinite(coords[:, j])
        ref = SmoothingSpline(t, coords[:, j])(t)[keep]
        worst = max(worst, float(np.max(np.abs(got[keep, j] - ref)) / np.max(np.abs(ref))))
    assert worst <= REL
    # smoothing moves a 60 Hz lab trajectory by well under a centimetre
    moved = np.abs(got - coords)[np.isfinite(coords)]
    assert 0.0 < np.median(moved) < 5.0
