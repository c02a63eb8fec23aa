"""LivePipeline: points, times, frame matching of two systems, clocks, errors."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from spotlab.acquisition.clocks import ClockModel, ClockSegment, EdgeClockEstimator
from spotlab.acquisition.live import LiveFrame, LivePipeline, PointRecorder
from spotlab.core.errors import ConfigurationError
from spotlab.core.frames import FrameBlock
from spotlab.core.streams import StreamSpec
from spotlab.geometry import Rig
from spotlab.reconstruction.frame_triangulator import FrameTriangulator
from spotlab.simulators.rigs import ring_rig
from spotlab.testing.synthetic_image2d import SyntheticImage2d

RIG = ring_rig(8)


def _device(rig: Rig = RIG, **kw: Any) -> SyntheticImage2d:
    device = SyntheticImage2d(rig, 16, 300.0, paced=False, **kw)
    device.start()
    return device


def _blocks(device: SyntheticImage2d, n: int) -> list[FrameBlock]:
    out = [device.recv() for _ in range(n)]
    assert all(b is not None for b in out)
    return out  # type: ignore[return-value]


def test_single_stream_points_times_and_latency() -> None:
    device = _device()
    rec = PointRecorder()
    pipeline = LivePipeline(RIG, [rec])
    pipeline.configure([device.spec, StreamSpec("timer", "timer", 0, 0, 100.0, 1e6)])
    for block in _blocks(device, 30):
        pipeline.on_block(device.name, block)
    pipeline.on_block("timer", _blocks(device, 1)[0])  # not an input: ignored
    a = rec.arrays()
    assert a["seq"].tolist() == list(range(30))
    np.testing.assert_allclose(a["frame_time_s"], np.arange(30) / 300.0, atol=1e-6)
    np.testing.assert_array_equal(a["time_s"], a["frame_time_s"][:, None].repeat(16, 1))
    truth = np.stack([device.truth(k) for k in range(30)])
    assert np.sqrt(np.mean(np.sum((a["points"] - truth) ** 2, axis=-1))) < 2.0  # mm
    stats = pipeline.stats()
    assert stats.frames_in == {"synthetic": 30} and stats.frames_out == 30
    assert stats.latency.frames == 30 == stats.latency_by_stream["synthetic"].frames
    pipeline.reset_latency()
    assert pipeline.stats().latency.frames == 0


def test_two_synchronised_systems_are_matched_by_time() -> None:
    halves = [Rig(RIG.cameras[:4]), Rig(RIG.cameras[4:])]
    centre = _device().centre
    a, b = (
        _device(h, name=f"sys{i}", seed=i, paths_seed=0, t0_ns=0, centre=centre)
        for i, h in enumerate(halves)
    )
    rec = PointRecorder()
    pipeline = LivePipeline(RIG, [rec], streams=["sys0", "sys1"])
    pipeline.configure([b.spec, a.spec])
    ba, bb = _blocks(a, 12), _blocks(b, 12)
    del bb[5]  # system 1 lost its frame 5
    # System 1's frames arrive three frames late; the pipeline waits for them.
    for k in range(12):
        pipeline.on_block("sys0", ba[k])
        if k >= 3:
            pipeline.on_block("sys1", bb[k - 3])
    pipeline.stop()  # the rest of system 0's frames go out alone
    out = rec.arrays()
    assert out["seq"].tolist() == list(range(12))
    stats = pipeline.stats()
    # Frame 5 lost, frames 10 and 11 of system 1 never arrived.
    assert stats.incomplete == 3 and stats.frames_out == 12
    tri = FrameTriangulator(RIG)
    for k in (0, 4, 6):
        uv = np.concatenate(
            [ba[k].data[0].transpose(1, 0, 2), bb[k if k < 5 else k - 1].data[0].transpose(1, 0, 2)]
        )
        np.testing.assert_array_equal(out["points"][k], tri(uv)[0])
    assert (out["n_views"][5] == 4).all() and np.isfinite(out["points"][5]).all()
    np.testing.assert_allclose(out["points"][5], a.truth(5), atol=5.0)


def test_clock_models_give_frame_times_and_scale_slot_offsets() -> None:
    device = _device()
    seg = ClockSegment(epoch=0, tick_start=0, tick_end=10**7, origin=0, offset_s=5.0, rate=2e-6)
    rec = PointRecorder()
    spec = StreamSpec(
        "synthetic", "image2d", 8, 16, 300.0, 1e6, 1e-4, device.spec.values, device.spec.units
    )
    pipeline = LivePipeline(RIG, [rec], clocks={"synthetic": ClockModel(1e6, [seg])})
    pipeline.configure([spec])
    for block in _blocks(device, 3):
        pipeline.on_block("synthetic", block)
    a = rec.arrays()
    ticks = np.round(np.arange(3) * 1e6 / 300.0)  # the device's microsecond ticks
    np.testing.assert_allclose(a["frame_time_s"], 5.0 + 2e-6 * ticks, rtol=1e-12)
    # Slot offsets in device seconds, times the clock's rate (2 session s per device s).
    np.testing.assert_allclose(a["time_s"][0] - a["frame_time_s"][0], (np.arange(16) + 0.5) * 2e-4)


def test_frames_wait_for_an_online_clock_and_callables_work() -> None:
    device = _device()
    estimator = EdgeClockEstimator(1e6)
    pipeline = LivePipeline(RIG, clocks={"synthetic": estimator})
    pipeline.configure([device.spec])
    blocks = _blocks(device, 4)
    pipeline.on_block("synthetic", blocks[0])
    assert pipeline.stats().unclocked == 1 and pipeline.stats().frames_out == 0
    ticks = np.arange(10, dtype=np.int64) * 10_000
    estimator.update(ticks, 7.0 + ticks * 1e-6)
    rec = PointRecorder()
    pipeline.consumers.append(rec)
    pipeline.on_block("synthetic", blocks[1])
    assert rec.arrays()["frame_time_s"][0] == pytest.approx(7.0 + 3333e-6, abs=1e-9)
    shifted = PointRecorder()
    other = LivePipeline(RIG, [shifted], clocks={"synthetic": lambda t: t * 1e-6 - 1.0})
    other.configure([device.spec])
    other.on_block("synthetic", blocks[2])
    assert shifted.arrays()["frame_time_s"][0] == pytest.approx(6667e-6 - 1.0, abs=1e-9)


def test_a_failing_consumer_does_not_stop_the_others() -> None:
    device = _device()
    got: list[LiveFrame] = []

    def bad(frame: LiveFrame) -> None:
        raise RuntimeError("consumer bug")

    pipeline = LivePipeline(RIG, [bad, got.append])
    pipeline.configure([device.spec])
    for block in _blocks(device, 4):
        pipeline.on_block("synthetic", block)
    assert len(got) == 4 and pipeline.stats().consumer_errors == 4


def test_configuration_errors_name_the_cause() -> None:
    spec = _device().spec
    with pytest.raises(ConfigurationError, match="Rig"):
        LivePipeline("rig.toml")  # type: ignore[arg-type]
    with pytest.raises(ConfigurationError, match="8 cameras but the rig has 4"):
        LivePipeline(Rig(RIG.cameras[:4])).configure([spec])
    with pytest.raises(ConfigurationError, match="no stream named"):
        LivePipeline(RIG, streams=["nope"]).configure([spec])
    with pytest.raises(ConfigurationError, match="image2d"):
        LivePipeline(RIG).configure([StreamSpec("t", "timer", 0, 0, 100.0, 1e6)])
    with pytest.raises(ConfigurationError, match="marker counts differ"):
        a = StreamSpec("a", "image2d", 4, 16, 300.0, 1e6)
        LivePipeline(RIG).configure([a, StreamSpec("b", "image2d", 4, 8, 300.0, 1e6)])
    with pytest.raises(ConfigurationError, match="not read here"):
        LivePipeline(RIG, clocks={"x": lambda t: t}).configure([spec])
