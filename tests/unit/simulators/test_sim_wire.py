"""Every golden byte vector of mcs1.md §6 and selspot.md §5, produced by the simulator's encoder."""

from __future__ import annotations

import numpy as np
import pytest
from _simwire import decode, spx

from spotlab.simulators import wire


def hexbytes(text: str) -> bytes:
    return bytes.fromhex(text.replace("\n", " "))


def test_crc_check_value() -> None:
    from spotlab.core.crc import crc16

    assert crc16(b"123456789") == 0x29B1


@pytest.mark.parametrize(
    ("text", "golden"),
    [
        ("OKAY", "4F 4B 41 59 32 36 43 46 0D"),
        ("ERROR80", "45 52 52 4F 52 38 30 43 46 35 33 0D"),
        ("ERROR04", "45 52 52 4F 52 30 34 30 36 37 45 0D"),
        ("RESET", "52 45 53 45 54 37 44 42 32 0D"),
    ],
)
def test_golden_replies(text: str, golden: str) -> None:
    assert wire.reply(text) == hexbytes(golden)


def test_golden_banner_constant() -> None:
    assert wire.BANNER == b"RESET7DB2\r" == hexbytes("52 45 53 45 54 37 44 42 32 0D")


def test_golden_time_and_version_replies() -> None:
    assert wire.reply("TIME 0001E240 0001E2A4") == b"TIME 0001E240 0001E2A4E2F2\r"
    assert wire.reply("SPX 1.0 SIM00042 4 128") == b"SPX 1.0 SIM00042 4 128C2DE\r"


@pytest.mark.parametrize(
    ("text", "golden"),
    [
        ("VER:0", b"VER:0F7C1\r"),
        ("COMM:8", b"COMM:88B92\r"),
        ("RATE:200000", b"RATE:2000008EC6\r"),
        ("START:", b"START:51B4\r"),
        ("STOP:", b"STOP:FD1C\r"),
        ("CONF:", b"CONF:621B\r"),
        ("CAMS:2", b"CAMS:2BD12\r"),
        ("LEDT:008005C01140", b"LEDT:008005C01140E8FF\r"),
        ("SLOT:100", b"SLOT:1000B9E\r"),
        ("BGND:1", b"BGND:1587B\r"),
        ("AGC:1,160", b"AGC:1,1608496\r"),
    ],
)
def test_golden_commands(text: str, golden: bytes) -> None:
    assert wire.command(text) == golden


def test_golden_event_frame() -> None:
    golden = hexbytes("A5 5A 7F 10 00 00 09 00 ED D8 4F 4B 41 59 32 36 43 46 0D 5C D3")
    assert wire.event_frame(wire.reply("OKAY")) == golden


GOLDEN_FRAME = hexbytes(
    """A5 5A 01 10 FE FF 2E 00 D7 70 D2 04 00 00 00 FF FF FF 02 00 06 00 64 00 03 02
    00 08 80 C8 01   E8 83 BB B4 01   FF FF FF 03 04   23 C1 AB FF 03
    11 E0 FE 5A 11   C4 C9 5D 78 09   D3 0D""".replace("\n", " ")
)
X = [[2048, 1000], [0xFFF, 0x123], [17, 2500]]
Y = [[2048, 3000], [0xFFF, 0xABC], [4078, 1500]]
I = [[200, 180], [3, 255], [90, 120]]  # noqa: E741
F = [[0x01, 0x01], [0x04, 0x03], [0x11, 0x09]]


def test_golden_data_frame_bytes() -> None:
    payload = wire.spx_payload(1234, 0xFFFFFF00, 0x0002, 100, X, Y, I, F)
    frame = wire.frame(wire.FRAME_SPX, 65534, payload)
    assert len(frame) == 58 == wire.spx_frame_length(3, 2)
    assert frame == GOLDEN_FRAME


def test_golden_data_frame_reads_back_with_independent_decoder() -> None:
    got = decode(GOLDEN_FRAME + GOLDEN_FRAME, spx_len=46)
    assert got.crc_errors == 0 and got.resyncs == 0 and len(got.frames) == 2
    f = got.frames[0]
    assert (f["type"], f["flags"], f["seq"]) == (1, 0x10, 0xFFFE)
    d = spx(f["payload"])  # type: ignore[arg-type]
    assert (d["frame_no"], d["tick"], d["status"], d["n_items"], d["slot_us"]) == (
        1234,
        0xFFFFFF00,
        2,
        6,
        100,
    )
    np.testing.assert_array_equal(d["x"], X)
    np.testing.assert_array_equal(d["y"], Y)
    np.testing.assert_array_equal(d["intensity"], I)
    np.testing.assert_array_equal(d["flags"], F)


def test_encoder_wraps_counters_and_sets_header_flags() -> None:
    payload = wire.spx_payload(2**32 + 5, 2**32 + 7, 0, 100, [[1]], [[2]], [[3]], [[1]])
    flags = wire.header_flags(simulated=True, overrun=True, resynced=True)
    assert flags == 0x17
    got = decode(wire.frame(wire.FRAME_SPX, 65536 + 3, payload, flags))
    f = got.frames[0]
    assert f["seq"] == 3 and f["flags"] == 0x17
    d = spx(f["payload"])  # type: ignore[arg-type]
    assert d["frame_no"] == 5 and d["tick"] == 7


def test_payload_limit_is_enforced() -> None:
    with pytest.raises(ValueError, match="4096"):
        wire.frame(wire.FRAME_SPX, 0, bytes(4097))


def test_conf_reply_golden_vector() -> None:
    """docs/protocols/mcs1.md §6: the simulator's reply to ``CONF:``."""
    assert wire.reply("CONF RATE=200000 CAMS=2") == bytes.fromhex(
        "43 4F 4E 46 20 52 41 54 45 3D 32 30 30 30 30 30 20 43 41 4D 53 3D 32 38 31 32 36 0D"
    )
