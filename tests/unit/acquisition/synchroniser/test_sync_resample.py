"""Resampling one stream: accuracy, runs, gaps, ends, bad input."""

from __future__ import annotations

import importlib

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.interpolate import CubicSpline

from spotlab.acquisition.synchroniser import (
    LOST_FRAMES,
    MISSING,
    OUTSIDE,
    TIME_GAP,
    resample,
)
from spotlab.core import SynchronisationError


def irregular_times(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return 0.3 + np.cumsum(rng.uniform(0.008, 0.012, n))


def test_one_run_equals_scipy_not_a_knot_cubic_spline() -> None:
    t = irregular_times(40)
    rng = np.random.default_rng(1)
    y = rng.normal(size=(40, 3, 2))
    u = np.sort(rng.uniform(t[0], t[-1], 200))
    r = resample(t, y, u)
    assert r.values.shape == (200, 3, 2) and r.flags.shape == (200, 3, 2)
    assert np.all(r.valid)
    assert_allclose(r.values, CubicSpline(t, y, axis=0)(u), atol=1e-11)


def test_cubic_reproduced_exactly_with_per_marker_offsets_and_trailing_axes() -> None:
    t = irregular_times(30)
    off = np.array([50e-6, 6.35e-3, 12.75e-3])

    def p(x: np.ndarray) -> np.ndarray:
        return 3.0 - 2.0 * x + 5.0 * x**2 - 7.0 * x**3

    ts = t[:, None] + off[None, :]  # (F, M) sample times
    y = np.stack([p(ts), 2.0 * p(ts), -p(ts)], axis=-1)[:, :, None, :]  # (F, M, 1, 3)
    u = np.linspace(t[0] + 0.013, t[-1], 97)
    r = resample(t, y, u, offsets=off)
    assert np.all(r.valid)
    want = np.stack([p(u), 2.0 * p(u), -p(u)], axis=-1)
    assert_allclose(r.values[:, :, 0, :], np.broadcast_to(want[:, None, :], (97, 3, 3)), atol=1e-9)


def test_without_the_offsets_a_moving_signal_is_late_by_the_offset() -> None:
    t = np.arange(50) / 100.0
    off = np.array([0.0, 0.005])
    y = (t[:, None] + off) * 1000.0  # mm, 1 m/s, sampled at slot times
    u = t[5:45]
    good = resample(t, y, u, offsets=off).values
    bad = resample(t, y, u).values
    assert_allclose(good, np.broadcast_to(u[:, None] * 1000.0, good.shape), atol=1e-9)
    assert_allclose(bad[:, 1] - u * 1000.0, 5.0, atol=1e-9)


def test_never_across_lost_frames_and_each_side_as_if_alone() -> None:
    t = np.arange(40) / 100.0
    seq = np.arange(40)
    seq[20:] += 3  # three frames lost between frame 19 and 20
    t[20:] += 0.03
    y = np.sin(7.0 * t)[:, None] + np.cos(3.0 * t)[:, None] * np.array([1.0, 2.0])
    u = np.linspace(t[0], t[-1], 301)
    r = resample(t, y, u, seq=seq)
    inside = (u > t[19]) & (u < t[20])
    assert inside.any()
    assert np.all(r.flags[inside] == LOST_FRAMES)
    assert np.all(np.isnan(r.values[inside]))
    assert np.all(r.valid[~inside])
    left, right = u <= t[19], u >= t[20]
    assert_allclose(r.values[left], resample(t[:20], y[:20], u[left]).values, atol=1e-12)
    assert_allclose(r.values[right], resample(t[20:], y[20:], u[right]).values, atol=1e-12)
    assert_array_equal(r.frame_gaps[19], LOST_FRAMES)


def test_time_jump_is_a_gap_only_beyond_max_interval() -> None:
    t = np.arange(30) / 100.0
    t[15:] += 0.05  # stall: seq is contiguous
    y = t[:, None] ** 2
    u = np.array([0.135, 0.17, 0.215])
    r = resample(t, y, u, max_interval_s=0.015)
    assert r.flags[:, 0].tolist() == [0, TIME_GAP, 0]
    assert np.isnan(r.values[1, 0])
    assert np.all(resample(t, y, u).valid)  # default: no interval is too long


def test_nan_run_in_one_channel_leaves_the_others_untouched() -> None:
    t = irregular_times(60, seed=3)
    y = np.stack([np.sin(5 * t), np.cos(5 * t), t**2], axis=1)
    y_nan = y.copy()
    y_nan[25:31, 1] = np.nan
    u = np.linspace(t[0], t[-1], 400)
    full = resample(t, y, u)
    r = resample(t, y_nan, u)
    hole = (u > t[24]) & (u < t[31])
    assert np.all(r.flags[hole, 1] == MISSING) and np.all(np.isnan(r.values[hole, 1]))
    assert np.all(r.valid[~hole, 1])
    assert_array_equal(r.values[:, [0, 2]], full.values[:, [0, 2]])
    after = u >= t[31]
    assert_allclose(r.values[after, 1], resample(t[31:], y[31:, 1:2], u[after]).values[:, 0])
    # And close to the truth away from the hole.
    ok = r.valid[:, 1]
    assert_allclose(r.values[ok, 1], np.cos(5 * u[ok]), atol=1e-6)


def test_ends_are_not_extrapolated_and_samples_are_reproduced() -> None:
    t = irregular_times(12)
    off = np.array([0.0, 0.004])
    y = np.random.default_rng(2).normal(size=(12, 2))
    u = np.array([t[0] - 1e-6, t[0], t[0] + 0.004, t[-1], t[-1] + 0.004, t[-1] + 0.0041])
    r = resample(t, y, u, offsets=off)
    assert r.flags[:, 0].tolist() == [OUTSIDE, 0, 0, 0, OUTSIDE, OUTSIDE]
    assert r.flags[:, 1].tolist() == [OUTSIDE, OUTSIDE, 0, 0, 0, OUTSIDE]
    assert_allclose(r.values[[1, 3], 0], y[[0, -1], 0], atol=1e-12)
    assert_allclose(r.values[[2, 4], 1], y[[0, -1], 1], atol=1e-12)


def test_short_runs_line_and_parabola() -> None:
    t = np.arange(12) / 10.0
    y = np.full((12, 2), np.nan)
    y[2:4, 0] = 4.0 * t[2:4] - 1.0  # two samples: a line
    y[6:9, 1] = 3.0 * t[6:9] ** 2 - t[6:9]  # three samples: a parabola
    y[0, 0] = 7.0  # an isolated sample spans no interval: given at its own time only
    u = np.linspace(0.0, 1.1, 221)
    r = resample(t, y, u)
    line = (u >= t[2]) & (u <= t[3])
    par = (u >= t[6]) & (u <= t[8])
    assert_array_equal(r.valid[:, 0], line | (u == t[0]))
    assert r.values[0, 0] == 7.0
    assert_array_equal(r.valid[:, 1], par)
    assert_allclose(r.values[line, 0], 4.0 * u[line] - 1.0, atol=1e-12)
    assert_allclose(r.values[par, 1], 3.0 * u[par] ** 2 - u[par], atol=1e-12)


def test_stream_without_markers_and_no_instants() -> None:
    t = np.arange(5) / 10.0
    r = resample(t, np.zeros((5, 0, 4, 3)), np.array([0.1, 0.2]))
    assert r.values.shape == (2, 0, 4, 3)
    r = resample(t, np.zeros((5, 2)), np.array([]))
    assert r.values.shape == (0, 2)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"frame_times": [0.0, 0.2, 0.1]}, "frame times do not increase"),
        ({"seq": np.array([0, 1, 0])}, "seq does not increase"),
        ({"values": np.zeros((4, 2))}, "shape \\(F, M, ...\\) with F = 3"),
        ({"values": np.zeros(3)}, "shape \\(F, M, ...\\)"),
        ({"frame_times": [], "values": np.zeros((0, 2))}, "at least 2 frames"),
        ({"instants": np.array([0.1, np.nan])}, "instants must be finite"),
        ({"instants": np.zeros((2, 2))}, "instants must be finite"),
        ({"offsets": np.zeros(3)}, "offsets must be finite, shape \\(2,\\)"),
        ({"offsets": np.array([0.0, np.nan])}, "offsets must be finite"),
        ({"max_interval_s": -1.0}, "largest frame interval"),
    ],
)
def test_bad_input_raises_a_named_error(kwargs: dict[str, object], match: str) -> None:
    args: dict[str, object] = {
        "frame_times": [0.0, 0.1, 0.2],
        "values": np.zeros((3, 2)),
        "instants": np.array([0.05]),
    }
    args.update(kwargs)
    with pytest.raises(SynchronisationError, match=match):
        resample(**args)  # type: ignore[arg-type]


