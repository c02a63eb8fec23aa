"""End to end: session → live pipeline (session-time clock) → LSL outlet → an inlet here."""

from __future__ import annotations

import os
import time
from typing import Any

import numpy as np
import pytest

from spotlab.acquisition.live import LiveFrame, LivePipeline, LslMarkers, PointRecorder
from spotlab.acquisition.session import Session
from spotlab.core.errors import ConfigurationError
from spotlab.simulators.rigs import ring_rig
from spotlab.testing.synthetic_image2d import TICK_HZ, SyntheticImage2d

pylsl = pytest.importorskip("pylsl", reason="the lsl extra is not installed")

from spotlab.acquisition.lsl import MarkerOutlet, configure  # noqa: E402

try:  # unicast on this machine, as the LSL tests do (multicast may be blocked)
    configure(("127.0.0.1",), log_level=-3)
except ConfigurationError:
    pass  # liblsl was configured already by another test module of this process

RATE, MARKERS = 200.0, 6


def _inlet(name: str) -> Any:
    found = pylsl.resolve_byprop("name", name, 1, 3.0)
    assert len(found) == 1, f"outlet {name} not found"
    inlet = pylsl.StreamInlet(found[0])
    inlet.open_stream(3.0)
    return inlet


def test_inlet_receives_the_live_points_at_the_live_frames_session_times() -> None:
    rig = ring_rig(4)
    t0_ns = time.monotonic_ns() + 200_000_000
    device = SyntheticImage2d(rig, MARKERS, RATE, name="cams", seed=4, t0_ns=t0_ns)
    device._base[2] = np.nan  # marker 2 is never seen: NaN on the wire too

    def session_time(ticks: np.ndarray) -> np.ndarray:
        """Device ticks to session time (host monotonic s): the device's frame instants."""
        return (t0_ns + ticks * (1e9 / TICK_HZ)) / 1e9

    name = f"spotlab-live-test-{os.getpid()}"
    outlet = MarkerOutlet(MARKERS, RATE, name=name)
    points = PointRecorder()
    frames: list[LiveFrame] = []
    live = LivePipeline(
        rig, [points, LslMarkers(outlet), frames.append], clocks={"cams": session_time}
    )
    inlet = None
    try:
        inlet = _inlet(name)
        with Session([device], [live]) as session:
            session.run_for(0.6)
        n = len(frames)
        rows: list[list[float]] = []
        stamps: list[float] = []
        end = time.monotonic() + 5.0
        while len(stamps) < n and time.monotonic() < end:
            x, t = inlet.pull_chunk(0.1)
            rows += x
            stamps += t
        correction = inlet.time_correction(3.0)
    finally:
        if inlet is not None:
            inlet.close_stream()
            del inlet
        outlet.close()
    assert n >= 0.3 * RATE and live.stats().consumer_errors == 0
    assert len(stamps) == n == outlet.samples_pushed
    frame_time = np.array([f.frame_time_s for f in frames])
    seq = np.array([f.seq for f in frames])
    # The live frames' session times are the device's frame instants on the host clock ...
    np.testing.assert_allclose(frame_time, (t0_ns + seq * 1e9 / RATE) / 1e9, rtol=0, atol=1e-9)
    arrival = np.array([f.arrival_ns for f in frames]) / 1e9
    assert np.all(arrival >= frame_time - 1e-6) and np.all(arrival - frame_time < 0.5)
    # ... the inlet's raw stamps are exactly those times on the LSL clock ...
    got_t = np.asarray(stamps)
    np.testing.assert_allclose(got_t, outlet.clock.to_lsl(frame_time), rtol=0, atol=1e-9)
    # ... and after the inlet's clock correction they agree within 1 ms.
    assert abs(correction) < 1e-3
    assert np.abs(outlet.clock.to_session(got_t + correction) - frame_time).max() < 1e-3
    # The 3-D points arrive as the pipeline made them (float32 on the wire), NaN kept.
    got = np.asarray(rows).reshape(n, MARKERS, 3)
    want = np.stack([f.points for f in frames]).astype(np.float32)
    assert np.isnan(got[:, 2]).all() and np.isfinite(np.delete(got, 2, axis=1)).all()
    np.testing.assert_array_equal(got, want)
    # ... and they are the markers' true positions (0.2 px noise: within a few mm).
    truth = np.stack([device.truth(int(s)) for s in seq])
    assert np.nanmax(np.abs(got - truth)) < 5.0
