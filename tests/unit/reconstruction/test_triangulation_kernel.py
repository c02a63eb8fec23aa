"""triangulate with the compiled kernel (_c_frame's odle / normalize_range) against its
numpy twin (_rays.normalize_seen and _solvers.odle), through the batch API."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from _kernel_rigs import kernel_rigs

from spotlab.core import native
from spotlab.core.errors import ReconstructionError
from spotlab.geometry import Rig
from spotlab.reconstruction import _frame_kernel, _solvers, triangulation
from spotlab.reconstruction.triangulation import TriangulationResult, triangulate_points
from spotlab.simulators.rigs import ring_rig

pytestmark = pytest.mark.skipif(
    native.load(_frame_kernel.KERNEL) is None, reason="compiled kernel not built or disabled"
)

Call = Callable[[], Any]


def _both(call: Call, monkeypatch: pytest.MonkeyPatch) -> tuple[Any, Any]:
    """(kernel, twin) results of ``call``, or the message of the ReconstructionError both
    raise (the same one)."""
    out, errors = [], []
    for twin in (False, True):
        with monkeypatch.context() as m:
            if twin:
                m.setenv(native.NO_NATIVE_ENV, "1")
            try:
                with np.errstate(over="ignore", invalid="ignore"):  # the twin's far pixels
                    out.append(call())
                errors.append(None)
            except ReconstructionError as exc:
                out.append(str(exc))
                errors.append(str(exc))
    assert errors[0] == errors[1]
    return out[0], out[1]


def _same(got: TriangulationResult, want: TriangulationResult) -> None:
    """Points to 1e-9 relative (1e-9 mm near 0), the same masks and flags."""
    assert got.points.shape == want.points.shape
    np.testing.assert_array_equal(np.isnan(got.points), np.isnan(want.points))
    np.testing.assert_allclose(got.points, want.points, rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(got.n_views, want.n_views)
    np.testing.assert_array_equal(got.ill_conditioned, want.ill_conditioned)
    np.testing.assert_array_equal(got.outlier, want.outlier)
    two = want.n_views >= 2
    np.testing.assert_allclose(got.conditioning[two], want.conditioning[two], rtol=1e-9, atol=1e-12)
    # Fewer views: the singular system's rounding (or NaN), in either.
    assert not (np.abs(got.conditioning[~two]) > 1e-12).any()
    assert not (np.abs(want.conditioning[~two]) > 1e-12).any()
    np.testing.assert_allclose(got.residuals, want.residuals, rtol=1e-9, atol=1e-8)
    np.testing.assert_allclose(got.rms, want.rms, rtol=1e-9, atol=1e-8)


def _points(seed: int, n: int) -> np.ndarray:
    """World points (n, 3) in front of every camera of a ring rig."""
    rng = np.random.default_rng(seed)
    return rng.uniform(-600.0, 600.0, (n, 3)) + np.array([0.0, 0.0, 1000.0])


def _scene(rig: Rig, seed: int, n: int) -> np.ndarray:
    """Noisy pixels (C, n, 2) with 30 % missing; points 0-3 seen by 0, 1, 2 cameras and
    by all but half an observation."""
    rng = np.random.default_rng(seed + 100)
    uv = rig.project(_points(seed, n)) + rng.normal(0.0, 0.2, (len(rig), n, 2))
    full = uv.copy()
    uv[rng.random((len(rig), n)) < 0.3] = np.nan
    uv[:, :4] = full[:, :4]
    uv[:, 0] = np.nan
    uv[1:, 1] = np.nan
    uv[2:, 2] = np.nan
    uv[0, 3, 1] = np.nan
    return uv


@pytest.mark.parametrize("name", list(kernel_rigs()))
def test_batch_points_equal_the_twins(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    rig = kernel_rigs()[name]
    uv = _scene(rig, 1, 150)  # the kernel's chunks of 64 points: two and a part
    rng = np.random.default_rng(9)
    weights = rng.uniform(0.2, 3.0, uv.shape[:2])
    weights[np.isnan(uv[..., 0])] = np.nan  # unseen rays' weights are not read
    for kw in (
        {},
        {"iterations": 0},
        {"iterations": 3},
        {"weights": weights},
        {"weights": 2.0},
        {"refine": 1},
        {"method": "dlt"},
    ):
        got, want = _both(lambda kw=kw: triangulate_points(rig, uv, **kw), monkeypatch)
        _same(got, want)
    assert np.isnan(got.points[:2]).all() and np.isfinite(got.points[2]).all()
    if len(rig) == 2:
        got, want = _both(lambda: triangulate_points(rig, uv, "midpoint"), monkeypatch)
        _same(got, want)
    empty = np.empty((len(rig), 0, 2))
    _same(*_both(lambda: triangulate_points(rig, empty), monkeypatch))


def test_chunks_and_threads(monkeypatch: pytest.MonkeyPatch) -> None:
    rig = ring_rig(8)
    uv = _scene(rig, 2, 400).reshape(8, 4, 100, 2)  # (C, F, M, 2)
    monkeypatch.setattr(triangulation, "_CHUNK", 70)  # 6 chunks, the last one short
    one = triangulate_points(rig, uv)
    for workers in (2, 3, None):
        got, want = _both(lambda w=workers: triangulate_points(rig, uv, workers=w), monkeypatch)
        _same(got, want)
        # Every point's arithmetic is its own: the same bits in any chunk or thread.
        np.testing.assert_array_equal(got.points, one.points)
        np.testing.assert_array_equal(got.conditioning, one.conditioning)
    assert one.points.shape == (4, 100, 3)


def test_behind_a_camera_and_far_out_pixels(monkeypatch: pytest.MonkeyPatch) -> None:
    rig = ring_rig(8)
    uv = rig.project(_points(4, 16))
    cam = rig.cameras[0]
    behind = cam.center - 300.0 * cam.R[2] + np.array([[0.0, 0.0, 0.0], [40.0, -30.0, 20.0]])
    uv[:, :2] = rig.project(behind)
    uv[:, 2:4] = rig.project(cam.center + np.array([[1e-3, 0.0, 0.0], [0.0, 2.0, 1.0]]))
    # Beyond the fitted start's margin: further Newton steps, the geometry layer's inverse
    # (for point 10: the kernel's solve after Python's part). The pixels of the points
    # behind or by camera 0 in some other cameras have no ray: errors.
    uv[2, 4] = [-150.0, -120.0]
    uv[5, 9] = [1280.0 + 140.0, 1024.0 + 100.0]
    uv[3, 10] = [1280.0 + 900.0, -800.0]
    for k in range(uv.shape[1]):
        got, want = _both(lambda k=k: triangulate_points(rig, uv[:, k : k + 1]), monkeypatch)
        if isinstance(got, TriangulationResult):
            _same(got, want)
    got, want = _both(lambda: triangulate_points(rig, uv), monkeypatch)
    assert isinstance(got, str) and "camera" in got
    for kw in ({}, {"iterations": 2}, {"refine": 1}, {"method": "dlt"}):
        _same(*_both(lambda kw=kw: triangulate_points(rig, uv[:, 4:], **kw), monkeypatch))


def test_conditioning_and_strict_alike(monkeypatch: pytest.MonkeyPatch) -> None:
    rig = ring_rig(8)
    uv = rig.project(_points(5, 100))
    uv[2:, 50:] = np.nan  # two cameras only: the worse conditioned
    for level in (1e-8, 1e-3, 0.05, 0.3):
        got, want = _both(
            lambda v=level: triangulate_points(rig, uv, min_conditioning=v), monkeypatch
        )
        _same(got, want)
    assert got.ill_conditioned[50:].all()
    got, _ = _both(lambda: triangulate_points(rig, uv, strict=True), monkeypatch)
    assert isinstance(got, TriangulationResult)
    got, _ = _both(
        lambda: triangulate_points(rig, uv, strict=True, min_conditioning=0.3), monkeypatch
    )
    assert "parallel" in got
    uv[1:, 0] = np.nan
    got, _ = _both(lambda: triangulate_points(rig, uv, strict=True), monkeypatch)
    assert "fewer than two" in got


def test_bad_input_is_refused_alike(monkeypatch: pytest.MonkeyPatch) -> None:
    rig = ring_rig(8)
    uv = _scene(rig, 6, 20)
    calls: list[Call] = [
        lambda: triangulate_points(rig, uv[:3]),
        lambda: triangulate_points(rig, uv[:, :, :1]),
        lambda: triangulate_points(rig, uv, weights=-np.ones(uv.shape[:2])),
        lambda: triangulate_points(rig, uv, weights=np.ones((3, 3))),
        lambda: triangulate_points(rig, uv, iterations=-1),
    ]
    inf = uv.copy()
    inf[4, 7, 1] = -np.inf
    calls.append(lambda: triangulate_points(rig, inf))
    for call in calls:
        got, _ = _both(call, monkeypatch)
        assert isinstance(got, str)


def test_strided_and_integer_input(monkeypatch: pytest.MonkeyPatch) -> None:
    rig = ring_rig(8)
    uv = _scene(rig, 7, 50)
    strided = np.swapaxes(np.swapaxes(uv, 0, 1).copy(), 0, 1)  # not C-contiguous
    _same(*_both(lambda: triangulate_points(rig, strided), monkeypatch))
    pixels = np.rint(rig.project(_points(8, 50))).astype(np.int32)
    _same(*_both(lambda: triangulate_points(rig, pixels), monkeypatch))


def test_the_batch_entry_points_check_their_arguments() -> None:
    module = native.load(_frame_kernel.KERNEL)
    assert module is not None
    rig = ring_rig(2)
    frame = _solvers.Frame(rig.cameras, np.zeros(3))
    packed = _frame_kernel.pack(frame, 1e-8)
    uv = np.ascontiguousarray(rig.project(np.array([[0.0, 0.0, 900.0]] * 6)))
    x, y = np.empty((2, 4)), np.empty((2, 4))
    seen, slow = np.empty((2, 4), dtype=bool), np.empty(8, dtype=np.int64)
    X, cond = np.empty((4, 3)), np.empty(4)
    with pytest.raises(ValueError, match="range"):
        module.normalize_range(packed, 6, uv, 3, 4, x, y, seen, slow)
    with pytest.raises(ValueError, match="uv"):
        module.normalize_range(packed, 5, uv, 0, 4, x, y, seen, slow)
    assert module.normalize_range(packed, 6, uv, 2, 4, x, y, seen, slow) == 0
    with pytest.raises(ValueError, match="weights"):
        module.odle(packed, 6, uv, 2, 4, np.ones(7), 1, X, cond, x, y, seen, slow)
    with pytest.raises(ValueError, match="passes"):
        module.odle(packed, 6, uv, 2, 4, None, -1, X, cond, x, y, seen, slow)
    with pytest.raises(ValueError, match="conditioning"):
        module.odle(packed, 6, uv, 2, 4, None, 1, X, cond[:3], x, y, seen, slow)
    assert module.odle(packed, 6, uv, 2, 4, np.ones(8), 2, X, cond, x, y, seen, slow) == 0
    X2, cond2 = np.empty((4, 3)), np.empty(4)
    with pytest.raises(ValueError, match="X"):
        module.odle_solve(packed, 4, x, y, seen, None, 2, X2[:3], cond2)
    module.odle_solve(packed, 4, x, y, seen, None, 2, X2, cond2)
    np.testing.assert_array_equal(X2, X)  # weights of 1 are no weights
    np.testing.assert_array_equal(cond2, cond)
    np.testing.assert_allclose(X2, [[0.0, 0.0, 900.0]] * 4, atol=1e-9)
