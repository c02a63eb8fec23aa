"""The bench's timing figures from stamps with a known clock, jitter and latency."""

from __future__ import annotations

import numpy as np
import pytest

from spotlab.bench.timing import FrameStamps, clock_fit, percentiles_us, stream_figures


def _stamps(n: int = 2000, drift_ppm: float = 50.0, jitter_ns: float = 0.0) -> FrameStamps:
    rng = np.random.default_rng(1)
    ticks = np.arange(n, dtype=np.int64) * 5000  # 200 Hz on a 1 MHz counter
    host_s = 3.0 + (ticks / 1e6) * (1 + drift_ppm * 1e-6)
    arrival = np.round(host_s * 1e9 + rng.uniform(0, jitter_ns, n)).astype(np.int64)
    delivered = arrival + 250_000  # 250 us each
    return FrameStamps(ticks, 1e6, arrival, delivered)


def test_drift_offset_and_jitter_of_a_known_clock() -> None:
    drift, offset, residual = clock_fit(_stamps(drift_ppm=50.0))
    assert drift == pytest.approx(50.0, abs=0.01)
    assert offset == pytest.approx(3.0, abs=1e-6)
    assert np.abs(residual).max() < 5.0  # ns: rounding only


def test_late_arrivals_do_not_bend_the_clock() -> None:
    s = _stamps(drift_ppm=-20.0, jitter_ns=20_000.0)
    late = s.arrival_ns.copy()
    late[::50] += 5_000_000  # every 50th frame read 5 ms late
    drift, _, _ = clock_fit(FrameStamps(s.ticks, s.tick_hz, late, s.delivered_ns))
    assert drift == pytest.approx(-20.0, abs=3.0)


def test_stream_figures() -> None:
    s = _stamps(n=1001)
    f = stream_figures(s, 5.0, 200.0, data_bytes=100_000, line_bits_per_s=2e6)
    assert f["frames"] == 1001
    assert f["rate_hz"] == pytest.approx(200.0 / (1 + 50e-6), rel=1e-6)
    assert f["latency_p50_us"] == f["latency_max_us"] == 250.0
    assert f["line_use"] == pytest.approx(100_000 * 10 / 5.0 / 2e6)
    assert f["jitter_rms_us"] == pytest.approx(0.0, abs=0.01)


def test_no_frames_gives_no_figures_rather_than_an_error() -> None:
    empty = np.zeros(0, np.int64)
    f = stream_figures(FrameStamps(empty, 1e6, empty, empty), 1.0, 100.0, 0, None)
    assert f["frames"] == 0 and f["latency_p50_us"] is None and f["line_use"] is None
    assert f["clock_drift_ppm"] is None
    assert percentiles_us(empty)["p99_us"] is None
