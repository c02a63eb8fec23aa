"""Scanner (CODA-3 style): closed form against synthetic truth, precision model, errors."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from spotlab.core.errors import ReconstructionError
from spotlab.reconstruction.scanner import scanner_angles, scanner_position, scanner_precision


def test_closed_form_inverts_the_angles() -> None:
    rng = np.random.default_rng(1)
    X = np.stack(
        [rng.uniform(-800, 800, 1000), rng.uniform(1500, 6000, 1000), rng.uniform(-600, 600, 1000)],
        axis=-1,
    )
    A = scanner_angles(X, base=1000.0)
    assert_allclose(scanner_position(A, base=1000.0), X, rtol=1e-12, atol=1e-9)


def test_hand_computed_point() -> None:
    # a marker 2 m straight ahead on the centre line: each vertical axis sees it at
    # atan(0.5 / 2) either side; the horizontal mirror at 0
    a = np.arctan(0.25)
    assert_allclose(scanner_angles([0.0, 2000.0, 0.0]), [a, -a, 0.0])
    assert_allclose(scanner_position([a, -a, np.arctan(0.1)]), [0.0, 2000.0, 200.0])


def test_precision_model_matches_monte_carlo() -> None:
    X = np.array([300.0, 3000.0, -200.0])
    sigma = np.array([4.4e-5, 4.4e-5, 6e-5])
    sd, cov = scanner_precision(X, sigma)
    rng = np.random.default_rng(2)
    A = scanner_angles(X) + rng.normal(0.0, 1.0, (200_000, 3)) * sigma
    P = scanner_position(A)
    assert_allclose(P.std(axis=0), sd, rtol=0.02)
    assert_allclose(np.cov(P.T), cov, rtol=0.05, atol=0.02 * sd.max() ** 2)


def test_depth_error_grows_with_the_square_lateral_linearly() -> None:
    d = np.array([1000.0, 2000.0, 4000.0, 8000.0])
    X = np.stack([np.zeros(4), d, np.zeros(4)], axis=-1)  # on the centre line
    sd, _ = scanner_precision(X, 4.4e-5)
    # on the centre line sec^2(alpha) = 1 + (b / 2y)^2, so, with b = 1000 mm:
    sigma, b = 4.4e-5, 1000.0
    assert_allclose(sd[:, 1], np.sqrt(2.0) * sigma * (d**2 + b**2 / 4) / b, rtol=1e-12)
    assert_allclose(sd[:, 0], sigma * (d + b**2 / (4 * d)) / np.sqrt(2.0), rtol=1e-12)
    assert_allclose(sd[:, 2], sigma * d, rtol=1e-12)
    ratio = sd[1:] / sd[:-1]
    assert_allclose(ratio[-1, 1], 4.0, rtol=0.02)  # depth: quadratic once y >> b
    assert_allclose(ratio[-1, 0], 2.0, rtol=0.02)  # lateral: linear
    assert_allclose(ratio[:, 2], 2.0, rtol=1e-12)
    # CODA-3: 1:16000 of 40 degrees is about 44 um per m laterally (Woltring: ~50 um/m)
    sigma = np.radians(40.0) / 16000.0
    sd1, _ = scanner_precision([0.0, 1000.0, 0.0], sigma)
    assert sd1[2] == pytest.approx(1000.0 * sigma)
    assert 0.04 < sd1[2] < 0.05


def test_missing_reading_gives_nan() -> None:
    P = scanner_position([[0.1, -0.1, 0.0], [np.nan, -0.1, 0.0]])
    assert np.isfinite(P[0]).all() and np.isnan(P[1]).all()


def test_scanner_errors() -> None:
    with pytest.raises(ReconstructionError, match="do not meet"):
        scanner_position([-0.1, 0.1, 0.0])
    with pytest.raises(ReconstructionError, match="90"):
        scanner_position([np.pi / 2, 0.1, 0.0])
    with pytest.raises(ReconstructionError, match="in front"):
        scanner_angles([0.0, -1.0, 0.0])
    with pytest.raises(ReconstructionError, match="base"):
        scanner_position([0.1, -0.1, 0.0], base=0.0)
    with pytest.raises(ReconstructionError, match="shape"):
        scanner_position([0.1, -0.1])
    with pytest.raises(ReconstructionError, match="sigma_angle"):
        scanner_precision([0.0, 1000.0, 0.0], -1.0)
