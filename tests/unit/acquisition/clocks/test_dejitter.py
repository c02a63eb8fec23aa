"""Host arrival stamps: recursive line fit with forgetting (liblsl's dejitter)."""

from __future__ import annotations

import numpy as np
import pytest

from spotlab.acquisition.clocks import ArrivalDejitter, dejitter_arrivals
from spotlab.acquisition.clocks.synthetic import SyntheticClock, arrival_times, frame_times
from spotlab.core.errors import ClockError


def test_exponential_queueing_leaves_the_mean_delay_as_bias():
    clock = SyntheticClock(offset_s=9.0, drift_ppm=-500.0)
    t = frame_times(6000, 100.0, seed=2)
    arrivals = arrival_times(t, latency_s=200e-6, mean_queue_s=1e-3, seed=5)
    result = dejitter_arrivals(clock.ticks(t), arrivals, clock.tick_hz)
    err = result.times_s - t
    late = err[3000:]  # after the fit has settled
    # the line passes through the mean delay (latency + mean queueing = 1.2 ms) ...
    assert np.mean(late) == pytest.approx(1.2e-3, abs=0.1e-3)
    # ... and removes most of the jitter: the raw delays have SD 1 ms
    assert np.std(late) < 0.1e-3
    assert result.model.drift_ppm == pytest.approx(-500.0, abs=10.0)
    assert result.model.jitter_s == pytest.approx(1e-3, rel=0.5)


def test_online_blocks_equal_offline():
    clock = SyntheticClock(drift_ppm=120.0)
    t = frame_times(500, 100.0, seed=2)
    arrivals = arrival_times(t, seed=6)
    ticks = clock.ticks(t)
    offline = dejitter_arrivals(ticks, arrivals, clock.tick_hz).times_s
    est = ArrivalDejitter(clock.tick_hz)
    online = np.concatenate(
        [est.update(ticks[i : i + 64], arrivals[i : i + 64]) for i in range(0, 500, 64)]
    )
    np.testing.assert_allclose(online, offline, rtol=0, atol=1e-12)


def test_large_step_restarts_the_fit():
    clock = SyntheticClock(drift_ppm=50.0, steps=[(20.0, 0.05)])
    t = frame_times(4000, 100.0, seed=2)
    arrivals = arrival_times(t, mean_queue_s=0.5e-3, seed=7)
    result = dejitter_arrivals(clock.ticks(t), arrivals, clock.tick_hz)
    (event,) = result.model.events
    assert event.kind == "step"
    assert event.size_s == pytest.approx(0.05, abs=2e-3)


def test_bad_arrivals_raise():
    with pytest.raises(ClockError, match="backwards"):
        dejitter_arrivals(np.array([0, 10, 5, 20]), np.arange(4) * 0.01, 1e6)
    with pytest.raises(ClockError, match="NaN"):
        dejitter_arrivals(np.array([0, 10, 20]), np.array([0.0, np.nan, 0.02]), 1e6)
    with pytest.raises(ClockError, match="half-life"):
        ArrivalDejitter(1e6, half_life_s=0.0)
