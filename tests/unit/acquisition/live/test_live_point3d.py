"""Labelled 3-D markers of a vendor system (Qualisys) through the live path and out on LSL."""

from __future__ import annotations

import os
import time
from typing import Any

import numpy as np
import pytest

from spotlab.acquisition.live import LiveFrame, LivePipeline, LslMarkers
from spotlab.acquisition.session import Session
from spotlab.core.errors import ConfigurationError
from spotlab.core.streams import StreamSpec
from spotlab.drivers.qualisys import QualisysDriver
from spotlab.simulators.qualisys import QualisysServer, QualisysSimOptions

pylsl = pytest.importorskip("pylsl", reason="the lsl extra is not installed")

from spotlab.acquisition.lsl import configure  # noqa: E402

try:  # unicast on this machine, as the LSL tests do (multicast may be blocked)
    configure(("127.0.0.1",), log_level=-3)
except ConfigurationError:
    pass  # liblsl was configured already by another test module of this process

RATE, MARKERS = 100.0, 8


def _channel_markers(info: Any) -> list[str]:
    out: list[str] = []
    ch = info.desc().child("channels").child("channel")
    while not ch.empty():
        out.append(ch.child_value("marker"))
        ch = ch.next_sibling()
    return out


def test_qualisys_markers_pass_through_the_live_path_to_an_lsl_inlet() -> None:
    name = f"spotlab-live3d-test-{os.getpid()}"
    frames: list[LiveFrame] = []
    lsl = LslMarkers(name=name)
    live = LivePipeline(None, [frames.append, lsl])
    inlet = None
    with QualisysServer(QualisysSimOptions(markers=MARKERS, rate_hz=RATE, seed=3)) as server:
        session = Session([QualisysDriver(server.address)], [live], close_devices=True)
        try:
            session.start()  # the outlet is made here, from the stream's spec
            found = pylsl.resolve_byprop("name", name, 1, 3.0)
            assert len(found) == 1, f"outlet {name} not found"
            inlet = pylsl.StreamInlet(found[0])
            info = inlet.info(3.0)
            inlet.open_stream(3.0)
            time.sleep(0.6)
        finally:
            session.stop()
        truth = server.truth()
    rows: list[list[float]] = []
    stamps: list[float] = []
    try:
        end = time.monotonic() + 3.0
        while time.monotonic() < end:
            x, t = inlet.pull_chunk(0.1)
            rows += x
            stamps += t
            if not x and stamps:
                break
    finally:
        inlet.close_stream()
        del inlet
        outlet = lsl.outlet
        lsl.close()
    labels = [str(x) for x in truth["labels"]]
    assert live.labels == tuple(labels) and all(f.labels == tuple(labels) for f in frames)
    stats = live.stats()
    assert stats.consumer_errors == 0 and stats.failed == 0 and stats.frames_out == len(frames)
    assert len(frames) >= 0.3 * RATE
    # Every live frame is the simulator's frame of that number, at QTM's time stamp.
    row = {int(n): i for i, n in enumerate(truth["frame"])}
    idx = [row[f.seq] for f in frames]
    want = np.stack([f.points for f in frames])
    np.testing.assert_array_equal(want, truth["markers_mm"][idx].astype(np.float32))
    times = np.array([f.frame_time_s for f in frames])
    np.testing.assert_array_equal(times, truth["timestamp_us"][idx] / 1e6)
    assert all(np.array_equal(f.time_s, np.full(MARKERS, f.frame_time_s)) for f in frames)
    # The LSL stream: MoCap, the marker labels in its channels, the frames as sent.
    assert info.type() == "MoCap" and info.channel_count() == 3 * MARKERS
    assert _channel_markers(info) == [m for m in labels for _ in range(3)]
    assert len(stamps) >= 0.2 * RATE
    assert outlet is not None
    sent_t = outlet.clock.to_lsl(times)  # type: ignore[attr-defined]
    k = np.searchsorted(sent_t, np.asarray(stamps) - 1e-6)
    np.testing.assert_allclose(sent_t[k], stamps, rtol=0, atol=1e-6)
    got = np.asarray(rows, dtype=np.float32).reshape(len(stamps), MARKERS, 3)
    np.testing.assert_array_equal(got, want[k].astype(np.float32))


def test_without_a_rig_one_point3d_stream_is_needed() -> None:
    points = StreamSpec("q", "point3d", 1, 4, 100.0, 1e6, values=("x", "y", "z"), units=("mm",) * 3)
    image = StreamSpec("cams", "image2d", 4, 4, 100.0, 1e6)
    with pytest.raises(ConfigurationError, match="one point3d stream"):
        LivePipeline(None).configure([image])
    with pytest.raises(ConfigurationError, match="one point3d stream"):
        LivePipeline(None).configure(
            [points, StreamSpec.from_dict({**points.to_dict(), "name": "r"})]
        )
    with pytest.raises(ConfigurationError, match="no stream named"):
        LivePipeline(None, streams=["nope"]).configure([points])
    live = LivePipeline(None, streams=["q"])
    live.configure([points, image])
    assert live.labels == ("m0", "m1", "m2", "m3")
