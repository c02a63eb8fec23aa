"""The video-centroid simulator: blobs against the truth, merges, ghosts, sunlight, drop-outs,
and the driver reading it in-process (sim://centroid)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

import spotlab.simulators  # noqa: F401  (registers sim://)
from spotlab.drivers.centroid import BLOB_MERGED, CentroidDriver, blobs_from_blocks
from spotlab.geometry import Camera
from spotlab.simulators.blobs import (
    EDGE,
    IN_MERGED,
    KIND_GHOST,
    KIND_MARKER,
    KIND_MERGED,
    OWN_BLOB,
    BlobModel,
    render_camera,
)
from spotlab.simulators.centroid_body import GaitBody, carried_by, segment_capsules
from spotlab.simulators.centroid_service import CentroidSimOptions, centroid_url_for
from spotlab.simulators.rigs import ring_rig


def test_unmerged_marker_blobs_lie_within_noise_of_the_true_projection() -> None:
    rig, body = ring_rig(8), GaitBody()
    X = body.all_markers(np.array([0.3]))[0]
    rng = np.random.default_rng(0)
    errors = []
    for cam in rig.cameras:
        b = render_camera(cam, X, BlobModel(centroid_noise_px=0.07), rng)
        own = b.kind == KIND_MARKER
        errors.append(b.uv[own] - cam.project(X[b.marker[own]]))
        assert (b.seen[b.marker[own]] == OWN_BLOB).all()
    err = np.concatenate(errors)
    assert err.shape[0] > 200
    assert 0.05 < np.sqrt((err**2).mean()) < 0.09


def test_close_markers_merge_into_one_flagged_blob() -> None:
    cam = ring_rig(1).cameras[0]
    target = np.array([0.0, 0.0, 900.0])
    X = np.array([target, target + np.array([0.0, 0.0, 8.0])])  # 8 mm apart: 14 mm discs overlap
    b = render_camera(
        cam, X, BlobModel(centroid_noise_px=0.0, noise_blobs=0.0), np.random.default_rng(1)
    )
    assert b.uv.shape[0] == 1 and b.kind[0] == KIND_MERGED and b.flags[0] & 0x04
    assert (b.seen == IN_MERGED).all()
    np.testing.assert_allclose(b.true_uv[0], cam.project(X).mean(axis=0), atol=0.05)


def test_occluding_segment_hides_a_marker_behind_it() -> None:
    cam = ring_rig(1).cameras[0]
    marker = np.array([[0.0, 0.0, 900.0]])
    mid = 0.5 * (marker[0] + cam.center)
    caps = (mid[None] - [0, 0, 200.0], mid[None] + [0, 0, 200.0], np.array([80.0]))
    model = BlobModel(noise_blobs=0.0)
    hidden = render_camera(cam, marker, model, np.random.default_rng(0), capsules=caps)
    assert hidden.uv.shape[0] == 0 and hidden.seen[0] == 0
    on = np.ones((1, 1), dtype=bool)
    own = render_camera(cam, marker, model, np.random.default_rng(0), capsules=caps, on_capsule=on)
    assert own.uv.shape[0] == 1


def test_ghost_reflections_appear_for_the_configured_pairs_only() -> None:
    rig, body = ring_rig(8), GaitBody()
    X = body.all_markers(np.array([0.0]))[0]
    rng = np.random.default_rng(3)
    pairs = rng.random((8, 40)) < 0.3
    n_ghosts = n_expected = 0
    for c, cam in enumerate(rig.cameras):
        b = render_camera(cam, X, BlobModel(noise_blobs=0.0), rng, ghosts=pairs[c])
        n_ghosts += int((b.kind == KIND_GHOST).sum())
        mirror = X[pairs[c]] * [1, 1, -1]
        uv = cam.project(mirror)
        w, h = cam.size
        n_expected += int(((uv >= 0) & (uv <= [w - 1, h - 1])).all(axis=1).sum())
    assert n_expected > 20
    # Reflections of foot markers next to the floor merge with the marker's own blob.
    assert 0.7 * n_expected <= n_ghosts <= n_expected


def test_body_markers_and_capsules_are_consistent() -> None:
    body = GaitBody()
    X = body.all_markers(np.linspace(0.0, 2.0, 7))
    assert X.shape == (7, 40, 3) and np.isfinite(X).all()
    a, b, r = segment_capsules(X[0])
    assert a.shape == b.shape == (9, 3) and (r > 0).all()
    assert carried_by(40).any(axis=1).sum() >= 20
    assert len(set(body.labels)) == 40


def _record(url: str, seconds: float, **kw: object) -> tuple[list, CentroidDriver]:
    driver = CentroidDriver(url, **kw)  # type: ignore[arg-type]
    driver.start()
    blocks = []
    t0 = time.monotonic()
    while time.monotonic() - t0 < seconds:
        block = driver.recv(0.05)
        if block is not None and len(block):
            blocks.append(block)
    driver.stop()
    driver.close()
    return blocks, driver


def test_sim_url_frames_match_the_truth(tmp_path: Path) -> None:
    truth = tmp_path / "truth.npz"
    opts = CentroidSimOptions(
        cameras=4, markers=40, rate_hz=100, seed=2, truth=truth, ghost_rate=0.1
    )
    blocks, driver = _record(centroid_url_for(opts), 0.6, cameras=4, rate_hz=100)
    bf = blobs_from_blocks(blocks)
    assert bf.n_frames >= 20 and driver.stats.lost_frames == 0
    t = np.load(truth)
    assert t["markers_mm"].shape[1:] == (40, 3) and t["labels"].shape == (40,)
    row = {int(f): k for k, f in enumerate(t["frame_no"])}
    c_total = t["camera_time_s"].shape[1]
    agree = [0, 0, 0, 0]  # merged flagged, merged, single flagged, single
    for f in range(bf.n_frames):
        k = row[int(bf.camera_frame[f, 0])]
        for c in range(4):
            s = bf.slice(f, c)
            start, stop = t["blob_offsets"][k * c_total + c], t["blob_offsets"][k * c_total + c + 1]
            assert stop - start == s.stop - s.start
            np.testing.assert_allclose(bf.uv[s], t["blob_uv_true"][start:stop], atol=0.6)
            merged = t["blob_kind"][start:stop] == KIND_MERGED
            flagged = (bf.flags[s] & BLOB_MERGED) != 0
            agree[0] += int((flagged & merged).sum())
            agree[1] += int(merged.sum())
            agree[2] += int((flagged & ~merged).sum())
            agree[3] += int((~merged).sum())
            assert bf.exposure_us[f, c] == t["camera_tick_us"][k, c]
    # The hub flags merges from their shape: most merges, few single blobs.
    assert agree[1] > 0 and agree[0] >= 0.5 * agree[1] and agree[2] <= 0.02 * agree[3], agree
    assert (t["blob_kind"] == KIND_GHOST).any()
    assert np.ptp(t["camera_offset_s"]) > 1.0  # every camera keeps its own clock


def test_sunlight_overflows_and_a_dropped_camera_is_a_gap(tmp_path: Path) -> None:
    opts = CentroidSimOptions(
        cameras=2, markers=20, rate_hz=50, seed=4, sunlight="1@0.1:0.2", camera_off="0@0.2:0.2"
    )
    blocks, driver = _record(centroid_url_for(opts), 0.8, cameras=2, rate_hz=50, max_blobs=128)
    bf = blobs_from_blocks(blocks)
    assert bf.overflow[:, 1].any() and not bf.overflow[:, 0].any()
    assert (bf.n_found[bf.overflow[:, 1], 1] > 1000).all()
    assert (bf.counts[:, 1] <= 128).all()
    off = bf.offline[:, 0]
    assert off.any() and not off.all() and np.isnan(bf.exposure_us[off, 0]).all()
    assert (bf.counts[off, 0] == 0).all() and not bf.offline[:, 1].any()
    assert driver.decoder.camera_gaps.tolist() == [1, 0]
    assert driver.stats.lost_frames == 0


def test_edge_flag_for_a_blob_at_the_border() -> None:
    ring = ring_rig(1).cameras[0]
    cam = Camera(ring.K, np.zeros(5), ring.R, ring.t, ring.size)
    z = 4000.0
    ray = np.linalg.solve(cam.K, [1.0, 500.0, 1.0])  # image point 1 px from the left border
    X = cam.R.T @ (ray / ray[2] * z - cam.t)
    b = render_camera(cam, X[None], BlobModel(noise_blobs=0.0), np.random.default_rng(0))
    assert b.uv.shape[0] == 1 and b.flags[0] & EDGE
    X = cam.R.T @ (np.linalg.solve(cam.K, [640.0, 500.0, 1.0]) * z - cam.t)
    b = render_camera(cam, X[None], BlobModel(noise_blobs=0.0), np.random.default_rng(0))
    assert b.uv.shape[0] == 1 and not b.flags[0] & EDGE


@pytest.mark.parametrize("bad", ["cameras=17", "markers=0", "sunlight=9@1:1", "camera_off=x"])
def test_bad_options_are_refused(bad: str) -> None:
    from spotlab.simulators.centroid_service import centroid_options_from_url

    with pytest.raises(ValueError):
        centroid_options_from_url(f"sim://centroid?{bad}")


def test_link_faults_are_detected_and_counted(tmp_path: Path) -> None:
    log = tmp_path / "faults.json"
    opts = CentroidSimOptions(
        cameras=2, markers=10, rate_hz=100, seed=6, fault_log=log,
        faults="bitflip@0.1,truncate@0.2,duplicate@0.3,garbage@0.35,overflow@0.4:2",
    )  # fmt: skip
    blocks, driver = _record(centroid_url_for(opts), 0.8, cameras=2, rate_hz=100)
    s = driver.stats
    assert s.crc_errors >= 2 and s.duplicates == 1 and s.device_dropped == 2
    assert s.lost_frames == 4  # 2 damaged on the link + 2 dropped by the device
    bf = blobs_from_blocks(blocks)
    assert np.all(np.diff(bf.seq) >= 1) and bf.n_frames >= 60


def test_hub_built_without_a_rig_uses_the_reference_ring() -> None:
    from spotlab.simulators.centroid import CentroidDevice

    device = CentroidDevice()
    reference = ring_rig(8)
    assert len(device.rig.cameras) == 8
    for ours, theirs in zip(device.rig.cameras, reference.cameras, strict=True):
        np.testing.assert_allclose(ours.center, theirs.center)
        assert ours.size == theirs.size


def test_the_merged_flag_follows_the_blob_shape() -> None:
    """Two discs far apart in one blob look elongated (flagged); nearly coincident, round."""
    ring = ring_rig(1).cameras[0]
    cam = Camera(ring.K, np.zeros(5), ring.R, ring.t, ring.size)
    z = 3000.0
    model = BlobModel(noise_blobs=0.0, centroid_noise_px=0.0, shape_noise=0.0)
    d_px = cam.K[0, 0] * model.marker_diameter_mm / z

    def blobs_at(sep_px: float) -> tuple[int, int]:
        pts = [[640.0 - sep_px / 2, 500.0, 1.0], [640.0 + sep_px / 2, 500.0, 1.0]]
        X = np.array([cam.R.T @ (np.linalg.solve(cam.K, p) * z - cam.t) for p in pts])
        b = render_camera(cam, X, model, np.random.default_rng(0))
        return b.uv.shape[0], int(b.flags[0] & BLOB_MERGED)

    assert blobs_at(0.8 * d_px) == (1, BLOB_MERGED)  # elongation sqrt(1 + 1.6^2) = 1.9
    assert blobs_at(0.1 * d_px) == (1, 0)  # elongation 1.02: one round blob
    assert blobs_at(1.5 * d_px)[0] == 2  # apart: two blobs
