"""Two simulated systems in one lab: the same markers (a common scene epoch) seen from
different camera rings (``--scene-epoch``, ``--ring-phase``)."""

from __future__ import annotations

import numpy as np

from spotlab.simulators.service import SelspotSimOptions, build_scene, options_from_url, url_for


def test_systems_powered_up_apart_see_the_same_markers_with_a_common_epoch() -> None:
    opts = SelspotSimOptions(cameras=4, leds=8, seed=5, motion="wand", scene_epoch_s=100.0)
    a = build_scene(opts, epoch_ns=101_000_000_000)  # powered up 1 s after the epoch
    b = build_scene(opts, epoch_ns=103_500_000_000)  # 3.5 s after it
    ids = np.arange(8)
    world = 106.25  # s: scene time is world minus each device's power-up
    pa = a.positions(np.full(8, world - 101.0), ids)
    pb = b.positions(np.full(8, world - 103.5), ids)
    assert np.allclose(pa, pb)
    # without the epoch each system starts the motion at its own power-up
    alone = build_scene(SelspotSimOptions(cameras=4, leds=8, seed=5, motion="wand"), 1)
    assert not np.allclose(alone.positions(np.full(8, world - 103.5), ids)[:2], pb[:2])


def test_ring_phase_turns_the_cameras_about_the_vertical() -> None:
    base = build_scene(SelspotSimOptions(cameras=4))
    turned = build_scene(SelspotSimOptions(cameras=4, ring_phase_deg=45.0))
    for c0, c1 in zip(base.cameras, turned.cameras, strict=True):
        e0 = -c0.R.T @ c0.t
        e1 = -c1.R.T @ c1.t
        assert np.isclose(e0[2], e1[2]) and np.isclose(np.hypot(*e0[:2]), np.hypot(*e1[:2]))
        turn = np.degrees(np.arctan2(e1[1], e1[0]) - np.arctan2(e0[1], e0[0])) % 360
        assert np.isclose(turn, 45.0)


def test_new_options_survive_the_url() -> None:
    opts = SelspotSimOptions(ring_phase_deg=45.0, scene_epoch_s=12.5)
    back = options_from_url(url_for(opts))
    assert back.ring_phase_deg == 45.0 and back.scene_epoch_s == 12.5
