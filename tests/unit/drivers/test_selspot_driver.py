"""SelspotDriver session logic against a scripted peer on a real pseudo-terminal."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from _pty_peer import SpxPeer
from _spx_wire import SpxStream, event_frame, line

from spotlab.core.errors import (
    BandwidthError,
    ConfigurationError,
    DeviceError,
    DeviceTimeout,
    ProtocolError,
)
from spotlab.core.frames import FrameBlock
from spotlab.drivers import load_driver
from spotlab.drivers.mcs1.commands import (
    DeviceBandwidthError,
    DeviceConfigurationError,
    WrongFamilyError,
)
from spotlab.drivers.selspot import SelspotDriver, decoder_from_metadata


class Tap:
    def __init__(self) -> None:
        self.rx: list[bytes] = []
        self.tx: list[bytes] = []
        self.events: list[tuple[str, dict[str, object]]] = []

    def on_rx(self, stream: str, data: bytes, arrival_ns: int) -> None:
        self.rx.append(data)

    def on_tx(self, stream: str, data: bytes, sent_ns: int) -> None:
        self.tx.append(data)

    def on_event(self, stream: str, kind: str, detail: dict[str, object], t_ns: int) -> None:
        self.events.append((kind, detail))

    def kinds(self) -> list[str]:
        return [k for k, _ in self.events]


@pytest.fixture
def peer(tmp_path: Path) -> Iterator[SpxPeer]:
    with SpxPeer(tmp_path) as p:
        yield p


def make_driver(port: str, **kwargs: object) -> SelspotDriver:
    options: dict[str, object] = {
        "cameras": 2, "leds": 3, "rate_hz": 200, "slot_us": 100, "bgnd": 1, "reply_timeout": 0.5
    }  # fmt: skip
    options.update(kwargs)
    return SelspotDriver(port, **options)  # type: ignore[arg-type]


def collect(driver: SelspotDriver, n: int, timeout: float = 5.0) -> FrameBlock:
    blocks: list[FrameBlock] = []
    deadline = time.monotonic() + timeout
    while sum(len(b) for b in blocks) < n and time.monotonic() < deadline:
        block = driver.recv(0.1)
        if block is not None:
            blocks.append(block)
    assert blocks, "no frames"
    return FrameBlock.concat(blocks)


def commands_until_reset(peer: SpxPeer, timeout: float = 5.0) -> list[str]:
    """The peer's commands once it has read the driver's last ``RESET:`` (its thread reads
    what the driver wrote just before closing a moment later)."""
    deadline = time.monotonic() + timeout
    while True:
        sent = peer.sent_commands()
        if (sent and sent[-1] == "RESET:" and len(sent) > 1) or time.monotonic() > deadline:
            return sent
        time.sleep(0.02)


def test_table_entry_loads_the_driver() -> None:
    assert load_driver("selspot") is SelspotDriver


def test_session_streams_and_stops(peer: SpxPeer) -> None:
    tap = Tap()
    driver = make_driver(peer.path, leds=[(0, 0x80), (5, 0xC0), (17, 0x40)], agc=160)
    driver.add_tap(tap)
    with driver:
        block = collect(driver, 10)
        expected = SpxStream(n_leds=3, n_cams=2)
        for i in range(len(block)):
            expected.append(i)
        np.testing.assert_array_equal(block.data, np.stack(expected.values))
        assert block.seq.tolist() == list(range(len(block)))
        assert np.all(np.diff(block.arrival_ns) >= 0)
        assert driver.device is not None and driver.device.serial_number == "TEST0001"
    assert commands_until_reset(peer) == [
        "RESET:",
        "COMM:8",
        "VER:0",
        "CAMS:2",
        "LEDT:008005C01140",
        "SLOT:100",
        "RATE:200000",
        "BGND:1",
        "AGC:1,160",
        "START:",
        "STOP:",
        "RESET:",  # the device is left as it powers up, for the next program
    ]
    assert b"".join(tap.tx).endswith(b"START:51B4\rSTOP:FD1C\rRESET:8A23\r")
    assert b"RESET7DB2\r" in b"".join(tap.rx)
    assert tap.kinds() == ["open", "baud_change", "configured", "started", "stopped", "close"]
    st = driver.stats
    assert st.frames >= 10 and st.crc_errors == 0 and st.lost_frames == 0
    assert st.bytes == len(b"".join(tap.rx))


def test_spec_and_metadata_rebuild_the_decoder(peer: SpxPeer) -> None:
    driver = make_driver(Path(peer.path), slot_us=150)  # path-like ports work too
    spec = driver.spec
    assert (spec.kind, spec.n_sensors, spec.n_markers, spec.rate_hz) == ("image2d", 2, 3, 200.0)
    assert spec.tick_hz == 1e6 and spec.slot_period_s == pytest.approx(150e-6)
    assert spec.values == ("x", "y", "intensity") and spec.units == ("count",) * 3
    assert spec.metadata["config"]["leds"] == [[0, 0x80], [1, 0x80], [2, 0x80]]
    meta = driver.metadata()
    assert meta["family"] == "selspot" and meta["port"] == peer.path
    dec = decoder_from_metadata(meta)
    assert (dec.n_cams, dec.n_leds, dec.slot_us) == (2, 3, 150)
    assert decoder_from_metadata(meta["spec"]).slot_us == 150


def test_recv_before_start_is_an_error(peer: SpxPeer) -> None:
    with pytest.raises(DeviceError, match="call start"):
        make_driver(peer.path).recv(0.01)


def test_device_that_never_answers_times_out(tmp_path: Path) -> None:
    with SpxPeer(tmp_path, silent=True) as peer:
        driver = make_driver(peer.path, reply_timeout=0.3)
        t0 = time.monotonic()
        with pytest.raises(DeviceTimeout) as info:
            driver.start()
        elapsed = time.monotonic() - t0
        driver.close()
    assert elapsed < 1.5  # 0.3 s asked for; generous for a loaded machine
    assert peer.path in str(info.value)
    assert "RESET:" in str(info.value) and "BREAK" in str(info.value)


def test_error80_on_start_is_a_clear_bandwidth_error(tmp_path: Path) -> None:
    with SpxPeer(tmp_path, answers={"START": line("ERROR80")}) as peer:
        driver = make_driver(peer.path)
        with pytest.raises(DeviceBandwidthError) as info:
            driver.start()
        driver.close()
    err = info.value
    assert isinstance(err, DeviceError) and isinstance(err, BandwidthError)
    assert err.code == 0x80
    message = str(err)
    assert "START:" in message and "ERROR80" in message and "bandwidth exceeded" in message
    assert "Mbit/s" in message


def test_unknown_reply_is_a_protocol_error_naming_it(tmp_path: Path) -> None:
    with SpxPeer(tmp_path, answers={"CAMS": line("HELLO")}) as peer:
        driver = make_driver(peer.path)
        with pytest.raises(ProtocolError) as info:
            driver.start()
        driver.close()
    assert "HELLO" in str(info.value)
    assert peer.sent_commands().count("RESET:") == 2  # reset and tried once more


def test_configuration_refused_by_the_device(tmp_path: Path) -> None:
    with SpxPeer(tmp_path, answers={"SLOT": line("ERROR23")}) as peer:
        driver = make_driver(peer.path)
        with pytest.raises(DeviceConfigurationError, match=r"SLOT:100.*parameter out of range"):
            driver.start()
        driver.close()


def test_led_table_refused_as_too_long_names_the_code(tmp_path: Path) -> None:
    with SpxPeer(tmp_path, answers={"LEDT": line("ERROR02")}) as peer:
        driver = make_driver(peer.path, cameras=1, leds=100, rate_hz=50)
        with pytest.raises(DeviceError, match=r"LEDT.*too long") as info:
            driver.start()
        driver.close()
    assert info.value.code == 0x02


def test_ver_unanswered_at_new_rate_resets_and_retries(tmp_path: Path) -> None:
    calls = []

    def first_ver_lost(args: str) -> bytes | None:
        calls.append(args)
        return None if len(calls) == 1 else line("SPX 1.0 TEST0001 4 128")

    with SpxPeer(tmp_path, answers={"VER": first_ver_lost}) as peer:
        driver = make_driver(peer.path)
        with driver:
            assert len(collect(driver, 2))
    assert peer.sent_commands()[:6] == ["RESET:", "COMM:8", "VER:0", "RESET:", "COMM:8", "VER:0"]


def test_other_family_is_refused(tmp_path: Path) -> None:
    with SpxPeer(tmp_path, version="CSX 1.0 X 8 12") as peer:
        driver = make_driver(peer.path)
        with pytest.raises(ProtocolError, match="CSX"):
            driver.start()
        driver.close()


def test_device_too_small_for_the_configuration(tmp_path: Path) -> None:
    with SpxPeer(tmp_path, version="SPX 1.0 SMALL 1 16") as peer:
        driver = make_driver(peer.path)
        with pytest.raises(ConfigurationError, match="at most 1 cameras"):
            driver.start()
        driver.close()


def test_event_replies_while_streaming_are_harmless(peer: SpxPeer) -> None:
    with make_driver(peer.path) as driver:
        collect(driver, 3)
        peer.write(event_frame("WARN83"))
        n = len(collect(driver, 5))
        assert n >= 5 and driver.stats.crc_errors == 0


def test_stop_without_reply_is_a_warning_and_closes(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    tap = Tap()
    with SpxPeer(tmp_path, answers={"STOP": None}) as peer:
        driver = make_driver(peer.path, reply_timeout=0.3)
        driver.add_tap(tap)
        driver.start()
        collect(driver, 2)
        with caplog.at_level("WARNING"):
            driver.close()  # what was recorded stays good: no error
        assert "no reply to STOP:" in caplog.text and not driver._link.is_open
        assert "stop_unconfirmed" in [kind for kind, _ in tap.events]
        driver.close()


def test_recovers_from_a_spontaneous_reset(peer: SpxPeer) -> None:
    tap = Tap()
    driver = make_driver(peer.path)
    driver.add_tap(tap)
    with driver:
        first = collect(driver, 5)
        peer.reset_itself()
        later = collect(driver, int(first.seq[-1]) + 20)  # frames from the restarted stream
        assert driver.stats.reconnects == 1 and driver.stats.gaps >= 1
        assert later.seq[-1] >= 65536, "the restarted stream is a new seq epoch"
    kinds = tap.kinds()
    assert "device_reset" in kinds and "reconnected" in kinds
    assert kinds.index("device_reset") < kinds.index("reconnected")


def test_recovers_from_silence(peer: SpxPeer) -> None:
    driver = make_driver(peer.path)
    with driver:
        collect(driver, 3)
        peer.go_quiet()
        t0 = time.monotonic()
        while driver.stats.reconnects == 0 and time.monotonic() - t0 < 5:
            driver.recv(0.05)
        assert driver.stats.reconnects == 1
        assert 0.4 < time.monotonic() - t0  # max(0.5 s, 20 periods) of silence first
        collect(driver, 3)


def test_recovers_from_disconnect_and_return(peer: SpxPeer) -> None:
    tap = Tap()
    driver = make_driver(peer.path)
    driver.add_tap(tap)
    with driver:
        collect(driver, 3)
        peer.pull_cable()
        t0 = time.monotonic()
        while "disconnected" not in tap.kinds() and time.monotonic() - t0 < 3:
            assert driver.recv(0.05) is None or True
        assert driver.recovering
        assert driver.recv(0.2) is None  # still gone: keeps trying, no exception
        peer.plug_back()
        back = time.monotonic()
        collect(driver, 3)
        assert time.monotonic() - back < 3.0  # target 1 s; generous on a loaded machine
    assert driver.stats.reconnects == 1
    kinds = tap.kinds()
    assert kinds.index("disconnected") < kinds.index("reconnected")


def test_reconnect_timeout_gives_up(peer: SpxPeer) -> None:
    driver = make_driver(peer.path, reconnect_timeout=0.3)
    with driver:
        collect(driver, 2)
        peer.pull_cable()
        with pytest.raises(DeviceError, match="could not reconnect"):
            t0 = time.monotonic()
            while time.monotonic() - t0 < 5:
                driver.recv(0.1)


def test_detect_finds_the_peer_and_ignores_the_rest(peer: SpxPeer, tmp_path: Path) -> None:
    found = SelspotDriver.detect(ports=[peer.path, str(tmp_path / "nothing")], timeout=0.3)
    assert [(d.family, d.port, d.serial_number) for d in found] == [
        ("selspot", peer.path, "TEST0001")
    ]
    assert found[0].extra == {"firmware": "1.0", "max_cameras": 4, "max_leds": 128}


def test_detect_is_quick_and_harmless_with_nothing_attached(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from serial.tools import list_ports

    monkeypatch.setattr(list_ports, "comports", lambda: [])
    t0 = time.monotonic()
    assert SelspotDriver.detect() == []
    assert time.monotonic() - t0 < 0.5


def test_settings_not_given_keep_the_devices_own(tmp_path: Path) -> None:
    """Only the LED count is given: rate, cameras, slot and mode are the device's (CONF:)."""
    conf = line("CONF RATE=150000 CAMS=2 SLOT=120 BGND=2 AGC=0,160")
    with SpxPeer(tmp_path, answers={"CONF": conf}, rate_hz=150.0) as peer:
        driver = SelspotDriver(peer.path, leds=3, reply_timeout=0.5)
        with driver:
            collect(driver, 3)
        sent = peer.sent_commands()
    assert sent[3] == "CONF:"
    assert {"CAMS:2", "SLOT:120", "RATE:150000", "BGND:2", "LEDT:008001800280"} <= set(sent)
    assert driver.config.rate_hz == 150.0 and driver.config.cameras == 2
    assert driver.spec.rate_hz == 150.0 and driver.spec.n_sensors == 2


def test_a_device_without_conf_gets_the_defaults(tmp_path: Path) -> None:
    with SpxPeer(tmp_path, answers={"CONF": line("ERROR01")}) as peer:
        driver = SelspotDriver(peer.path, reply_timeout=0.5)
        with driver:
            collect(driver, 3)
        sent = peer.sent_commands()
    assert "RATE:100000" in sent and "CAMS:1" in sent
    assert driver.config.rate_hz == 100.0


def test_another_mcs1_family_is_named(tmp_path: Path) -> None:
    with SpxPeer(tmp_path, version="TMR 1.0 T1 8 4 10000000") as peer:
        driver = make_driver(peer.path)
        with pytest.raises(WrongFamilyError, match=r"timer device \(TMR\).*--driver timer"):
            driver.start()
        driver.close()
        # The device is sent back to 9600 baud for the right driver.
        assert commands_until_reset(peer)[-1] == "RESET:"
