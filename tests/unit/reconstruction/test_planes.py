"""intersect_planes and linear_sensor_plane: exact points, noise, conditioning, errors."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from spotlab.core.errors import ReconstructionError
from spotlab.reconstruction.planes import intersect_planes, linear_sensor_plane
from spotlab.simulators.rigs import look_at


def test_three_coordinate_planes_meet_at_the_point() -> None:
    res = intersect_planes(2.0 * np.eye(3), [2.0, 4.0, -6.0])  # x = 1, y = 2, z = -3
    assert_allclose(res.points, [1.0, 2.0, -3.0])
    assert_allclose(res.condition, 1.0)
    assert res.n_planes == 3 and not res.ill_conditioned
    assert_allclose(res.residuals, 0.0, atol=1e-15)


def _sensors() -> list[tuple[np.ndarray, np.ndarray, int]]:
    """A WATSMART-like unit: three linear sensors, two horizontal, one vertical."""
    out = []
    for center, axis in [
        ((-500.0, -3000.0, 1000.0), 0),
        ((500.0, -3000.0, 1000.0), 0),
        ((0.0, -3000.0, 1200.0), 1),
    ]:
        R, t = look_at(center, (0.0, 0.0, 1000.0))
        out.append((R, t, axis))
    return out


def _readings(X: np.ndarray, focal: float = 2000.0, principal: float = 1024.0) -> list[np.ndarray]:
    out = []
    for R, t, axis in _sensors():
        xs = X @ R.T + t
        out.append(focal * xs[..., axis] / xs[..., 2] + principal)
    return out


def test_linear_sensors_reconstruct_points() -> None:
    rng = np.random.default_rng(1)
    X = rng.uniform(-400.0, 400.0, (500, 3)) + np.array([0.0, 0.0, 1000.0])
    planes = [
        linear_sensor_plane(r, focal=2000.0, principal=1024.0, R=R, t=t, axis=axis)
        for r, (R, t, axis) in zip(_readings(X), _sensors(), strict=True)
    ]
    normals = np.stack([p[0] for p in planes], axis=-2)
    offsets = np.stack([p[1] for p in planes], axis=-1)
    res = intersect_planes(normals, offsets)
    assert res.points.shape == (500, 3)
    assert_allclose(res.points, X, atol=1e-8)
    assert not res.ill_conditioned.any()
    assert_allclose(np.linalg.norm(normals, axis=-1), 1.0)


def test_noise_and_weights() -> None:
    # four noisy planes: the heavily weighted exact ones dominate
    X = np.array([10.0, -20.0, 30.0])
    normals = np.array([[1.0, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]]) / [
        [1],
        [1],
        [1],
        [np.sqrt(3)],
    ]
    offsets = normals @ X
    offsets[3] += 5.0  # the fourth plane is 5 mm off
    even = intersect_planes(normals, offsets)
    trusted = intersect_planes(normals, offsets, weights=[1.0, 1.0, 1.0, 1e-9])
    assert_allclose(trusted.points, X, atol=1e-6)
    assert np.linalg.norm(even.points - X) > 1.0
    assert_allclose(even.residuals.sum(), even.residuals.sum())  # finite
    # normal equations: the residual vector is orthogonal to every normal direction
    assert_allclose(normals.T @ even.residuals, 0.0, atol=1e-9)
    assert even.rms > 0.0 and trusted.residuals[3] == pytest.approx(-5.0, abs=1e-6)


def test_nearly_parallel_planes_are_flagged() -> None:
    # three planes whose normals are almost coplanar: no point is fixed
    eps = np.array([1e-3, 1e-6])
    normals = np.stack(
        [
            np.broadcast_to([1.0, 0.0, 0.0], (2, 3)),
            np.broadcast_to([0.0, 1.0, 0.0], (2, 3)),
            np.stack([np.ones(2), np.ones(2), eps], axis=-1),
        ],
        axis=-2,
    )
    res = intersect_planes(normals, np.ones((2, 3)))
    assert res.ill_conditioned.tolist() == [False, True]
    assert np.isnan(res.points[1]).all() and np.isfinite(res.points[0]).all()
    assert res.condition[1] > 1e8 > res.condition[0] > 1e5


def test_missing_planes() -> None:
    normals = np.tile(np.vstack([np.eye(3), [[1.0, 1.0, 0.0]]]), (2, 1, 1))
    offsets = np.array([[1.0, 2.0, 3.0, 3.0], [1.0, 2.0, np.nan, 3.0]])
    res = intersect_planes(normals, offsets)
    assert res.n_planes.tolist() == [4, 3]
    assert_allclose(res.points[0], [1.0, 2.0, 3.0])
    assert res.ill_conditioned[1]  # three planes left, all containing the z direction
    assert np.isnan(res.residuals[1, 2])


@pytest.mark.parametrize(
    ("normals", "offsets", "match"),
    [
        (np.eye(3)[:2], np.zeros(2), "at least 3"),
        (np.eye(3), np.zeros(2), "offsets must have shape"),
        (np.zeros((3, 3)), np.zeros(3), "zero"),
        (np.full((3, 3), np.nan), np.zeros(3), "NaN everywhere"),
        (np.full((3, 3), np.inf), np.zeros(3), "infinite"),
        (np.ones(3), np.zeros(1), "shape"),
    ],
)
def test_plane_errors(normals: np.ndarray, offsets: np.ndarray, match: str) -> None:
    with pytest.raises(ReconstructionError, match=match):
        intersect_planes(normals, offsets)


def test_sensor_plane_errors() -> None:
    with pytest.raises(ReconstructionError, match="axis"):
        linear_sensor_plane(1.0, focal=1.0, principal=0.0, R=np.eye(3), t=np.zeros(3), axis=2)
    with pytest.raises(ReconstructionError, match="focal"):
        linear_sensor_plane(1.0, focal=0.0, principal=0.0, R=np.eye(3), t=np.zeros(3))
    with pytest.raises(ReconstructionError, match="rotation"):
        linear_sensor_plane(1.0, focal=1.0, principal=0.0, R=2 * np.eye(3), t=np.zeros(3))
    with pytest.raises(ReconstructionError, match="weights"):
        intersect_planes(np.eye(3), np.zeros(3), weights=[1.0, -1.0, 1.0])
