"""Labelled 3-D markers of a vendor system (Qualisys, NatNet) through the live path, out on LSL."""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pytest

from spotlab.acquisition.live import LiveFrame, LivePipeline, LslMarkers, PointRecorder
from spotlab.acquisition.session import Session
from spotlab.core.errors import ConfigurationError
from spotlab.core.streams import StreamSpec
from spotlab.drivers.natnet import NatNetDriver
from spotlab.drivers.qualisys import QualisysDriver
from spotlab.io.c3d_files import read_c3d
from spotlab.simulators.natnet import NatNetServer
from spotlab.simulators.natnet_scene import NatNetScene
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


class _Run(NamedTuple):
    live: LivePipeline
    frames: list[LiveFrame]
    info: Any  # the LSL stream's full info
    stamps: Any  # (N,) LSL stamps received
    rows: Any  # (N, M, 3) float32 received
    sent_t: Any  # (F,) LSL stamps of the live frames


def _through_lsl(driver: Any, name: str) -> _Run:
    """Session of one driver → LivePipeline(None) → LslMarkers() → an inlet here, 0.6 s."""
    frames: list[LiveFrame] = []
    lsl = LslMarkers(name=name)
    live = LivePipeline(None, [frames.append, lsl])
    session = Session([driver], [live], close_devices=True)
    inlet = None
    try:
        session.start()  # the outlet is made here, from the stream's spec
        found = pylsl.resolve_byprop("name", name, 1, 3.0)
        assert len(found) == 1, f"outlet {name} not found"
        inlet = pylsl.StreamInlet(found[0])
        info = inlet.info(3.0)
        inlet.open_stream(3.0)
        time.sleep(0.6)
        session.stop()
        rows: list[list[float]] = []
        stamps: list[float] = []
        end = time.monotonic() + 3.0
        while time.monotonic() < end:
            x, t = inlet.pull_chunk(0.1)
            rows += x
            stamps += t
            if not x and stamps:
                break
        outlet: Any = lsl.outlet
        sent_t = outlet.clock.to_lsl(np.array([f.frame_time_s for f in frames]))
    finally:
        session.stop()
        if inlet is not None:
            inlet.close_stream()
            del inlet
        lsl.close()
    m = len(live.labels)
    got = np.asarray(rows, dtype=np.float32).reshape(len(stamps), m, 3)
    return _Run(live, frames, info, np.asarray(stamps), got, sent_t)


def _check(run: _Run, labels: list[str], markers_mm: Any, time_s: Any, rtol: float = 0.0) -> None:
    """The live frames are the truth rows given (float32 on the wire: exact, or to
    ``rtol`` where the wire's float32 are metres); the inlet got them with the labels."""
    live, frames = run.live, run.frames
    assert live.labels == tuple(labels) and all(f.labels == tuple(labels) for f in frames)
    stats = live.stats()
    assert stats.consumer_errors == 0 and stats.failed == 0 and stats.frames_out == len(frames)
    assert len(frames) >= 0.3 * RATE
    want = np.stack([f.points for f in frames])
    if rtol:
        np.testing.assert_allclose(want, markers_mm, rtol=rtol, atol=0)
    else:
        np.testing.assert_array_equal(want, markers_mm.astype(np.float32))
    times = np.array([f.frame_time_s for f in frames])
    np.testing.assert_allclose(times, time_s, rtol=0, atol=1e-9)
    m = len(labels)
    assert all(np.array_equal(f.time_s, np.full(m, f.frame_time_s)) for f in frames)
    # The LSL stream: MoCap, the marker labels in its channels, the frames as sent.
    assert run.info.type() == "MoCap" and run.info.channel_count() == 3 * m
    assert _channel_markers(run.info) == [x for x in labels for _ in range(3)]
    assert len(run.stamps) >= 0.2 * RATE
    k = np.searchsorted(run.sent_t, run.stamps - 1e-6)
    np.testing.assert_allclose(run.sent_t[k], run.stamps, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(run.rows, want[k].astype(np.float32))


def test_qualisys_markers_pass_through_the_live_path_to_an_lsl_inlet(tmp_path: Path) -> None:
    options = QualisysSimOptions(markers=MARKERS, rate_hz=RATE, seed=3)
    with QualisysServer(options) as server:
        run = _through_lsl(QualisysDriver(server.address), f"spotlab-live3d-q-{os.getpid()}")
        truth = server.truth()
    row = {int(n): i for i, n in enumerate(truth["frame"])}
    idx = [row[f.seq] for f in run.frames]
    labels = [str(x) for x in truth["labels"]]
    _check(run, labels, truth["markers_mm"][idx], truth["timestamp_us"][idx] / 1e6)
    # The live points saved as C3D keep the labels.
    rec = PointRecorder()
    for frame in run.frames:
        rec(frame)
    trial = read_c3d(rec.save(tmp_path / "live.c3d"))
    assert list(trial.labels) == labels


def test_natnet_markers_pass_through_the_live_path_to_an_lsl_inlet(tmp_path: Path) -> None:
    scene = NatNetScene(markers=MARKERS, rate_hz=RATE, seed=5)
    path = tmp_path / "truth.npz"
    with NatNetServer(scene, truth=path) as server:
        driver = NatNetDriver(server.address)
        run = _through_lsl(driver, f"spotlab-live3d-n-{os.getpid()}")
    truth = np.load(path)
    row = {int(n): i for i, n in enumerate(truth["frame"])}
    idx = [row[f.seq] for f in run.frames]
    labels = [str(x) for x in truth["labels"]]
    ticks = truth["ticks"][idx]
    # NatNet sends float32 metres: the driver's mm are within two float32 roundings.
    _check(run, labels, truth["markers_mm"][idx], ticks / driver.spec.tick_hz, rtol=3e-7)


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
