"""vanishing_point: exact on synthetic lines, points at infinity, NaN lines, error paths."""

from __future__ import annotations

import doctest

import numpy as np
import pytest
from numpy.testing import assert_allclose

from spotlab.calibration import vanishing, vanishing_point
from spotlab.core.errors import CalibrationError
from spotlab.geometry import Camera

CAMERA = Camera(
    [[1150.0, 0.5, 652.0], [0.0, 1140.0, 505.0], [0.0, 0.0, 1.0]],
    None,
    np.eye(3),
    np.zeros(3),
    (1280, 1024),
)
POSITIONS = np.array([0.0, 200.0, 600.0])


def _lines(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Random 3-D lines in front of CAMERA: origins (n, 3), unit directions (n, 3)."""
    z = rng.uniform(2000.0, 5000.0, n)
    origins = np.column_stack([rng.uniform(-0.3, 0.3, (n, 2)) * z[:, None], z])
    d = rng.normal(size=(n, 3))
    return origins, d / np.linalg.norm(d, axis=1, keepdims=True)


def _expected(d: np.ndarray) -> np.ndarray:
    v = d @ CAMERA.K.T  # K R d with R = I
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    return v * np.where(v[..., 2:3] < 0.0, -1.0, 1.0)


@pytest.mark.parametrize("positions", [POSITIONS, np.array([0.0, 150.0, 320.0, 450.0, 600.0])])
def test_noise_free_lines_give_the_exact_vanishing_point(positions: np.ndarray) -> None:
    rng = np.random.default_rng(3)
    origins, d = _lines(200, rng)
    X = origins[:, None, :] + positions[None, :, None] * d[:, None, :]
    vp = vanishing_point(CAMERA.project(X), positions)
    assert vp.shape == (200, 3)
    assert_allclose(vp, _expected(d), atol=1e-9)


def test_batch_shape_and_order_of_markers_do_not_matter() -> None:
    rng = np.random.default_rng(4)
    origins, d = _lines(12, rng)
    X = origins[:, None, :] + POSITIONS[None, :, None] * d[:, None, :]
    uv = CAMERA.project(X).reshape(3, 4, 3, 2)
    vp = vanishing_point(uv, POSITIONS)
    assert vp.shape == (3, 4, 3)
    order = [2, 0, 1]
    assert_allclose(vanishing_point(uv[..., order, :], POSITIONS[order]), vp, atol=1e-12)


def test_line_parallel_to_the_image_gives_a_point_at_infinity() -> None:
    d = np.array([0.6, 0.8, 0.0])
    X = np.array([100.0, -50.0, 3000.0]) + POSITIONS[:, None] * d
    vp = vanishing_point(CAMERA.project(X), POSITIONS)
    assert abs(vp[2]) < 1e-12
    expected = _expected(d)
    assert_allclose(vp * np.sign(vp @ expected), expected, atol=1e-12)  # sign is arbitrary


def test_noisy_markers_with_more_positions_fit_better() -> None:
    rng = np.random.default_rng(5)
    origins, d = _lines(400, rng)
    many = np.linspace(0.0, 600.0, 7)
    errors = []
    for positions in (POSITIONS, many):
        X = origins[:, None, :] + positions[None, :, None] * d[:, None, :]
        uv = CAMERA.project(X) + rng.normal(0.0, 0.2, (400, positions.size, 2))
        vp = vanishing_point(uv, positions)
        # Angle between the fitted and the true direction of the ray through the point.
        ray = np.linalg.solve(CAMERA.K, vp.T).T
        cos = np.abs(np.sum(ray * d, axis=1)) / np.linalg.norm(ray, axis=1)
        errors.append(np.degrees(np.median(np.arccos(np.clip(cos, 0.0, 1.0)))))
    assert errors[1] < errors[0] < 10.0


def test_nan_marker_and_end_on_line_give_nan_rows() -> None:
    rng = np.random.default_rng(6)
    origins, d = _lines(3, rng)
    X = origins[:, None, :] + POSITIONS[None, :, None] * d[:, None, :]
    uv = CAMERA.project(X)
    uv[1, 2, 0] = np.nan
    uv[2] = uv[2, 0]  # all three markers on one image point
    vp = vanishing_point(uv, POSITIONS)
    assert np.all(np.isfinite(vp[0]))
    assert np.all(np.isnan(vp[1:]))


def test_too_few_markers() -> None:
    with pytest.raises(CalibrationError, match="at least 3 markers"):
        vanishing_point(np.zeros((2, 2)), [0.0, 1.0])


def test_repeated_positions() -> None:
    with pytest.raises(CalibrationError, match="distinct"):
        vanishing_point(np.arange(6.0).reshape(3, 2), [0.0, 1.0, 1.0])


def test_shape_mismatch() -> None:
    with pytest.raises(CalibrationError, match=r"shape \(\.\.\., 3, 2\)"):
        vanishing_point(np.zeros((5, 4, 2)), POSITIONS)


def test_nan_positions() -> None:
    with pytest.raises(CalibrationError, match="NaN"):
        vanishing_point(np.zeros((3, 2)), [0.0, np.nan, 2.0])


def test_docstring_example_runs() -> None:
    failures, tried = doctest.testmod(vanishing, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert tried > 0 and failures == 0
