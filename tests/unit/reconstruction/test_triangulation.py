"""triangulate / triangulate_points on the reference ring rig (8 cameras, distortion).

Noise-free data must be reproduced exactly by every method, at the world origin and with
the rig 1 km away from it; noisy data must give the error of the maximum-likelihood
estimate (the noise floor).
"""

from __future__ import annotations

import doctest

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.optimize import least_squares

from spotlab.geometry import Camera, Rig
from spotlab.reconstruction import triangulate, triangulate_points
from spotlab.simulators.rigs import ring_rig

RIG = ring_rig()


def _shifted(rig: Rig, offset: np.ndarray) -> Rig:
    """The same cameras moved by ``offset`` (mm): world origin far from the rig."""
    return Rig(
        Camera(cam.K, cam.dist, cam.R, cam.t - cam.R @ offset, cam.size, cam.name) for cam in rig
    )


def _scene(
    n: int, seed: int, noise_px: float = 0.0, rig: Rig = RIG, offset: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Points in the capture volume seen by 2..8 random cameras; uv (C, n, 2) with NaN."""
    rng = np.random.default_rng(seed)
    r = 1500.0 * np.sqrt(rng.uniform(0, 1, n))
    phi = rng.uniform(0, 2 * np.pi, n)
    X = np.stack([r * np.cos(phi), r * np.sin(phi), rng.uniform(100, 2100, n)], 1)
    X[0] = 0.0  # the world origin itself
    if offset is not None:
        X += offset
    uv = rig.project(X)
    C = len(rig)
    keep = rng.integers(2, C + 1, n)
    order = np.argsort(rng.uniform(size=(C, n)), axis=0)
    rank = np.argsort(order, axis=0)
    uv[rank >= keep] = np.nan
    return X, uv + rng.normal(0.0, noise_px, uv.shape)


def _rms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=-1))))


@pytest.mark.parametrize("method", ["odle", "dlt"])
@pytest.mark.parametrize("far", [False, True])
def test_exact_on_noise_free_data(method: str, far: bool) -> None:
    offset = np.array([1.0e6, -4.0e5, 2.0e5]) if far else None
    rig = _shifted(RIG, offset) if offset is not None else RIG
    X, uv = _scene(3000, 1, rig=rig, offset=offset)
    got = triangulate(rig, uv, method)
    assert_allclose(got, X, rtol=0, atol=1e-6)  # mm; measured about 1e-9 (1e-8 far away)
    assert_allclose(triangulate(rig, uv, method, iterations=0), X, rtol=0, atol=1e-6)
    assert_allclose(got[0], offset if far else 0.0, rtol=0, atol=1e-6)


def test_midpoint_of_two_views_is_exact_and_equals_plain_odle() -> None:
    X, uv = _scene(500, 2)
    two = uv.copy()
    two[2:] = np.nan  # cameras 1 and 2 only
    seen = np.all(np.isfinite(two[:2]), axis=-1).all(axis=0)
    got = triangulate(RIG, two, "midpoint")
    assert_allclose(got[seen], X[seen], rtol=0, atol=1e-6)
    assert np.all(np.isnan(got[~seen]))
    _, noisy = _scene(500, 2, noise_px=0.5)
    noisy[2:] = np.nan
    # Woltring: Eq. 6 with two rays is the midpoint of their common perpendicular.
    assert_allclose(
        triangulate(RIG, noisy, "midpoint"),
        triangulate(RIG, noisy, "odle", iterations=0),
        rtol=0,
        atol=1e-7,
    )


def test_views_counted_and_too_few_give_nan() -> None:
    X, uv = _scene(800, 3)
    uv[:, :100] = np.nan  # unseen
    uv[1:, 100:200] = np.nan  # seen by one camera
    result = triangulate_points(RIG, uv)
    expected_views = np.all(np.isfinite(uv), axis=-1).sum(axis=0)
    assert_allclose(result.n_views, expected_views)
    assert np.all(np.isnan(result.points[:200]))
    assert np.all(np.isnan(result.rms[:200]))
    assert set(np.unique(result.n_views[200:])) == set(range(2, 9))
    assert_allclose(result.points[200:], X[200:], rtol=0, atol=1e-6)
    assert np.max(result.ray_error[np.isfinite(result.ray_error)]) < 1e-6  # px


def test_all_nan_gives_nan_unless_strict() -> None:
    uv = np.full((len(RIG), 5, 2), np.nan)
    assert np.all(np.isnan(triangulate(RIG, uv)))
    with pytest.raises(Exception, match="5 of 5 points are seen by fewer than two cameras"):
        triangulate(RIG, uv, strict=True)


def test_frames_by_markers_shape() -> None:
    X, uv = _scene(600, 4)
    got = triangulate(RIG, uv.reshape(len(RIG), 20, 30, 2))
    assert got.shape == (20, 30, 3)
    assert_allclose(got.reshape(-1, 3), X, rtol=0, atol=1e-6)
    result = triangulate_points(RIG, uv.reshape(len(RIG), 20, 30, 2))
    assert result.residuals.shape == (len(RIG), 20, 30, 2)
    assert result.rms.shape == result.n_views.shape == result.outlier.shape == (20, 30)


def test_zero_weight_drops_a_camera() -> None:
    _, uv = _scene(400, 5, noise_px=0.3)
    weights = np.ones((len(RIG), 1))
    weights[3] = 0.0
    dropped = uv.copy()
    dropped[3] = np.nan
    for method in ("odle", "dlt"):
        got = triangulate(RIG, uv, method, weights=weights)
        want = triangulate(RIG, dropped, method)
        ok = np.isfinite(want[:, 0])
        assert_allclose(got[ok], want[ok], rtol=0, atol=1e-8)


def _pixel_cost(uv_point: np.ndarray, X: np.ndarray) -> float:
    seen = np.all(np.isfinite(uv_point), axis=-1)
    return float(np.sum((RIG.project(X)[seen] - uv_point[seen]) ** 2))


def _ml_point(uv_point: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """Independent maximum-likelihood point: scipy least_squares on the pixel error."""
    seen = np.all(np.isfinite(uv_point), axis=-1)

    def fun(X: np.ndarray) -> np.ndarray:
        return (RIG.project(X)[seen] - uv_point[seen]).ravel()

    return np.asarray(least_squares(fun, x0, method="lm", xtol=1e-15, ftol=1e-15).x)


def test_noise_floor() -> None:
    X, uv = _scene(20000, 6, noise_px=0.2)
    ml = triangulate(RIG, uv, refine=3)
    for i in range(0, 20000, 2000):  # refine reaches scipy's maximum-likelihood point
        theirs = _ml_point(uv[:, i], X[i])
        assert_allclose(ml[i], theirs, rtol=0, atol=1e-4)  # mm: the minimum is flat
        assert _pixel_cost(uv[:, i], ml[i]) <= _pixel_cost(uv[:, i], theirs) * (1 + 1e-12)
    floor = _rms(ml, X)
    assert 0.4 < floor < 1.5  # mm, 0.2 px at about 4 m
    assert _rms(triangulate(RIG, uv), X) < 1.002 * floor
    assert _rms(triangulate(RIG, uv, "dlt"), X) < 1.005 * floor
    # Unweighted Eq. 6 and Eq. 8 are a few per cent worse: why the defaults re-weight.
    assert _rms(triangulate(RIG, uv, iterations=0), X) > 1.01 * floor
    assert _rms(triangulate(RIG, uv, "dlt", iterations=0), X) > 1.01 * floor


def _homogeneous_dlt_unnormalised(rig: Rig, uv: np.ndarray) -> np.ndarray:
    """The textbook homogeneous DLT in pixels and mm, without Hartley's conditioning."""
    out = np.full((uv.shape[1], 3), np.nan)
    for i in range(uv.shape[1]):
        rows = []
        for cam, (u, v) in zip(rig, uv[:, i], strict=True):
            if np.isfinite(u):
                P = cam.projection_matrix
                u_ideal, v_ideal = cam.undistort([u, v])
                rows += [u_ideal * P[2] - P[0], v_ideal * P[2] - P[1]]
        h = np.linalg.svd(np.array(rows))[2][-1]
        out[i] = h[:3] / h[3]
    return out


def test_conditioned_at_the_origin() -> None:
    """TARGETS.md: an unnormalised DLT in mm loses accuracy at the world origin; ours not."""
    rng = np.random.default_rng(7)
    X = rng.normal(0.0, 1.0, (300, 3))  # within a few mm of the origin
    uv = RIG.project(X) + rng.normal(0.0, 0.2, (len(RIG), 300, 2))
    floor = _rms(triangulate(RIG, uv, refine=3), X)
    naive = _rms(_homogeneous_dlt_unnormalised(RIG, uv), X)
    for method in ("odle", "dlt"):
        assert _rms(triangulate(RIG, uv, method), X) < 1.01 * floor
    assert naive > 1.5 * floor


def test_result_flags_outliers_and_parallel_rays() -> None:
    X, uv = _scene(300, 8)
    uv[:, 10] = RIG.project(X[10])  # all 8 views
    uv[4, 10] += [25.0, -10.0]  # one bad ray
    result = triangulate_points(RIG, uv)
    assert result.outlier[10] and np.count_nonzero(result.outlier) == 1
    assert result.ray_error[4, 10] > 10.0
    assert result.rms[10] > 3.0
    # Two cameras 1 mm apart see a point 3 m away: rays nearly parallel.
    cam = RIG[0]
    twin = Camera(cam.K, cam.dist, cam.R, cam.t - cam.R @ [1.0, 0.0, 0.0], cam.size)
    pair = Rig([cam, twin])
    uv2 = pair.project(X[:5])
    near = triangulate_points(pair, uv2)
    assert np.all(near.ill_conditioned) and np.all(np.isnan(near.points))
    assert np.all(near.conditioning < 1e-8)
    with pytest.raises(Exception, match="parallel"):
        triangulate(pair, uv2, strict=True)
    assert np.all(np.isfinite(triangulate(pair, uv2, min_conditioning=0.0)))


def test_docstring_examples() -> None:
    from spotlab.reconstruction import triangulation

    failures, tried = doctest.testmod(triangulation, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert tried > 0 and failures == 0


def test_threads_give_the_same_points() -> None:
    X, uv = _scene(70000, 9, noise_px=0.2)  # more than one chunk of 32768 points
    one = triangulate(RIG, uv, workers=1)
    assert_allclose(triangulate(RIG, uv, workers=2), one, rtol=0, atol=1e-9)
    assert_allclose(triangulate(RIG, uv, workers=None), one, rtol=0, atol=1e-9)
    assert _rms(one, X) < 1.5  # mm: a real reconstruction, not NaN


def test_undistortion_matches_the_geometry_layer() -> None:
    """The fitted start and one Newton step reach Camera.normalize to 1e-9 px."""
    from spotlab.reconstruction._rays import Lens

    for cam in RIG:
        w, h = cam.size
        u, v = np.meshgrid(np.linspace(-60, w + 60, 181), np.linspace(-60, h + 60, 147))
        uv = np.stack([u.ravel(), v.ravel()], axis=-1)
        exact = cam.normalize(uv)
        x, y = Lens(cam).normalize(uv[:, 0], uv[:, 1])
        err_px = np.hypot(x - exact[:, 0], y - exact[:, 1]) * cam.K[0, 0]
        assert err_px.max() < 1e-8  # measured about 2e-9 (the margin beyond 3 %: more steps)
        assert np.median(err_px) < 1e-9
