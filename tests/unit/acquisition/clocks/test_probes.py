"""Probe exchanges (NTP style, minimum round trip per window): what they achieve."""

from __future__ import annotations

import numpy as np
import pytest

from spotlab.acquisition.clocks import fit_probes, min_rtt_per_window, probe_pairs
from spotlab.acquisition.clocks.synthetic import SyntheticClock, frame_times, probe_exchanges
from spotlab.core.errors import ClockError


def test_symmetric_exact_exchange_recovers_the_clock():
    clock = SyntheticClock(tick_hz=1e7, offset_s=42.0, drift_ppm=-300.0)
    log = probe_exchanges(clock, 60.0, up_s=(150e-6, 0.0), down_s=(150e-6, 0.0))
    model = fit_probes(log.t0_s, log.t1_ticks, log.t2_ticks, log.t3_s, clock.tick_hz)
    t = frame_times(600, 10.0)
    assert np.max(np.abs(model(clock.ticks(t)) - t)) < 0.5e-6
    assert model.drift_ppm == pytest.approx(-300.0, abs=0.05)


def test_asymmetric_delays_bias_the_offset_by_half_the_difference():
    # up 100 µs + exp(200 µs), down 300 µs + exp(200 µs): the minimum-RTT probe sees
    # nearly the fixed parts, so the offset is biased by about (100 - 300) / 2 = -100 µs,
    # a bias no exchange can observe
    clock = SyntheticClock(offset_s=5.0, drift_ppm=400.0)
    log = probe_exchanges(clock, 60.0, up_s=(100e-6, 200e-6), down_s=(300e-6, 200e-6), seed=4)
    model = fit_probes(log.t0_s, log.t1_ticks, log.t2_ticks, log.t3_s, clock.tick_hz)
    t = frame_times(600, 10.0)
    err = model(clock.ticks(t)) - t
    assert np.mean(err) == pytest.approx(100e-6, abs=30e-6)  # host time reads late
    assert np.std(err) < 20e-6
    assert model.drift_ppm == pytest.approx(400.0, abs=3.0)


def test_min_rtt_selection_keeps_one_probe_per_window():
    clock = SyntheticClock()
    log = probe_exchanges(clock, 20.0, seed=1)
    pairs = probe_pairs(log.t0_s, log.t1_ticks, log.t2_ticks, log.t3_s, clock.tick_hz)
    keep = min_rtt_per_window(pairs, log.t0_s, window_s=2.0)
    assert keep.size == 10
    for w, i in enumerate(keep):
        burst = slice(8 * w, 8 * w + 8)
        assert pairs.rtt_s[i] == np.min(pairs.rtt_s[burst])
    assert min_rtt_per_window(pairs, log.t0_s, min_probes=9).size == 0


def test_bad_exchanges_raise():
    t0 = np.array([0.0, 1.0, 2.0, 3.0])
    t1 = np.array([10, 20, 30, 40])
    with pytest.raises(ClockError, match="before it was sent"):
        probe_pairs(t0, t1, t1 + 1, t0 - 1e-3, 1e6)
    with pytest.raises(ClockError, match="before receiving"):
        probe_pairs(t0, t1, t1 - 1, t0 + 1e-3, 1e6)
    with pytest.raises(ClockError, match="NaN"):
        probe_pairs(np.array([0.0, np.nan, 2.0]), t1[:3], t1[:3], t0[:3] + 1, 1e6)
    with pytest.raises(ClockError, match="only 1 probe windows"):
        fit_probes(t0[:2].repeat(2), t1, t1 + 1, t0[:2].repeat(2) + 1e-3, 1e6, window_s=2.0)
