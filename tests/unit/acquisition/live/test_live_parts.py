"""Live pipeline parts: frame matching, latency histogram, PSD readings, results files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spotlab.acquisition.live import (
    FLAG_SATURATED,
    FrameMatcher,
    LatencyStats,
    LiveFrame,
    LslMarkers,
    PointRecorder,
    pixels,
)
from spotlab.core.errors import ConfigurationError, RecordingError
from spotlab.core.streams import StreamSpec
from spotlab.io import read_c3d


def test_matcher_groups_frames_of_one_time_in_any_arrival_order() -> None:
    m = FrameMatcher[str](2, tolerance_s=0.001, max_wait_s=0.01)
    assert m.add(1, 0.0002, "b0") == []
    assert m.add(1, 0.0035, "b1") == []  # b runs ahead: a0 may still come
    assert m.add(0, 0.0, "a0") == [(0.0, ["a0", "b0"])]
    assert m.add(0, 0.0033, "a1") == [(0.0033, ["a1", "b1"])]
    assert m.waiting == 0 and m.incomplete == 0


def test_matcher_hands_out_without_a_stream_that_missed_the_frame() -> None:
    m = FrameMatcher[str](2, tolerance_s=0.001, max_wait_s=0.01)
    m.add(0, 0.0, "a0")
    # b's next frame is later than a0 + tolerance: b lost its frame of 0.0.
    assert m.add(1, 0.0033, "b1") == [(0.0, ["a0", None])]
    assert m.incomplete == 1 and m.waiting == 1
    assert m.add(0, 0.0033, "a1") == [(0.0033, ["a1", "b1"])]


def test_matcher_stops_waiting_for_a_stalled_stream() -> None:
    m = FrameMatcher[int](2, tolerance_s=0.001, max_wait_s=0.01)
    out = [g for k in range(4) for g in m.add(0, k * 0.0033, k)]
    assert out == [] and m.waiting == 4  # 0.0099 is not more than 0.01 after 0
    # 0.0132 is: frame 0 goes out alone, stream 1 counts as stalled, nothing waits.
    assert [g for _, g in m.add(0, 0.0132, 4)] == [[k, None] for k in range(5)]
    assert [g for _, g in m.add(0, 0.0165, 5)] == [[5, None]]
    # Stream 1 delivers again: it is waited for again.
    assert m.add(1, 0.0198, 100) == []
    assert [g for _, g in m.add(0, 0.0198, 6)] == [[6, 100]]
    assert m.incomplete == 6
    m.add(0, 0.0231, 7)
    assert [g for _, g in m.flush()] == [[7, None]]
    assert m.add(0, 0.0100, 9) == [] and m.late == 1  # not after its stream's last frame


def test_matcher_configuration_errors() -> None:
    with pytest.raises(ConfigurationError, match="at least one stream"):
        FrameMatcher[int](0, 0.001, 0.01)
    with pytest.raises(ConfigurationError, match="positive"):
        FrameMatcher[int](2, 0.0, 0.01)
    assert FrameMatcher.default_tolerances([300.0, 1.0]) == (0.25, 3.0)
    assert FrameMatcher.default_tolerances([300.0]) == (0.25 / 300.0, 0.1)


def test_latency_percentiles_from_the_histogram() -> None:
    stats = LatencyStats()
    assert np.isnan(stats.summary().p50_us)
    for us in range(1, 101):  # 1 .. 100 us
        stats.add(us * 1000 - 500)
    stats.add(-20)  # a stamp before the arrival counts as 0
    stats.add(2_500_000)
    s = stats.summary()
    assert s.frames == 102 and s.over_1ms == 1
    assert s.p50_us == 50.0  # the 51st of 102 is 49.5 us: the upper edge of its bin
    assert s.p99_us == 100.0
    assert s.max_us == 2500.0
    assert s.mean_us == pytest.approx((sum(u * 1000 - 500 for u in range(1, 101)) + 2.5e6) / 102e3)
    small = LatencyStats(bin_ns=1000, range_ns=10_000)
    small.add(50_000_000)
    assert small.summary().p99_us == 11.0 and small.max_ns == 50_000_000
    with pytest.raises(ConfigurationError, match="histogram"):
        LatencyStats(bin_ns=0)


def test_pixels_apply_the_psd_rule_only_to_detector_counts() -> None:
    data = np.full((1, 3, 2, 3), 1000.0)  # F, M, S, V
    data[0, 1, 0, 0] = 0.0  # clipped
    data[0, 2, 1, :2] = np.nan  # not valid
    flags = np.zeros((1, 3, 2), np.uint8)
    flags[0, 0, 1] = FLAG_SATURATED
    counts = StreamSpec("s", "image2d", 2, 3, 70.0, 1e6, 1e-4, ("x", "y", "i"), ("count",) * 3)
    uv = pixels(counts, data, flags)
    assert uv.shape == (1, 2, 3, 2)  # F, S, M, 2
    nan = np.isnan(uv[0, :, :, 0])
    assert nan.tolist() == [[False, True, False], [True, False, True]]
    video = StreamSpec("v", "image2d", 2, 3, 70.0, 1e6, None, ("x", "y", "i"), ("px",) * 3)
    assert np.isnan(pixels(video, data, flags)[0, :, :, 0]).tolist() == [
        [False, False, False],
        [False, False, True],
    ]


def _frame(i: int, m: int = 3) -> LiveFrame:
    rng = np.random.default_rng(i)
    points = rng.normal(0.0, 100.0, (m, 3))
    points[i % m] = np.nan
    return LiveFrame(
        index=i,
        seq=10 + i,
        frame_time_s=i / 100.0,
        time_s=i / 100.0 + np.arange(m) * 1e-4,
        points=points,
        residual_px=np.full(m, 0.1),
        n_views=np.full(m, 4),
        arrival_ns=1000 * i,
    )


def test_point_recorder_writes_npz_and_c3d(tmp_path: Path) -> None:
    rec = PointRecorder()
    with pytest.raises(ConfigurationError, match="no frame"):
        rec.arrays()
    for i in range(5):
        rec(_frame(i))
    arrays = rec.arrays()
    assert arrays["points"].shape == (5, 3, 3) and arrays["seq"].tolist() == [10, 11, 12, 13, 14]
    saved = np.load(rec.save(tmp_path / "live.npz"))
    np.testing.assert_array_equal(saved["points"], arrays["points"])
    np.testing.assert_array_equal(saved["time_s"], arrays["time_s"])
    trial = read_c3d(rec.save(tmp_path / "live.c3d"))
    assert trial.point_rate == pytest.approx(100.0)
    np.testing.assert_allclose(trial.points, arrays["points"], atol=1e-3)  # float32 in C3D
    with pytest.raises(RecordingError, match=r"\.npz or \.c3d"):
        rec.save(tmp_path / "live.csv")


def test_lsl_consumer_pushes_the_frame_time_and_points() -> None:
    pushed: list[tuple[np.ndarray, np.ndarray]] = []

    class Outlet:
        def push_markers(self, time_s: np.ndarray, X: np.ndarray) -> None:
            pushed.append((time_s, X))

    frame = _frame(2)
    LslMarkers(Outlet())(frame)
    assert pushed[0][0].tolist() == [0.02]
    assert pushed[0][1] is frame.points