def test_markers_in_blocks_give_the_same_result(monkeypatch: pytest.MonkeyPatch) -> None:
    module = importlib.import_module("spotlab.acquisition.synchroniser.resample")

    t = irregular_times(30, seed=4)
    y = np.random.default_rng(4).normal(size=(30, 7, 2, 3))
    y[10:14, 2, 1] = np.nan
    off = np.linspace(0.0, 0.005, 7)
    u = np.linspace(t[0], t[-1] + 0.01, 90)
    whole = resample(t, y, u, offsets=off)
    monkeypatch.setattr(module, "_BLOCK", 1)  # one marker per block
    blocks = resample(t, y, u, offsets=off)
    assert_array_equal(blocks.flags, whole.flags)
    assert_array_equal(blocks.values, whole.values)


def test_every_run_is_its_own_not_a_knot_spline() -> None:
    t = irregular_times(40, seed=6)
    rng = np.random.default_rng(6)
    y = rng.normal(size=(40, 2))
    y[[9, 10, 25], 0] = np.nan  # channel 0: runs 0-8, 11-24, 26-39
    y[[4, 20], 1] = np.nan  # channel 1: runs 0-3 (4 samples), 5-19, 21-39
    u = np.sort(rng.uniform(t[0], t[-1], 500))
    r = resample(t, y, u)
    for ch, runs in ((0, [(0, 9), (11, 25), (26, 40)]), (1, [(0, 4), (5, 20), (21, 40)])):
        for a, b in runs:
            inside = (u >= t[a]) & (u <= t[b - 1])
            want = CubicSpline(t[a:b], y[a:b, ch])(u[inside])
            assert_allclose(r.values[inside, ch], want, atol=1e-10)
            assert np.all(r.valid[inside, ch])
