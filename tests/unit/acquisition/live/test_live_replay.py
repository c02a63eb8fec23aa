"""A recording made live equals the same recording replayed through the live pipeline."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

import spotlab.simulators  # noqa: F401  (registers sim://)
from spotlab.acquisition.live import LivePipeline, PointRecorder, replay_live
from spotlab.acquisition.recorder import Recorder
from spotlab.acquisition.session import Session
from spotlab.drivers.selspot import SelspotDriver
from spotlab.drivers.selspot.protocol import decoder_from_metadata
from spotlab.geometry import Rig
from spotlab.simulators.service import SelspotSimOptions, build_device, url_for


def test_live_points_equal_replayed_points(tmp_path: Path) -> None:
    rig_path = tmp_path / "rig.toml"
    options = SelspotSimOptions(
        cameras=4, leds=8, rate_hz=200.0, seed=5, floor_reflectance=0.0, rig_out=rig_path
    )
    build_device(options)  # writes the simulator's true rig (detector counts)
    driver = SelspotDriver(
        url_for(replace(options, rig_out=None)), cameras=4, leds=8, rate_hz=200.0, name="spx"
    )
    live = PointRecorder()
    pipeline = LivePipeline(Rig.load(rig_path), [live])
    journal = tmp_path / "run.spj"
    session = Session([driver], [Recorder(journal), pipeline], close_devices=True)
    session.run_for(0.5)
    stats = pipeline.stats()
    assert stats.frames_out == stats.frames_in["spx"] == len(live) > 20
    assert stats.failed == stats.unclocked == stats.consumer_errors == 0
    assert stats.latency.frames == len(live) and stats.latency.max_us > 0

    replayed = PointRecorder()
    again = LivePipeline(Rig.load(rig_path), [replayed])
    frames = replay_live(again, journal, decoder_from_metadata)
    assert frames == len(live)
    a, b = live.arrays(), replayed.arrays()
    assert set(a) == set(b)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)

    # It computes something real: most markers seen, rays meeting within a few counts.
    points = a["points"]
    assert np.isfinite(points[..., 0]).mean() > 0.5
    assert float(np.nanmedian(a["residual_px"])) < 5.0
    # Each LED sampled in its own 100 us slot: LED k at frame time + (k + 1/2) slots.
    slot = np.diff(a["time_s"], axis=1)
    np.testing.assert_allclose(slot, driver.spec.slot_period_s, rtol=1e-9)
    np.testing.assert_allclose(a["time_s"][:, 0] - a["frame_time_s"], slot[0, 0] / 2, rtol=1e-9)
