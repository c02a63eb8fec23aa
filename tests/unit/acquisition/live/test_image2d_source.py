"""The out-of-process synthetic source: bytes from a child process, decoded into frames."""

from __future__ import annotations

import time

import numpy as np
import pytest

from spotlab.acquisition.live import LivePipeline, PointRecorder
from spotlab.acquisition.session import Session
from spotlab.core.errors import DeviceError
from spotlab.simulators.rigs import ring_rig
from spotlab.testing.image2d_source import HEADER_BYTES, Image2dSourceDevice, frame_dtype


def test_wire_layout_is_the_documented_one() -> None:
    dtype = frame_dtype(8, 128)
    assert dtype.itemsize == HEADER_BYTES + 8 * 128 * 8
    assert [dtype.fields[k][1] for k in ("n_cameras", "seq", "ticks", "sent_ns", "xy")] == [
        4,
        8,
        16,
        24,
        32,
    ]


def test_frames_from_the_source_process_equal_the_in_process_frames() -> None:
    rig = ring_rig(3)
    device = Image2dSourceDevice(rig, 5, 250.0, seed=3, period=40)
    blocks = []
    device.start()
    try:
        pid = device._proc.pid if device._proc is not None else -1
        assert pid > 0
        end = time.monotonic() + 5.0
        while sum(len(b) for b in blocks) < 60 and time.monotonic() < end:
            block = device.recv(0.1)
            if block is not None:
                blocks.append(block)
        device.stop()  # the source process ends: the next read finds the link closed
        with pytest.raises(DeviceError, match="closed the link"):
            for _ in range(100):
                device.recv(0.1)
    finally:
        device.close()
    seq = np.concatenate([b.seq for b in blocks])
    assert seq.size >= 60 and np.array_equal(seq, np.arange(seq.size))
    ticks = np.concatenate([b.ticks for b in blocks])
    np.testing.assert_array_equal(ticks, np.round(seq * 1e6 / 250.0).astype(np.int64))
    arrival = np.concatenate([b.arrival_ns for b in blocks])
    assert np.all(np.diff(arrival) >= 0)
    # Paced by the source's clock: 60 frames at 250 Hz take about 0.24 s.
    assert (arrival[59] - arrival[0]) / 1e9 > 0.9 * 59 / 250.0
    data = np.concatenate([b.data for b in blocks])
    truth = device.truth_device.frames()[seq % 40]
    assert data.shape == (seq.size, 5, 3, 2)
    np.testing.assert_allclose(data, truth, rtol=0, atol=1e-3)  # float32 on the wire
    assert device.stats.frames == seq.size and device.behind.frames == seq.size


def test_a_session_reconstructs_the_source_frames_inline() -> None:
    rig = ring_rig(4)
    device = Image2dSourceDevice(rig, 6, 200.0, seed=1, noise_px=0.0, period=50)
    points = PointRecorder()
    live = LivePipeline(rig, [points])
    with Session([device], [live], close_devices=True) as session:
        session.run_for(0.3)
    out = points.arrays()
    assert live.stats().frames_out == len(points) >= 40
    truth = np.stack([device.truth_device.truth(int(s)) for s in out["seq"]])
    assert np.abs(out["points"] - truth).max() < 0.05  # mm: float32 pixels, no noise
    np.testing.assert_allclose(out["frame_time_s"], out["seq"] / 200.0, rtol=0, atol=1e-9)
    assert live.stats().latency.frames == len(points)
