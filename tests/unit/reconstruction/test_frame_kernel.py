"""The compiled frame kernel (_c_frame) against its numpy twin, FrameTriangulator's own code."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from _kernel_rigs import kernel_rigs

from spotlab.core import native
from spotlab.core.errors import ReconstructionError
from spotlab.geometry import Rig
from spotlab.reconstruction import _frame_kernel
from spotlab.reconstruction.frame_triangulator import FrameTriangulator
from spotlab.simulators.rigs import ring_rig

pytestmark = pytest.mark.skipif(
    native.load(_frame_kernel.KERNEL) is None, reason="compiled kernel not built or disabled"
)


def _pair(
    rig: Rig, monkeypatch: pytest.MonkeyPatch, **kw: Any
) -> tuple[FrameTriangulator, FrameTriangulator]:
    """(kernel, twin) for one rig."""
    compiled = FrameTriangulator(rig, **kw)
    assert compiled._kernel is not None
    with monkeypatch.context() as m:
        m.setenv(native.NO_NATIVE_ENV, "1")
        twin = FrameTriangulator(rig, **kw)
    assert twin._kernel is None
    return compiled, twin


def _same_points(got: tuple[np.ndarray, ...], want: tuple[np.ndarray, ...]) -> None:
    X, rms, n_views = got
    assert X.shape == want[0].shape and rms.shape == want[1].shape
    assert n_views.dtype == want[2].dtype
    np.testing.assert_array_equal(n_views, want[2])
    np.testing.assert_array_equal(np.isnan(X), np.isnan(want[0]))
    np.testing.assert_array_equal(np.isnan(rms), np.isnan(want[1]))
    np.testing.assert_allclose(X, want[0], rtol=1e-9, atol=1e-9)  # mm: 1e-12 m
    # The residual of a noise-free point is itself rounding (1e-9 px): its own atol.
    np.testing.assert_allclose(rms, want[1], rtol=1e-9, atol=1e-8)


def _same_behaviour(call: Callable[[FrameTriangulator], Any], pair: tuple[Any, Any]) -> Any:
    """Both raise the same error, or neither does; the results of both. (The twin's
    arithmetic overflows on pixels far outside the image: numpy's warning is ignored.)"""
    results, errors = [], []
    for tri in pair:
        try:
            with np.errstate(over="ignore", invalid="ignore"):
                results.append(call(tri))
            errors.append(None)
        except ReconstructionError as exc:
            errors.append(str(exc))
    assert errors[0] == errors[1]
    return results


def _scene(rig: Rig, seed: int, n: int = 128) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    X = rng.uniform(-600.0, 600.0, (n, 3)) + np.array([0.0, 0.0, 1000.0])
    return X, rig.project(X) + rng.normal(0.0, 0.2, (len(rig), n, 2))


@pytest.mark.parametrize("name", list(kernel_rigs()))
def test_points_equal_the_twins(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    rig = kernel_rigs()[name]
    pair = _pair(rig, monkeypatch)
    C = len(rig)
    _, uv = _scene(rig, 1, 150)  # the kernel's chunks of 64: two and a part
    _same_points(pair[0](uv), pair[1](uv))  # every camera sees every marker
    rng = np.random.default_rng(2)
    full = uv.copy()
    uv[rng.random((C, 150)) < 0.3] = np.nan  # missing observations
    uv[:, :4] = full[:, :4]
    uv[:, 0] = np.nan  # seen by none
    uv[1:, 1] = np.nan  # by one
    uv[2:, 2] = np.nan  # by two
    uv[0, 3, 1] = np.nan  # half an observation
    got, want = pair[0](uv), pair[1](uv)
    _same_points(got, want)
    for tri in pair:  # marker by marker: the same points
        _same_points(tri.by_marker(np.swapaxes(uv, 0, 1).copy()), want)
    assert got[2][0] == 0 and got[2][1] == 1 and got[2][2] == 2
    assert np.isnan(got[0][:2]).all() and np.isfinite(got[0][2]).all()
    x, y, seen = pair[0].normalize(uv)
    x2, y2, seen2 = pair[1].normalize(uv)
    np.testing.assert_array_equal(seen, seen2)
    np.testing.assert_array_equal(x, x2)  # the same arithmetic: the same bits
    np.testing.assert_array_equal(y, y2)
    for a, b in zip(pair[0].solve(x, y, seen), pair[1].solve(x, y, seen), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9)
    empty = np.empty((C, 0, 2))
    _same_points(pair[0](empty), pair[1](empty))


def test_points_behind_a_camera_and_far_out_pixels(monkeypatch: pytest.MonkeyPatch) -> None:
    rig = ring_rig(8)
    pair = _pair(rig, monkeypatch)
    X, uv = _scene(rig, 4, 16)
    cam = rig.cameras[0]
    behind = cam.center - 300.0 * cam.R[2] + np.array([[0.0, 0.0, 0.0], [40.0, -30.0, 20.0]])
    uv[:, :2] = rig.project(behind)
    near = cam.center + np.array([[1e-3, 0.0, 0.0], [0.0, 2.0, 1.0]])  # by the lens
    uv[:, 2:4] = rig.project(near)
    # Beyond the fitted start's margin: further Newton steps, the geometry layer's inverse.
    uv[2, 4] = [-150.0, -120.0]
    uv[5, 9] = [1280.0 + 140.0, 1024.0 + 100.0]
    uv[3, 10] = [1280.0 + 900.0, -800.0]
    for k in range(uv.shape[1]):
        one = uv[:, k : k + 1].copy()
        results = _same_behaviour(lambda tri, one=one: tri(one), pair)
        if results:
            _same_points(*results)
    results = _same_behaviour(lambda tri: tri(uv[:, 4:10]), pair)
    _same_points(*results)
    by_marker = _same_behaviour(lambda tri: tri.by_marker(np.swapaxes(uv[:, 4:10], 0, 1)), pair)
    _same_points(by_marker[0], results[0])
    _same_points(by_marker[1], results[0])
    # A point behind camera 0, whose ray (a line) it is on: seen by 0 and 4, then 0, 3-5.
    c0, c4 = rig.cameras[0].center, rig.cameras[4].center
    X = c0 + 200.0 * (c0 - c4) / np.linalg.norm(c0 - c4) + np.array([0.0, 30.0, -20.0])
    both = np.full((8, 2, 2), np.nan)
    both[:, 0] = both[:, 1] = rig.project(X[None])[:, 0]
    both[0] = rig.project((2.0 * c0 - X)[None])[0, 0]  # the pixel of its ray
    both[[1, 2, 3, 5, 6, 7], 0] = np.nan
    both[[1, 2, 6, 7], 1] = np.nan
    got = pair[0](both)
    _same_points(got, pair[1](both))
    np.testing.assert_allclose(got[0], [X, X], atol=1e-6)


def test_low_conditioning_is_masked_alike(monkeypatch: pytest.MonkeyPatch) -> None:
    rig = ring_rig(8)
    _, uv = _scene(rig, 5)
    uv[2:] = np.nan  # two cameras only: the worse conditioned
    for level in (1e-8, 1e-3, 0.05, 0.3):
        pair = _pair(rig, monkeypatch, min_conditioning=level)
        _same_points(pair[0](uv), pair[1](uv))


def test_bad_input_is_refused_alike(monkeypatch: pytest.MonkeyPatch) -> None:
    rig = ring_rig(8)
    pair = _pair(rig, monkeypatch)
    _, uv = _scene(rig, 6)
    _same_behaviour(lambda tri: tri(uv[:3]), pair)
    _same_behaviour(lambda tri: tri(uv[:, :, :1]), pair)
    uv[4, 7, 1] = -np.inf
    with pytest.raises(ReconstructionError, match="infinite"):
        pair[0](uv)
    _same_behaviour(lambda tri: tri(uv), pair)
    _same_behaviour(lambda tri: tri.normalize(uv), pair)
    _same_behaviour(lambda tri: tri.by_marker(np.swapaxes(uv, 0, 1)), pair)
    _same_behaviour(lambda tri: tri.by_marker(uv), pair)  # (C, N, 2): the wrong shape


def test_strided_and_integer_input(monkeypatch: pytest.MonkeyPatch) -> None:
    rig = ring_rig(8)
    pair = _pair(rig, monkeypatch)
    _, uv = _scene(rig, 7)
    strided = np.swapaxes(np.swapaxes(uv, 0, 1).copy(), 0, 1)  # not C-contiguous
    _same_points(pair[0](strided), pair[1](uv))
    pixels = np.rint(uv).astype(np.int32)
    _same_points(pair[0](pixels), pair[1](pixels))


def test_the_kernel_checks_buffer_sizes() -> None:
    module = native.load(_frame_kernel.KERNEL)
    assert module is not None
    rig = _frame_kernel.pack(FrameTriangulator(ring_rig(2))._frame, 1e-8)
    uv = np.zeros((2, 4, 2))
    x, y = np.empty((2, 4)), np.empty((2, 4))
    seen, slow = np.empty((2, 4), dtype=bool), np.empty(8, dtype=np.int64)
    with pytest.raises(ValueError, match="uv"):
        module.normalize(rig, 5, uv, False, x, y, seen, slow)
    with pytest.raises(ValueError, match="rig"):
        module.normalize(rig[:-1], 4, uv, False, x, y, seen, slow)
    assert module.normalize(rig, 4, uv, False, x, y, seen, slow) == 0
    X, rms, n_views = np.empty((4, 3)), np.empty(4), np.empty(4, dtype=np.int64)
    with pytest.raises(ValueError, match="rms"):
        module.frame(rig, 4, uv, False, X, rms[:3], n_views)
    assert module.frame(rig, 4, uv, False, X, rms, n_views) == 0


def test_threads_share_one_triangulator() -> None:
    # The kernel runs without the interpreter lock and keeps no state between calls.
    rig = ring_rig(8)
    tri = FrameTriangulator(rig)
    frames = [_scene(rig, seed)[1] for seed in range(8)]
    want = [tri(uv) for uv in frames]
    got: dict[int, list[tuple[np.ndarray, ...]]] = {}

    def work(k: int) -> None:
        got[k] = [tri(frames[(k + i) % 8]) for i in range(40)]

    threads = [threading.Thread(target=work, args=(k,)) for k in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for k, results in got.items():
        for i, result in enumerate(results):
            for a, b in zip(result, want[(k + i) % 8], strict=True):
                np.testing.assert_array_equal(a, b)
