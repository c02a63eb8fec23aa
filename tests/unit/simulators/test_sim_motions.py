"""Generated motions and C3D replay."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from _simwire import Host, cmd, decode, spx

from spotlab.simulators.motions import (
    Concat,
    Gait,
    RigidClusters,
    SampledMotion,
    WandDance,
    from_c3d,
    make_motion,
    reference_markers,
)
from spotlab.simulators.scene import Scene, ring_rig
from spotlab.simulators.selspot import SelspotDevice

T = np.linspace(0.0, 60.0, 3001)


def all_markers(motion: object, t: np.ndarray) -> np.ndarray:
    m = motion.n_markers  # type: ignore[attr-defined]
    times = np.repeat(t, m)
    ids = np.tile(np.arange(m), t.size)
    return motion.sample(times, ids).reshape(t.size, m, 3)  # type: ignore[attr-defined,no-any-return]


def test_wand_ends_stay_500_mm_apart_inside_the_volume() -> None:
    p = all_markers(WandDance(seed=7), T)
    np.testing.assert_allclose(np.linalg.norm(p[:, 0] - p[:, 1], axis=1), 500.0)
    # An operator's sweep: from near the floor to above the head, across the volume.
    assert p[..., 2].min() > 100 and p[..., 2].max() < 2000
    assert np.abs(p[..., :2]).max() < 2000
    speed = np.linalg.norm(np.diff(p[:, 0], axis=0), axis=1) / np.diff(T)[0]
    assert 50 < np.median(speed) < 3000  # mm/s: a person waving a wand
    direction = (p[:, 1] - p[:, 0]) / 500.0
    assert np.ptp(direction, axis=0).min() > 1.0  # it turns through many directions


def test_seeds_give_different_dances() -> None:
    a, b = all_markers(WandDance(seed=1), T[:10]), all_markers(WandDance(seed=2), T[:10])
    assert not np.allclose(a, b)
    np.testing.assert_array_equal(a, all_markers(WandDance(seed=1), T[:10]))


def test_rigid_clusters_keep_their_shape() -> None:
    motion = RigidClusters(n_markers=12, cluster_size=4, seed=3)
    p = all_markers(motion, T[::10])
    for j in range(3):
        c = p[:, 4 * j : 4 * j + 4]
        d = np.linalg.norm(c[:, :, None] - c[:, None, :], axis=-1)
        np.testing.assert_allclose(d, np.broadcast_to(d[0], d.shape), atol=1e-9)
        assert np.ptp(c[:, 0], axis=0).max() > 300  # and they do move
    with pytest.raises(ValueError):
        RigidClusters(cluster_size=2)


def test_gait_walks_with_feet_near_the_floor() -> None:
    g = Gait()
    p = all_markers(g, T[:600])
    labels = list(g.labels)
    assert len(labels) == 19
    assert p[..., 2].min() >= 5.0
    head, toe = labels.index("HEAD"), labels.index("LTOE")
    assert 1500 < p[:, head, 2].mean() < 1800 and p[:, toe, 2].mean() < 150
    pelvis = p[:, labels.index("SACR"), :2]
    path = np.linalg.norm(np.diff(pelvis, axis=0), axis=1).sum()
    assert path == pytest.approx(1200 * (T[599] - T[0]), rel=0.05)  # 1.2 m/s round a circle
    la, ra = p[:, labels.index("LANK")], p[:, labels.index("RANK")]
    assert np.corrcoef(la[:, 2], ra[:, 2])[0, 1] < 0.0  # feet lift in turn
    assert np.ptp(la[:, 2]) > 50


def test_make_motion_pads_with_reference_markers_and_cuts() -> None:
    m = make_motion("wand", 8, seed=1)
    assert m.n_markers == 8 and isinstance(m, Concat)
    p = m.positions(3.0)
    np.testing.assert_array_equal(p[2:6], reference_markers(4).points)  # the L-frame follows
    assert make_motion("gait", 5).n_markers == 5
    assert make_motion("cluster", 6).n_markers == 6
    assert make_motion("gait", 25).labels[19] == "LF_O"


def test_sampled_motion_interpolates_and_loops() -> None:
    times = np.array([0.0, 1.0, 2.0])
    pos = np.zeros((3, 2, 3))
    pos[:, 0, 0] = [0.0, 10.0, 30.0]
    pos[1, 1] = np.nan
    looping = SampledMotion(times, pos)
    np.testing.assert_allclose(
        looping.sample(np.array([0.5, 1.5, 3.5]), np.array([0, 0, 0]))[:, 0], [5, 20, 5]
    )
    np.testing.assert_allclose(
        looping.sample(np.array([2.5]), np.array([0]))[0, 0], 15.0
    )  # back to start
    gap = looping.sample(np.array([0.0, 0.5, 1.5, 2.0]), np.array([1, 1, 1, 1]))
    assert np.isfinite(gap[0]).all() and np.isnan(gap[1:3]).all() and np.isfinite(gap[3]).all()
    once = SampledMotion(times, pos, loop=False)
    assert np.isnan(once.sample(np.array([3.1, -0.1]), np.array([0, 0]))).all()
    with pytest.raises(ValueError):
        SampledMotion([0.0, 0.0], np.zeros((2, 1, 3)))


@pytest.fixture
def c3d_file(shared_file: Callable[[str], Path]) -> Path:
    return shared_file("c3d_org_samples/sample01/Eb015pi.c3d")


def test_c3d_replay(c3d_file: Path) -> None:
    import c3d

    motion = from_c3d(c3d_file, center=False)
    with c3d_file.open("rb") as fh:
        reader = c3d.Reader(fh)
        rate = reader.point_rate
        raw = np.stack([pts for _, pts, _ in reader.read_frames(copy=True)])
    assert motion.n_markers == raw.shape[1] == 26 and motion.labels[0] == "RFT1"
    frame = 10
    p = motion.positions(frame / rate)
    seen = raw[frame, :, 3] >= 0
    np.testing.assert_allclose(p[seen], raw[frame, seen, :3], atol=1e-4)
    assert np.isnan(p[~seen]).all() == (~seen).any() or not (~seen).any()
    half = motion.positions((frame + 0.5) / rate)
    both = seen & (raw[frame + 1, :, 3] >= 0)
    np.testing.assert_allclose(
        half[both], (raw[frame, both, :3] + raw[frame + 1, both, :3]) / 2, atol=1e-4
    )
    missing = np.argwhere(raw[:, :, 3] < 0)
    assert missing.size  # this file has gaps: they come back as NaN
    f, m = missing[0]
    assert np.isnan(motion.sample(np.array([f / rate]), np.array([m]))).all()
    centred = from_c3d(c3d_file)
    assert np.abs(np.nanmean(centred.data[..., :2].reshape(-1, 2), axis=0)).max() < 1e-6


def test_c3d_gaps_become_invalid_records(
    c3d_file: Path, make_device: Callable[..., SelspotDevice]
) -> None:
    motion = from_c3d(c3d_file)
    scene = Scene(motion, ring_rig(2))
    h = Host(make_device(scene=scene))
    h.configure(2, 26, 50_000)
    h.buf.clear()
    h.send(cmd("START:"), baud=2_000_000)
    for _ in range(10):
        h.wait(1_000_000_000)  # 10 s: more than the file's 9 s, it loops
    frames = [spx(f["payload"]) for f in decode(bytes(h.buf)).frames if f["type"] == 1]  # type: ignore[arg-type]
    assert len(frames) >= 499
    valid = np.stack([(f["flags"] & 1) != 0 for f in frames])  # type: ignore[operator]
    gaps = np.isnan(motion.data[..., 0])  # (F, M) frames of the file where a marker is missing
    gappy = np.flatnonzero(gaps.any(axis=0))
    assert gappy.size
    # A marker missing for a stretch of the file is invalid on every camera during it.
    m = int(gappy[0])
    assert (~valid[:, m, :].any(axis=1)).sum() >= 0.5 * gaps[:, m].sum() * len(frames) / gaps.shape[
        0
    ]
