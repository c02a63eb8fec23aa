"""Clock models from timer edges: truth within 50 µs (TARGETS.md) under clock faults."""

from __future__ import annotations

import numpy as np
import pytest

from spotlab.acquisition.clocks import EdgeClockEstimator, fit_edges
from spotlab.acquisition.clocks.synthetic import SyntheticClock, frame_times, timer_reference
from spotlab.core.errors import ClockError

TARGET_S = 50e-6
N, RATE = 3000, 100.0  # 30 s at 100 Hz

SCENARIOS = {
    "drift+500": (SyntheticClock(offset_s=123.4, drift_ppm=500.0), []),
    "drift-500": (SyntheticClock(offset_s=-7.0, drift_ppm=-500.0), []),
    "step forward": (SyntheticClock(offset_s=5.0, drift_ppm=200.0, steps=[(15.0, 1e-3)]), ["step"]),
    "step back": (SyntheticClock(offset_s=5.0, drift_ppm=-150.0, steps=[(15.0, -5e-3)]), ["step"]),
    "reset": (SyntheticClock(offset_s=50.0, drift_ppm=100.0, resets=[(15.0, 0.001)]), ["reset"]),
    "wrap glitch": (
        SyntheticClock(offset_s=4000.0, drift_ppm=-300.0, wraps=[(12.0, 1, 32)]),
        ["wrap"],
    ),
}


def scenario(name: str, jitter_s: float = 2e-6):
    clock, kinds = SCENARIOS[name]
    truth = frame_times(N, RATE, seed=7, jitter_s=jitter_s)
    return clock, kinds, truth, clock.ticks(truth), timer_reference(truth)


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_offline_fit_within_target_and_reports_events(name):
    clock, kinds, truth, ticks, ref = scenario(name)
    model = fit_edges(ticks, ref, clock.tick_hz, allow_resets=bool(clock.resets))
    err = model(ticks) - truth
    assert np.max(np.abs(err)) < TARGET_S
    # the floor is the 1 µs device tick (uniform rounding, SD 0.29 µs)
    assert np.sqrt(np.mean(err**2)) < 0.5e-6
    assert [e.kind for e in model.events] == kinds
    assert model.drift_ppm == pytest.approx(clock.drift_ppm, abs=0.2)
    assert model.residuals.shape == ticks.shape
    assert 0.1e-6 < model.jitter_s < 1e-6


@pytest.mark.parametrize(("name", "size"), [("step forward", 1e-3), ("step back", -5e-3)])
def test_step_size_is_measured(name, size):
    clock, _, truth, ticks, ref = scenario(name)
    (event,) = fit_edges(ticks, ref, clock.tick_hz).events
    assert event.size_s == pytest.approx(size, abs=2e-6)
    # the step is placed at the first frame after it
    assert truth[event.index - 1] < 15.0 <= truth[event.index]


def test_wrap_size_is_one_counter_period():
    clock, _, _, ticks, ref = scenario("wrap glitch")
    (event,) = fit_edges(ticks, ref, clock.tick_hz).events
    assert event.size_s * clock.tick_hz == pytest.approx(2**32, abs=2)


def test_single_late_edge_is_not_a_step():
    clock, _, truth, ticks, ref = scenario("drift+500")
    ref = ref.copy()
    ref[1000] += 200e-6
    model = fit_edges(ticks, ref, clock.tick_hz)
    assert model.events == ()
    assert np.max(np.abs(model(ticks) - truth)) < 2e-6


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_online_estimator_matches_offline(name):
    clock, kinds, truth, ticks, ref = scenario(name)
    est = EdgeClockEstimator(clock.tick_hz, allow_resets=bool(clock.resets))
    for lo in range(0, N, 37):
        est.update(ticks[lo : lo + 37], ref[lo : lo + 37])
    model = est.model
    assert np.max(np.abs(model(ticks) - truth)) < TARGET_S
    assert [e.kind for e in est.events] == kinds


def test_online_estimator_needs_pairs_first():
    est = EdgeClockEstimator(1e6)
    with pytest.raises(ClockError, match="too few pairs"):
        _ = est.model
    est.update(np.array([1, 2]), np.array([0.1, 0.2]))
    with pytest.raises(ClockError, match="too few pairs"):
        _ = est.model


def test_online_rejects_backwards_ticks_and_stopped_reference():
    est = EdgeClockEstimator(1e6)
    est.update(np.arange(10) * 10_000, np.arange(10) * 0.01)
    with pytest.raises(ClockError, match="backwards"):
        est.update(np.array([5]), np.array([0.2]))
    est = EdgeClockEstimator(1e6)
    est.update(np.arange(10) * 10_000, np.arange(10) * 0.01)
    with pytest.raises(ClockError, match="does not advance"):
        est.update(np.array([200_000]), np.array([0.09]))


@pytest.mark.parametrize(
    ("ticks", "ref", "match"),
    [
        ([0, 10], [0.0, 1e-5], "at least 3 pairs"),
        ([0, 10, 20, 30], [0.0, np.nan, 2e-5, 3e-5], "NaN"),
        ([0, 10, 5, 30], [0.0, 1e-5, 2e-5, 3e-5], "backwards"),
        ([0, 10, 10, 30], [0.0, 1e-5, 2e-5, 3e-5], "repeat"),
        ([0, 10, 20, 30], [0.0, 1e-5, 1e-5, 1e-5], "does not advance"),
        ([0, 10, 20], [0.0, 1e-5], "equal length"),
        ([0.5, 10, 20], [0.0, 1e-5, 2e-5], "whole numbers"),
    ],
)
def test_bad_input_raises_named_error(ticks, ref, match):
    with pytest.raises(ClockError, match=match):
        fit_edges(np.array(ticks), np.array(ref), 1e6)


def test_reset_with_too_few_pairs_after_it():
    ticks = np.array([100, 200, 300, 400, 10, 20])
    ref = np.arange(6) * 1e-4
    with pytest.raises(ClockError, match="epoch 1"):
        fit_edges(ticks, ref, 1e6, allow_resets=True)
