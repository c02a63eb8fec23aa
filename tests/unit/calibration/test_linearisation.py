"""fit_linearisation / DetectorLinearisation against the simulator's PSD edge non-linearity."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest
from numpy.testing import assert_allclose

from spotlab.calibration import DetectorLinearisation, fit_linearisation
from spotlab.core.errors import CalibrationError
from spotlab.simulators.psd import HALF_RANGE, PsdModel
from spotlab.simulators.scene import DETECTOR_CENTRE

NOISE = 0.3  # counts, SD per axis of the measured grid


def _psd_response(true: np.ndarray, k: float = PsdModel().pincushion) -> np.ndarray:
    """The simulator's detector model (simulators/psd.py): radial pincushion in p, q."""
    pq = (true - DETECTOR_CENTRE) / HALF_RANGE
    bend = 1.0 + k * np.sum(pq**2, axis=-1, keepdims=True)
    return DETECTOR_CENTRE + HALF_RANGE * pq * bend


def _grid(n: int, margin: float = 150.0) -> np.ndarray:
    g = np.linspace(margin, 2.0 * DETECTOR_CENTRE - margin, n)
    return np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)


def test_fit_removes_the_psd_non_linearity_down_to_the_noise() -> None:
    rng = np.random.default_rng(0)
    true = _grid(17)
    measured = _psd_response(true) + rng.normal(0.0, NOISE, true.shape)
    lin = fit_linearisation(measured, true, order=7)
    noise_rms = NOISE * np.sqrt(2.0)
    assert lin.raw_rms > 50.0 * noise_rms
    assert lin.residual_rms < 1.1 * noise_rms
    # Held-out points between the grid nodes, noise free: the map itself is accurate.
    held_true = rng.uniform(300.0, 3800.0, (2000, 2))
    held = _psd_response(held_true)
    err = np.hypot(*(lin(held) - held_true).T)
    assert np.sqrt(np.mean(err**2)) < 0.3 * noise_rms
    assert err.max() < noise_rms


def test_residual_falls_with_the_order() -> None:
    true = _grid(15)
    measured = _psd_response(true)
    rms = [fit_linearisation(measured, true, order=n).residual_rms for n in (1, 3, 5, 7)]
    assert rms[0] > 10.0
    assert all(b < 0.2 * a for a, b in itertools.pairwise(rms))


def test_an_exact_polynomial_is_recovered_exactly() -> None:
    true = _grid(6, margin=0.0)
    x, y = (true / 4096.0).T
    measured = np.column_stack([true[:, 0] + 30 * x * y, true[:, 1] - 20 * x**2])
    # The inverse of this map is not a polynomial, so fit forward instead: true -> measured.
    lin = fit_linearisation(true, measured, order=2)
    assert lin.residual_rms < 1e-9
    probe = np.array([[1000.0, 2500.0], [37.0, 4000.0]])
    px, py = (probe / 4096.0).T
    expected = np.column_stack([probe[:, 0] + 30 * px * py, probe[:, 1] - 20 * px**2])
    assert_allclose(lin(probe), expected, atol=1e-8)


def test_outside_the_domain_raises_or_flags() -> None:
    true = _grid(9)
    lin = fit_linearisation(_psd_response(true), true, order=3)
    lo, hi = lin.domain[0]
    pts = np.array([[2048.0, 2048.0], [hi + 10.0, 2048.0], [np.nan, 1.0]])
    assert lin.inside(pts).tolist() == [True, False, False]
    with pytest.raises(CalibrationError, match="1 points lie outside the fitted domain"):
        lin(pts)
    out = lin(pts, outside="nan")
    assert np.all(np.isfinite(out[0])) and np.all(np.isnan(out[1:]))
    assert np.all(np.isfinite(lin(pts[:2], outside="extrapolate")))
    assert lo < 2048.0


def test_dict_round_trip_through_json() -> None:
    true = _grid(11)
    lin = fit_linearisation(_psd_response(true), true, order=5)
    data = json.loads(json.dumps(lin.to_dict()))
    back = DetectorLinearisation.from_dict(data)
    probe = np.random.default_rng(1).uniform(300.0, 3800.0, (50, 2))
    assert_allclose(back(probe), lin(probe), rtol=0, atol=1e-9)
    assert back.residual_rms == lin.residual_rms and back.n_points == lin.n_points


def test_from_dict_rejects_other_content() -> None:
    with pytest.raises(CalibrationError, match="not a detector linearisation"):
        DetectorLinearisation.from_dict({"kind": "spline"})
    true = _grid(5)
    data = fit_linearisation(_psd_response(true), true, order=2).to_dict()
    del data["coefficients"]
    with pytest.raises(CalibrationError, match="incomplete"):
        DetectorLinearisation.from_dict(data)
    data = fit_linearisation(_psd_response(true), true, order=2).to_dict()
    data["coefficients"] = data["coefficients"][:1]
    with pytest.raises(CalibrationError, match="coefficients of shape"):
        DetectorLinearisation.from_dict(data)


def test_too_few_points_for_the_order() -> None:
    true = _grid(4)  # 16 points; order 5 has 21 terms
    with pytest.raises(CalibrationError, match="needs at least 21 points, got 16"):
        fit_linearisation(_psd_response(true), true, order=5)


def test_collinear_grid() -> None:
    t = np.linspace(100.0, 4000.0, 40)
    true = np.column_stack([t, 0.5 * t + 10.0])
    with pytest.raises(CalibrationError, match="collinear"):
        fit_linearisation(true, true, order=2)


def test_too_few_distinct_columns_for_the_order() -> None:
    # 3 grid columns cannot determine cubic terms in u, however many rows there are.
    u = np.array([500.0, 2000.0, 3500.0])
    v = np.linspace(100.0, 4000.0, 30)
    true = np.stack(np.meshgrid(u, v), axis=-1).reshape(-1, 2)
    with pytest.raises(CalibrationError, match="does not determine an order-3 map"):
        fit_linearisation(true, true, order=3)


def test_nan_and_bad_arguments() -> None:
    true = _grid(6)
    measured = _psd_response(true)
    measured[7, 1] = np.nan
    with pytest.raises(CalibrationError, match=r"NaN or infinite coordinates at grid points \[7\]"):
        fit_linearisation(measured, true)
    with pytest.raises(CalibrationError, match="order must be an integer"):
        fit_linearisation(true, true, order=0)
    with pytest.raises(CalibrationError, match=r"shape \(N, 2\)"):
        fit_linearisation(true, true[:-1])
    with pytest.raises(CalibrationError, match="domain must hold"):
        fit_linearisation(true, true, order=2, domain=[[500.0, 600.0], [0.0, 4096.0]])
