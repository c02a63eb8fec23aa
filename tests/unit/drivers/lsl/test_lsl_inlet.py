"""The LSL inlet as a device: in a session beside a simulated SELSPOT system, recorded and
replayed; its journal records; stream not found; ``spotlab record --device lsl=NAME``."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import spotlab.simulators  # noqa: F401  (registers sim://)
from spotlab.acquisition.lsl import MarkerOutlet
from spotlab.acquisition.recorder import Recorder
from spotlab.acquisition.replay import replay
from spotlab.acquisition.session import Session
from spotlab.console.cli import main
from spotlab.core.errors import ConfigurationError, DeviceError, DeviceNotFound
from spotlab.core.frames import FrameBlock
from spotlab.drivers import load_driver
from spotlab.drivers.lsl import LslChunkDecoder, LslInletDriver, encode_chunk, parse_port
from spotlab.drivers.selspot import SelspotDriver
from spotlab.processing.decoding import decoder_for

pytest.importorskip("pylsl", reason="the lsl extra is not installed")

URL = "sim://selspot?cameras=2&leds=4&reflectance=0&seed=5"


def _wait(cond: object, timeout_s: float = 3.0) -> None:
    end = time.monotonic() + timeout_s
    while not cond() and time.monotonic() < end:  # type: ignore[operator]
        time.sleep(0.01)


def test_inlet_joins_a_session_with_a_selspot_system_and_both_are_recorded(
    tmp_path: Path,
) -> None:
    F = 30
    rng = np.random.default_rng(3)
    X = rng.normal(0.0, 500.0, (F, 2, 3))
    out = tmp_path / "two.spj"
    with MarkerOutlet(2, 100.0, name="remote-markers") as remote:
        inlet = LslInletDriver("remote-markers", name="remote")
        cam = SelspotDriver(URL, cameras=2, leds=4, rate_hz=100, name="cam")
        got: list[FrameBlock] = []

        class Keep:
            def on_block(self, stream: str, block: FrameBlock) -> None:
                if stream == "remote":
                    got.append(block)

            def on_error(self, stream: str, exc: BaseException) -> None:
                raise AssertionError(exc)

            def stop(self) -> None:
                pass

        with Session([inlet, cam], [Recorder(out), Keep()], close_devices=True) as session:
            assert inlet.spec.kind == "point3d" and inlet.spec.n_markers == 2
            assert abs(inlet.time_correction_s) < 1e-3
            session_s = time.monotonic() + np.arange(F) / 100.0
            remote.push_markers(session_s[:12], X[:12])
            remote.push_markers(session_s[12:], X[12:])
            _wait(lambda: session.frames["remote"] >= F and session.frames["cam"] >= 10)
            session.stop()
        live = FrameBlock.concat(got)
        # Frames in order, values as pushed (float32 on the wire), times agree within 1 ms.
        np.testing.assert_array_equal(live.seq, np.arange(F))
        np.testing.assert_allclose(live.data[:, :, 0], X.astype(np.float32), rtol=0, atol=0)
        np.testing.assert_allclose(
            live.ticks / 1e9, remote.clock.to_lsl(session_s), rtol=0, atol=2e-9
        )
        assert np.abs(inlet.session_times(live) - session_s).max() < 1e-3
        assert inlet.stats.frames == F and inlet.stats.bytes > 0
    # The journal replays to the same frames for the LSL stream, and holds the camera too.
    replayed: dict[str, list[FrameBlock]] = {}
    for stream, block in replay(out, decoder_for):
        replayed.setdefault(stream, []).append(block)
    assert set(replayed) == {"remote", "cam"}
    again = FrameBlock.concat(replayed["remote"])
    for field in ("seq", "ticks", "arrival_ns", "data", "flags", "status"):
        np.testing.assert_array_equal(getattr(again, field), getattr(live, field))
    assert sum(len(b) for b in replayed["cam"]) >= 10


def test_a_missing_stream_is_reported_by_name() -> None:
    driver = LslInletDriver("name=no-such-stream", resolve_timeout=0.2)
    with pytest.raises(DeviceNotFound, match=r"no LSL stream with name='no-such-stream'.*0\.2 s"):
        driver.start()
    with pytest.raises(DeviceError, match="only after start"):
        _ = driver.spec
    driver.close()


def test_ports_and_options_are_checked() -> None:
    assert parse_port("cams") == ("name", "cams")
    assert parse_port("type=MoCap") == ("type", "MoCap")
    with pytest.raises(ConfigurationError, match="PROP=VALUE"):
        parse_port("colour=red")
    with pytest.raises(ConfigurationError, match="PROP=VALUE"):
        parse_port("")
    with pytest.raises(ConfigurationError, match="resolve_timeout must be positive"):
        LslInletDriver("x", resolve_timeout=0)
    assert load_driver("lsl") is LslInletDriver


def test_journal_records_survive_any_split_and_damage_is_counted() -> None:
    with MarkerOutlet(1, 10.0, name="spec-only") as outlet:
        spec = outlet.spec
    t = np.array([10.0, 10.1, 10.2])
    x = np.arange(9.0).reshape(3, 3)
    rec = encode_chunk(t, x, 2e-5)
    whole = LslChunkDecoder(spec).feed(rec + rec, 7)
    np.testing.assert_array_equal(whole.seq, np.arange(6))
    np.testing.assert_array_equal(whole.ticks[:3], [10_000_000_000, 10_100_000_000, 10_200_000_000])
    np.testing.assert_array_equal(whole.data[3:, 0, 0], x)
    split = LslChunkDecoder(spec)
    parts = [split.feed(rec[i : i + 1], 7) for i in range(len(rec))]
    assert sum(len(p) for p in parts) == 3 and split.time_correction_s == 2e-5
    damaged = bytearray(rec)
    damaged[30] ^= 0x10
    dec = LslChunkDecoder(spec)
    block = dec.feed(b"junk" + bytes(damaged) + rec, 7)
    assert len(block) == 3 and dec.stats.crc_errors == 1 and dec.stats.resyncs >= 1
    with pytest.raises(ConfigurationError, match="F >= 1"):
        encode_chunk([], np.zeros((0, 3)))


def test_record_command_takes_an_lsl_device(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "lsl.spj"
    with MarkerOutlet(1, 50.0, name="cli-markers") as remote:
        stop = threading.Event()

        def feed() -> None:
            while not stop.wait(0.02):
                remote.push_markers(time.monotonic(), np.ones((1, 3)))

        pusher = threading.Thread(target=feed, name="test-lsl-pusher")
        pusher.start()
        try:
            argv = ["record", "--device", "lsl=cli-markers", "--seconds", "1.2", "--json"]
            code = main([*argv, "--out", str(out)])
        finally:
            stop.set()
            pusher.join()
    assert code == 0
    result = json.loads(capsys.readouterr().out)
    assert result["streams"][0]["family"] == "lsl" and result["streams"][0]["frames"] > 0
    frames = sum(len(b) for s, b in replay(out, decoder_for) if s == "lsl")
    assert frames == result["streams"][0]["frames"]
