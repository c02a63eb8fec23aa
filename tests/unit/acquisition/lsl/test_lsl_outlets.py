"""LSL outlets: what an inlet on this machine receives, times, channel metadata, errors."""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

import spotlab.simulators  # noqa: F401  (registers sim://)
from spotlab.acquisition.lsl import LslClock, LslOutlet, LslOutletSink, MarkerOutlet
from spotlab.acquisition.session import Session
from spotlab.core.errors import ConfigurationError
from spotlab.core.frames import FrameBlock
from spotlab.core.streams import StreamSpec
from spotlab.drivers.selspot import SelspotDriver

pylsl = pytest.importorskip("pylsl", reason="the lsl extra is not installed")

URL = "sim://selspot?cameras=2&leds=4&reflectance=0&seed=2"


def _inlet(name: str) -> Any:
    found = pylsl.resolve_byprop("name", name, 1, 2.0)
    assert len(found) == 1, f"outlet {name} not found"
    inlet = pylsl.StreamInlet(found[0])
    inlet.open_stream(2.0)
    return inlet


def _pull(inlet: Any, n: int, timeout_s: float = 3.0) -> tuple[np.ndarray, np.ndarray]:
    rows: list[list[float]] = []
    stamps: list[float] = []
    end = time.monotonic() + timeout_s
    while len(stamps) < n and time.monotonic() < end:
        x, t = inlet.pull_chunk(0.1)
        rows += x
        stamps += t
    return np.asarray(rows), np.asarray(stamps)


def _channels(info: Any) -> list[dict[str, str]]:
    out = []
    ch = info.desc().child("channels").child("channel")
    while not ch.empty():
        out.append({k: ch.child_value(k) for k in ("label", "marker", "type", "unit")})
        ch = ch.next_sibling()
    return out


@pytest.fixture
def markers() -> Iterator[MarkerOutlet]:
    outlet = MarkerOutlet(3, 200.0, name="test-markers", labels=("a", "b", "c"))
    yield outlet
    outlet.close()


def test_inlet_receives_3d_markers_with_the_session_times(markers: MarkerOutlet) -> None:
    inlet = _inlet("test-markers")
    try:
        info = inlet.info(2.0)
        assert info.type() == "MoCap" and info.channel_count() == 9
        chans = _channels(info)
        assert [c["label"] for c in chans[:3]] == ["a_X", "a_Y", "a_Z"]
        assert [c["type"] for c in chans[3:6]] == ["PositionX", "PositionY", "PositionZ"]
        assert {c["unit"] for c in chans} == {"millimeters"} and chans[8]["marker"] == "c"
        rng = np.random.default_rng(1)
        F = 40
        session_s = time.monotonic() - 1.0 + np.arange(F) / 200.0
        X = rng.normal(0.0, 800.0, (F, 3, 3))
        X[5, 1] = np.nan  # a marker not seen
        markers.push_markers(session_s[:10], X[:10])
        for f in range(10, F):  # one frame at a time, as a live pipeline does
            markers.push_markers(session_s[f], X[f])
        values, stamps = _pull(inlet, F)
        correction = inlet.time_correction(2.0)
    finally:
        inlet.close_stream()
        del inlet
    assert stamps.shape == (F,) and markers.samples_pushed == F
    # The stamps are the session times on the LSL clock, to float64 rounding ...
    np.testing.assert_allclose(stamps, markers.clock.to_lsl(session_s), rtol=0, atol=1e-9)
    # ... and an inlet that applies its clock correction agrees within 1 ms.
    assert abs(correction) < 1e-3
    assert np.abs(markers.clock.to_session(stamps + correction) - session_s).max() < 1e-3
    got = values.reshape(F, 3, 3)
    assert np.isnan(got[5, 1]).all() and np.isfinite(np.delete(got.reshape(F * 3, 3), 16, 0)).all()
    np.testing.assert_allclose(got, X.astype(np.float32), rtol=0, atol=0, equal_nan=True)


