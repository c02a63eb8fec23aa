"""Spline refinement of edge-fitted clocks: drift that changes slowly, never across a step."""

from __future__ import annotations

import numpy as np
import pytest

from spotlab.acquisition.clocks import fit_edges, refine_model
from spotlab.acquisition.clocks.synthetic import frame_times, timer_reference
from spotlab.core.errors import ClockError


def warming_clock(step_at: float | None = None):
    """Drift rising from 10 to 30 ppm over 30 s (a crystal warming up), 1 MHz ticks."""
    truth = frame_times(3000, 100.0, seed=3, jitter_s=1e-6)
    device = 3.0 + truth * (1 + 10e-6) + 0.5 * (20e-6 / 30.0) * truth**2
    if step_at is not None:
        device = device + np.where(truth >= step_at, 2e-3, 0.0)
    ticks = np.floor(device * 1e6).astype(np.int64)
    return truth, ticks, timer_reference(truth)


def test_spline_removes_drift_change_the_line_cannot():
    truth, ticks, ref = warming_clock()
    model = fit_edges(ticks, ref, 1e6, min_step_s=1e-4)
    line_err = np.max(np.abs(model(ticks) - truth))
    refined = refine_model(model, ticks, ref, ref_resolution_s=1e-7)
    spline_err = refined(ticks) - truth
    assert line_err > 20e-6  # the straight line misses the curvature by tens of µs
    assert np.max(np.abs(spline_err)) < 2e-6
    assert np.sqrt(np.mean(spline_err**2)) < 0.6e-6


def test_spline_stays_within_segments():
    truth, ticks, ref = warming_clock(step_at=15.0)
    model = fit_edges(ticks, ref, 1e6, min_step_s=1e-4)
    assert [e.kind for e in model.events] == ["step"]
    refined = refine_model(model, ticks, ref, ref_resolution_s=1e-7)
    err = refined(ticks) - truth
    assert np.max(np.abs(err)) < 3e-6
    assert len(refined.splines) == 2 and all(s is not None for s in refined.splines)


def test_refine_rejects_bad_input():
    truth, ticks, ref = warming_clock()
    model = fit_edges(ticks, ref, 1e6, min_step_s=1e-4)
    with pytest.raises(ClockError, match="NaN"):
        refine_model(model, ticks, np.where(truth > 10, np.nan, ref))
    with pytest.raises(ClockError, match=">= 0"):
        refine_model(model, ticks, ref, ref_resolution_s=-1.0)
