"""Sample times with slot offsets, frame checks and gap flags."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from spotlab.acquisition.synchroniser import (
    LOST_FRAMES,
    TIME_GAP,
    check_frames,
    frame_gaps,
    sample_offsets,
    sample_times,
    valid_runs,
)
from spotlab.core import StreamSpec, SynchronisationError


def spec(slot: float | None, m: int = 128) -> StreamSpec:
    return StreamSpec("sel", "image2d", 4, m, 75.0, 1e6, slot_period_s=slot)


def test_slot_offsets_are_half_a_slot_past_each_led_slot_start() -> None:
    off = sample_offsets(spec(100e-6))
    assert off.shape == (128,)
    assert_allclose(off[[0, 63, 127]], [50e-6, 6.35e-3, 12.75e-3], rtol=0, atol=1e-15)
    assert_allclose(np.diff(off), 100e-6, rtol=0, atol=1e-15)


def test_clock_rate_scales_the_offsets() -> None:
    off = sample_offsets(spec(100e-6), clock_rate=1 + 200e-6)
    assert off[127] == pytest.approx(12.75e-3 * (1 + 200e-6), rel=1e-12)


def test_sample_times_per_marker_for_multiplexed_streams_per_frame_otherwise() -> None:
    t = np.array([1.0, 1.0 + 1 / 75])
    st = sample_times(t, spec(100e-6))
    assert st.shape == (2, 128)
    assert_allclose(st[:, 10], t + 10.5e-4, rtol=0, atol=1e-12)
    plain = sample_times(t, spec(None))
    assert plain.shape == (2,)
    assert_array_equal(plain, t)
    assert_array_equal(sample_offsets(spec(None)), np.zeros(128))


@pytest.mark.parametrize("bad", [np.zeros((2, 2)), np.array([0.0, np.nan])])
def test_sample_times_refuse_bad_frame_times(bad: np.ndarray) -> None:
    with pytest.raises(SynchronisationError, match="frame times"):
        sample_times(bad, spec(100e-6))


@pytest.mark.parametrize("rate", [0.0, -1.0, np.inf, np.nan])
def test_sample_offsets_refuse_bad_clock_rate(rate: float) -> None:
    with pytest.raises(SynchronisationError, match="clock rate"):
        sample_offsets(spec(100e-6), clock_rate=rate)


def test_frame_gaps_flag_lost_frames_and_long_intervals() -> None:
    seq, t = check_frames([0, 1, 2, 5, 6, 7], [0.0, 0.01, 0.02, 0.05, 0.06, 0.1])
    g = frame_gaps(seq, t, max_interval_s=0.015)
    assert_array_equal(g, [0, 0, LOST_FRAMES, 0, TIME_GAP])
    # Lost frames that do not explain the whole interval: a stall as well.
    g = frame_gaps(seq, t, max_interval_s=0.009)
    assert_array_equal(g, [TIME_GAP, TIME_GAP, LOST_FRAMES | TIME_GAP, TIME_GAP, TIME_GAP])
    assert_array_equal(frame_gaps(seq, t, np.inf), [0, 0, LOST_FRAMES, 0, 0])
    with pytest.raises(SynchronisationError, match="> 0"):
        frame_gaps(seq, t, 0.0)


@pytest.mark.parametrize(
    ("seq", "times", "match"),
    [
        ([0, 1, 1], [0.0, 0.1, 0.2], "seq does not increase at frame 2"),
        ([0, 2, 1], [0.0, 0.1, 0.2], "seq does not increase at frame 2"),
        ([0, 1, 2], [0.0, 0.2, 0.1], "frame times do not increase at frame 2"),
        ([0, 1, 2], [0.0, 0.1, 0.1], "frame times do not increase"),
        ([0, 1, 2], [0.0, np.inf, 0.3], "frame 1 is not finite"),
        ([0, 1], [0.0, 0.1, 0.2], "shape"),
        ([], [], "at least 2 frames"),
        ([0], [0.0], "at least 2 frames"),
        ([0.0, 1.0], [0.0, 0.1], "integers"),
    ],
)
def test_check_frames_names_the_cause(seq: list[float], times: list[float], match: str) -> None:
    with pytest.raises(SynchronisationError, match=match):
        check_frames(np.asarray(seq), times)


def test_valid_runs_per_column_never_join_columns() -> None:
    m = np.array([[True, False], [True, True], [False, True], [True, True]])
    assert valid_runs(m).tolist() == [[0, 0, 2], [0, 3, 4], [1, 1, 4]]
    assert valid_runs(np.zeros(5, dtype=bool)).shape == (0, 3)
    assert valid_runs(np.ones(3, dtype=bool)).tolist() == [[0, 0, 3]]
    with pytest.raises(SynchronisationError, match="shape"):
        valid_runs(np.ones((2, 2, 2), dtype=bool))