def test_push_refuses_wrong_shapes_bad_times_and_a_closed_outlet(markers: MarkerOutlet) -> None:
    with pytest.raises(ConfigurationError, match=r"shape \(3, 3\) or \(F, 3, 3\)"):
        markers.push_markers(1.0, np.zeros((4, 3)))
    with pytest.raises(ConfigurationError, match="9 channels, got 8"):
        markers.push([1.0], np.zeros((1, 8)))
    with pytest.raises(ConfigurationError, match="NaN or infinite"):
        markers.push_markers(np.nan, np.zeros((3, 3)))
    with pytest.raises(ConfigurationError, match="times for values"):
        markers.push([1.0, 2.0], np.zeros((3, 9)))
    markers.push([], np.zeros((0, 9)))  # nothing to send is fine
    assert markers.samples_pushed == 0
    markers.close()
    assert markers.closed
    with pytest.raises(ConfigurationError, match="closed"):
        markers.push_markers(1.0, np.zeros((3, 3)))
    with pytest.raises(ConfigurationError, match="at least one marker"):
        MarkerOutlet(0, 100.0)
    empty = StreamSpec("e", "image2d", n_sensors=0, n_markers=4, rate_hz=10.0, tick_hz=1e6)
    with pytest.raises(ConfigurationError, match="no channel"):
        LslOutlet(empty)
    with pytest.raises(ConfigurationError, match="channel_format"):
        MarkerOutlet(1, 10.0, channel_format="int16")


def test_clock_maps_monotonic_session_time_to_local_clock() -> None:
    clock = LslClock.measure()
    # On one host both read the same steady clock: the offset is the reading's width.
    before = time.monotonic()
    lsl = pylsl.local_clock()
    after = time.monotonic()
    assert before - 1e-4 <= float(clock.to_session(lsl)) <= after + 1e-4
    assert clock.uncertainty_s < 1e-3
    shifted = LslClock.measure(origin_ns=time.monotonic_ns())
    assert abs(float(shifted.to_session(pylsl.local_clock()))) < 0.1
    with pytest.raises(ConfigurationError, match="reads"):
        LslClock.measure(reads=0)


class _Frames:
    """Keeps every block of every stream (what the session delivered)."""

    name = "frames"

    def __init__(self) -> None:
        self.blocks: dict[str, list[FrameBlock]] = {}

    def on_block(self, stream: str, block: FrameBlock) -> None:
        self.blocks.setdefault(stream, []).append(block)

    def on_error(self, stream: str, exc: BaseException) -> None:
        raise AssertionError(f"{stream}: {exc}")

    def stop(self) -> None:
        pass


def test_sink_publishes_a_session_stream_stamped_by_its_clock_model() -> None:
    # A stand-in clock model: session time = ticks (us) / 1e6 + a fixed offset.
    origin = time.monotonic() - 5.0

    def time_of(stream: str, block: FrameBlock) -> np.ndarray:
        return origin + block.ticks / 1e6

    driver = SelspotDriver(URL, cameras=2, leds=4, rate_hz=100, name="cam")
    sink = LslOutletSink(["cam"], time_of=time_of, channel_format="double64")
    frames = _Frames()
    with Session([driver], [frames, sink], close_devices=True) as session:
        assert set(sink.outlets) == {"cam"} and sink.outlets["cam"].stream_type == "MoCapRaw"
        clock = sink.outlets["cam"].clock
        inlet = _inlet("spotlab-cam")
        try:
            chans = _channels(inlet.info(2.0))
            values, stamps = _pull(inlet, 15)
        finally:
            inlet.close_stream()
            del inlet
        session.stop()
    assert not sink.outlets  # destroyed at stop
    assert len(chans) == 4 * 2 * 3 and chans[0]["label"] == "led0_s0_x"
    block = FrameBlock.concat(frames.blocks["cam"])
    session_s = time_of("cam", block)
    assert len(stamps) >= 15
    # Every sample the inlet got is a session frame: same time, same values.
    back = clock.to_session(stamps)
    idx = np.searchsorted(session_s, back - 1e-6)
    np.testing.assert_allclose(session_s[idx], back, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(values, block.data[idx].reshape(len(idx), -1))


def test_sink_refuses_a_stream_the_session_does_not_have() -> None:
    driver = SelspotDriver(URL, cameras=1, leds=2, rate_hz=100)
    session = Session([driver], [LslOutletSink(["nope"])], close_devices=True)
    with pytest.raises(ConfigurationError, match=r"not in the session: \['nope'\]"):
        session.start()


def test_no_outlet_exists_unless_asked(tmp_path: Any) -> None:
    # A recording without LSL neither loads pylsl nor publishes anything.
    code = (
        "import sys; from spotlab.console.cli import main; "
        f"rc = main(['record', '--device', 'selspot={URL}', '--seconds', '0.2', "
        f"'--out', {str(tmp_path / 'r.spj')!r}, '--json']); "
        "print(rc, 'pylsl' in sys.modules)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=50, check=True
    )
    assert out.stdout.split()[-2:] == ["0", "False"]
    driver = SelspotDriver(URL, cameras=1, leds=2, rate_hz=100, name="quiet")
    with Session([driver], [_Frames()], close_devices=True) as session:
        session.run_for(0.1)
        assert pylsl.resolve_byprop("name", "spotlab-quiet", 1, 0.3) == []
