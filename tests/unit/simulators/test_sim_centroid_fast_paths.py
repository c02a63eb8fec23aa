"""The centroid simulator's fast paths give what the plain computations give: overlapping
pairs, merge components, the projection, and the scene computed for a block of frames."""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from spotlab.simulators.blob_optics import Optics, project_many
from spotlab.simulators.blobs import _components, _touching
from spotlab.simulators.centroid import CentroidStream
from spotlab.simulators.centroid_service import CentroidSimOptions, build_centroid_device
from spotlab.simulators.rigs import ring_rig


def _all_pairs(cam_of: np.ndarray, uv: np.ndarray, d: np.ndarray) -> set[tuple[int, int]]:
    """Every pair of one camera whose discs overlap, tested one by one."""
    out = set()
    for i in range(cam_of.size):
        for j in range(i + 1, cam_of.size):
            du, dv = uv[i, 0] - uv[j, 0], uv[i, 1] - uv[j, 1]
            if cam_of[i] == cam_of[j] and 4 * (du * du + dv * dv) < (d[i] + d[j]) ** 2:
                out.add((i, j))
    return out


def test_overlapping_pairs_are_those_of_the_all_pairs_test() -> None:
    rng = np.random.default_rng(5)
    for trial in range(40):
        n = int(rng.integers(1, 5))
        cam_of = np.repeat(np.arange(n), rng.integers(0, 40, n)).astype(np.int64)
        uv = rng.uniform(0, 60.0 if trial % 2 else 400.0, (cam_of.size, 2))
        uv[1::4] = uv[0:-1:4][: uv[1::4].shape[0]]  # some coincide exactly
        d = rng.uniform(0.5, 12.0, cam_of.size)
        a, b = _touching(cam_of, uv, d, np.ones(n, dtype=bool))
        found = {(min(x, y), max(x, y)) for x, y in zip(a.tolist(), b.tolist(), strict=True)}
        assert len(found) == a.size
        assert found == _all_pairs(cam_of, uv, d)


def test_merge_components_are_numbered_as_scipy_numbers_them() -> None:
    rng = np.random.default_rng(6)
    for pairs in (0, 1, 5, 30, 200):
        n = 120
        a = rng.integers(0, n, pairs).astype(np.int64)
        b = rng.integers(0, n, pairs).astype(np.int64)
        ncomp, label = _components(n, a, b)
        graph = coo_matrix((np.ones(pairs), (a, b)), shape=(n, n))
        want_n, want = connected_components(graph, directed=False)
        assert ncomp == want_n
        np.testing.assert_array_equal(label, want)


def test_projection_matches_the_rotation_as_a_matrix_product() -> None:
    cams = ring_rig(8).cameras
    optics = Optics.of(cams)
    rng = np.random.default_rng(7)
    P = rng.normal(0.0, 1500.0, (8, 50, 3)) + np.array([0.0, 0.0, 1000.0])
    P[:, ::7] = np.nan
    uv, diameter, _, inside = project_many(optics, P, 14.0, 200.0)
    for c, cam in enumerate(cams):
        ok = inside[c]
        assert ok.sum() > 10
        np.testing.assert_allclose(uv[c, ok], cam.project(P[c, ok]), rtol=0, atol=1e-9)
        z = (P[c, ok] @ cam.R.T + cam.t)[:, 2]
        np.testing.assert_allclose(diameter[c, ok], cam.K[0, 0] * 14.0 / z, rtol=1e-12)
    picked = optics.select([5, 2])
    np.testing.assert_array_equal(picked.centers, optics.centers[[5, 2]])
    np.testing.assert_array_equal(picked.fx, optics.fx[[5, 2]])


def test_a_block_of_frames_has_each_frames_own_scene() -> None:
    dev = build_centroid_device(CentroidSimOptions(rate_hz=300.0, seed=3), now_ns=0)
    stream = dev._new_stream(1_000_000_000, 0)
    assert isinstance(stream, CentroidStream)
    half = stream.cconfig.exposure_us * 0.5e-6
    for _ in range(40):  # past the first block
        w_trig, times, X = stream._scene()
        assert w_trig == float(stream.clock.world_ns(stream._osc0))
        w_exp = w_trig + (dev.trigger_delay_s[stream.cams] + half) * 1e9
        want = np.append((w_exp - stream.clock.epoch_ns) * 1e-9, times[-1])
        np.testing.assert_array_equal(times, want)
        assert times[-1] == (w_trig + half * 1e9 - stream.clock.epoch_ns) * 1e-9
        np.testing.assert_array_equal(X, dev.positions(times))
        stream.take()
