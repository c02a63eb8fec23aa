"""The host side of the WSX bytes against the golden vectors of docs/protocols/wsx.md."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from spotlab.core.errors import ConfigurationError
from spotlab.drivers.wsx.decoding import WsxDecoder
from spotlab.drivers.wsx.link import parse_sim_address, raise_status
from spotlab.drivers.wsx.protocol import Info, Setup, Status, error_text, parse_calibration
from spotlab.drivers.wsx.usbio import Target, parse_port, parse_ports
from spotlab.testing.golden import golden_vector

SPEC = Path(__file__).resolve().parents[4] / "docs" / "protocols" / "wsx.md"


def _golden(name: str) -> bytes:
    return golden_vector(SPEC, name)


def test_set_up_round_trips() -> None:
    s = Setup.decode(_golden("Set-up"))
    assert s == Setup(24, (8, 8, 8, 0), 350, 4_600_000, 176_923, 80, 30, 160, 0x0002)
    assert s.encode() == _golden("Set-up")
    assert Setup.decode(_golden("Refused set-up")).rate_hz == 200.0
    assert Setup.from_dict(s.to_dict()) == s


def test_info_status_and_errors() -> None:
    info = Info.decode(_golden("Information"))
    assert (info.firmware, info.sensors, info.ccds, info.pixels) == ("1.2", 3, 3, 2048)
    assert (info.max_markers, info.clock_hz, info.ports) == (512, 1_000_000_000, 4)
    status = Status.decode(_golden("Status"))
    assert status == Status(True, 0, 0, 1000, 0, 123_456)
    refused = Status.decode(_golden("Status after the refused set-up"))
    assert refused.last_error == 0x24 and "marker rate / (markers + 2)" in error_text(0x24)


def test_calibration_record() -> None:
    ccds = parse_calibration(_golden("Calibration"), 0)
    assert [c["axis"] for c in ccds] == [0, 1, 0]
    assert [c["t"] for c in ccds] == [
        [450.0, 0.0, 3000.0],
        [0.0, 0.0, 3000.0],
        [-450.0, 0.0, 3000.0],
    ]
    assert all(c["focal"] == 1750.0 and c["principal"] == 1024.0 for c in ccds)
    assert ccds[1]["R"] == [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]


def test_frame_decodes_in_any_split_and_events_are_counted() -> None:
    frame, event = _golden("Frame"), _golden("Event")
    data = event + frame
    for cut in (0, 3, 17, 50, len(data)):
        dec = WsxDecoder(2, 1)
        a = dec.feed(data[:cut], 1)
        b = dec.feed(data[cut:], 2)
        block = b if len(b) else a
        assert len(a) + len(b) == 1 and dec.events == {1: 1}
        assert block.seq.tolist() == [1234] and block.ticks.tolist() == [5_000_000_000]
        c = block.data[0, :, :, 0]
        assert c[0].tolist() == [1024.5, 1000.25, -1.0]
        assert c[1, 0] == 1100.0 and np.isnan(c[1, 1]) and c[1, 2] == 980.75
        assert block.data[0, :, 0, 2].tolist() == [38_043, 255_435]
        assert block.flags[0].tolist() == [[0, 0, 3], [0, 2, 10]]
        assert block.data[0, 0, 2, 1] == 4095


def test_a_corrupt_or_short_frame_is_skipped() -> None:
    frame = _golden("Frame")
    bad = bytearray(frame)
    bad[40] ^= 0xFF
    dec = WsxDecoder(2, 1)
    block = dec.feed(bytes(bad) + frame[:50] + frame, 0)
    assert block.seq.tolist() == [1234]
    assert dec.stats.crc_errors >= 1 and dec.stats.resyncs >= 1


def test_lost_and_restarted_frames_are_counted() -> None:
    frame = bytearray(_golden("Frame"))

    def numbered(n: int, dropped: int = 0) -> bytes:
        import zlib

        f = bytearray(frame)
        struct.pack_into("<I", f, 8, n)
        struct.pack_into("<I", f, 28, dropped)
        struct.pack_into("<I", f, len(f) - 4, zlib.crc32(bytes(f[:-4])))
        return bytes(f)

    dec = WsxDecoder(2, 1)
    block = dec.feed(numbered(0) + numbered(1) + numbered(4, 1) + numbered(0), 0)
    assert block.seq.tolist() == [0, 1, 4, 5]
    assert dec.stats.lost_frames == 1 and dec.stats.device_dropped == 1
    assert dec.restarts == 1


def test_ports_and_addresses() -> None:
    assert parse_sim_address("wsxsim://127.0.0.1:4000/WSX00042") == ("127.0.0.1", 4000, "WSX00042")
    assert parse_port("usb:WSX00001") == Target(serial="WSX00001")
    assert parse_port("usb:1209:0010:WSX1") == Target(serial="WSX1")
    assert parse_ports("8+8+8") == (8, 8, 8, 0)
    with pytest.raises(ConfigurationError, match="is not a WSX hub"):
        parse_port("usb:16c0:05dc")
    with pytest.raises(ConfigurationError):
        parse_sim_address("wsxsim://nowhere")


@pytest.mark.parametrize(("status", "errno_"), [(-9, 32), (-4, 19), (-8, 75)])
def test_link_statuses_become_pyusb_errors(status: int, errno_: int) -> None:
    import usb.core

    with pytest.raises(usb.core.USBError) as info:
        raise_status(status)
    assert info.value.errno == errno_
    with pytest.raises(usb.core.USBTimeoutError):
        raise_status(-7)
    assert raise_status(12) == 12


def test_mutated_bytes_never_raise() -> None:
    rng = np.random.default_rng(0)
    good = _golden("Event") + _golden("Frame") * 3
    dec = WsxDecoder(2, 1)
    for _ in range(2000):
        data = bytearray(good)
        for i in rng.integers(0, len(data), size=rng.integers(1, 6)):
            data[i] = int(rng.integers(0, 256))
        cut = int(rng.integers(0, len(data)))
        for part in (bytes(data[:cut]), bytes(data[cut:])):
            block = dec.feed(part, 0)
            assert block.data.shape[1:] == (2, 3, 3)
        dec.mark_discontinuity()


def test_a_start_beyond_int64_with_a_good_crc_is_skipped() -> None:
    # Found by the fuzzer (spotlab.testing.fuzz, target wsx): start_ns is a u64 on the
    # wire, a tick an int64; such a frame is not a good frame, not an OverflowError.
    import zlib

    f = bytearray(_golden("Frame"))
    struct.pack_into("<Q", f, 20, 1 << 63)
    struct.pack_into("<I", f, len(f) - 4, zlib.crc32(bytes(f[:-4])))
    dec = WsxDecoder(2, 1)
    block = dec.feed(bytes(f) + _golden("Frame"), 0)
    assert block.seq.tolist() == [1234] and dec.stats.crc_errors == 1
