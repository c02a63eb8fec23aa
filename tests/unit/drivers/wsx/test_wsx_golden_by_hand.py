"""Every golden vector of docs/protocols/wsx.md built again by hand with ``struct``,
straight from the spec's field tables (offsets, types, little-endian, CRC-32 as §5
defines it), and compared with the bytes the page shows.

The vectors were produced with ``simulators/wsx_wire.py`` and pasted into the page,
so the codec and simulator tests that compare with them partly check the simulator
against itself. This module imports neither the driver nor the simulator: each
vector is packed here field by field from the tables and the vector's caption.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import pytest

from spotlab.testing.golden import golden_vector

SPEC = Path(__file__).resolve().parents[4] / "docs" / "protocols" / "wsx.md"


def _golden(name: str) -> bytes:
    return golden_vector(SPEC, name)


def _pack(fields: list[tuple[int, str, object]], size: int) -> bytes:
    """``size`` zero bytes with each ``(offset, struct format, value)`` packed in place.

    Formats are little-endian (the spec: "Every number is little-endian"); fields
    must not overlap and must fill the record exactly.
    """
    out = bytearray(size)
    used = [False] * size
    for offset, fmt, value in fields:
        f = struct.Struct("<" + fmt)
        span = range(offset, offset + f.size)
        assert span.stop <= size and not any(used[i] for i in span), (offset, fmt)
        for i in span:
            used[i] = True
        f.pack_into(out, offset, *(value if isinstance(value, tuple) else (value,)))
    assert all(used), f"bytes {[i for i, u in enumerate(used) if not u]} are in no field"
    return bytes(out)


# -- §2 descriptors (USB 2.0 chapter 9 layouts with the values of §2's table) -------------


def test_device_descriptor() -> None:
    expected = _pack(
        [
            (0, "B", 18),  # bLength
            (1, "B", 1),  # DEVICE
            (2, "H", 0x0200),  # bcdUSB 2.00
            (4, "B", 0xFF),  # vendor class
            (5, "B", 0),
            (6, "B", 0),
            (7, "B", 64),  # bMaxPacketSize0
            (8, "H", 0x1209),  # VID
            (10, "H", 0x0010),  # PID
            (12, "H", 0x0102),  # bcdDevice: firmware 1.2
            (14, "B", 1),  # iManufacturer
            (15, "B", 2),  # iProduct
            (16, "B", 3),  # iSerialNumber
            (17, "B", 1),  # bNumConfigurations
        ],
        18,
    )
    assert _golden("Device descriptor") == expected


def test_configuration_descriptor() -> None:
    configuration = _pack(
        [(0, "B", 9), (1, "B", 2), (2, "H", 32), (4, "B", 1), (5, "B", 1), (6, "B", 0),
         (7, "B", 0x80), (8, "B", 100 // 2)],  # bus powered, 100 mA in 2 mA units
        9,
    )  # fmt: skip
    interface = _pack(
        [(0, "B", 9), (1, "B", 4), (2, "B", 0), (3, "B", 0), (4, "B", 2), (5, "B", 0xFF),
         (6, "B", 0), (7, "B", 0), (8, "B", 0)],
        9,
    )  # fmt: skip
    bulk_in = _pack([(0, "B", 7), (1, "B", 5), (2, "B", 0x81), (3, "B", 2), (4, "H", 512),
                     (6, "B", 0)], 7)  # fmt: skip
    interrupt_in = _pack([(0, "B", 7), (1, "B", 5), (2, "B", 0x82), (3, "B", 3), (4, "H", 16),
                          (6, "B", 4)], 7)  # fmt: skip
    assert _golden("Configuration descriptor") == configuration + interface + bulk_in + interrupt_in


def test_serial_string() -> None:
    text = "WSX00042".encode("utf-16-le")
    assert _golden("Serial string") == struct.pack("<BB", 2 + len(text), 3) + text


# -- §3, §4 control records -----------------------------------------------------------


def test_information() -> None:
    expected = _pack(
        [
            (0, "H", 0x0102),  # firmware 1.2
            (2, "B", 3),  # sensors
            (3, "B", 3),  # CCDs per sensor
            (4, "H", 2048),  # pixels
            (6, "H", 512),  # max markers
            (8, "I", 1_000_000_000),  # clock Hz
            (12, "H", 4),  # strober ports
            (14, "H", 0),  # reserved
        ],
        16,
    )
    assert _golden("Information") == expected


def _setup(frame_rate_mhz: int) -> bytes:
    """§4.1: 24 markers, 8 on ports 1-3, duty 350, 4600 Hz, 8.0 V, 30, 160, FULL_RAW."""
    return _pack(
        [
            (0, "H", 24),
            (2, "4H", (8, 8, 8, 0)),
            (10, "H", 350),
            (12, "I", 4_600_000),
            (16, "I", frame_rate_mhz),
            (20, "H", 80),
            (22, "B", 30),
            (23, "B", 0),
            (24, "H", 160),
            (26, "H", 0b10),  # bit 1 FULL_RAW
            (28, "I", 0),
        ],
        32,
    )


def test_set_up_and_its_bound() -> None:
    highest = 4_600_000 // (24 + 2)  # mHz: 4600 / 26 Hz, "the highest for 24 markers"
    assert highest == 176_923
    assert _golden("Set-up") == _setup(highest)
    assert _golden("Refused set-up") == _setup(200_000)
    assert 200_000 > 4_600_000 / 26  # refused: error 0x24


@pytest.mark.parametrize(
    ("name", "fields"),
    [
        ("Status", (1, 0, 0, 1000, 0, 123_456)),
        ("Status after the refused set-up", (0, 0x24, 0, 0, 0, 2000)),
    ],
)
def test_status(name: str, fields: tuple[int, ...]) -> None:
    offsets = [(0, "B"), (1, "B"), (2, "H"), (4, "I"), (8, "I"), (12, "I")]
    expected = _pack([(o, f, v) for (o, f), v in zip(offsets, fields, strict=True)], 16)
    assert _golden(name) == expected


def test_calibration() -> None:
    header = _pack([(0, "B", 0), (1, "B", 3), (2, "H", 60), (4, "B", 0), (5, "3s", b"")], 8)
    identity = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    ccds = b""
    # CCD 0 and 2 measure along x, CCD 1 along y (§1); each at x = C, 3 m away:
    # x = R X + t with R = I, so t = (-C, 0, 3000).
    for ccd, (axis, centre_x) in enumerate([(0, -450.0), (1, 0.0), (0, 450.0)]):
        ccds += _pack(
            [
                (0, "B", ccd),
                (1, "B", axis),
                (2, "H", 0),
                (4, "f", 1750.0),
                (8, "f", 1024.0),
                (12, "9f", identity),
                (48, "3f", (-centre_x + 0.0, 0.0, 3000.0)),
            ],
            60,
        )
    expected = header + ccds
    assert len(expected) == 188
    assert _golden("Calibration") == expected


# -- §5 frames, §6 events ---------------------------------------------------------------

MISSING = b"\xee\xee\xee\xee"


def _ccd(centroid: float | None, peak: int, code: int) -> bytes:
    value = MISSING if centroid is None else struct.pack("<f", centroid)
    return value + struct.pack("<HBB", peak, code, 0)


def test_frame() -> None:
    markers, sensors = 2, 1
    size = 32 + markers * (4 + 24 * sensors) + 4
    assert size == 92
    header = _pack(
        [
            (0, "4s", b"WSXF"),
            (4, "I", size),
            (8, "I", 1234),
            (12, "H", 0),
            (14, "H", markers),
            (16, "B", sensors),
            (17, "B", 3),
            (18, "H", 0),
            (20, "Q", 5_000_000_000),
            (28, "I", 0),
        ],
        32,
    )
    # Marker k fires at (k + duty/2) / marker_rate after the frame's start (§1).
    fire = [round((k + 0.35 / 2) / 4600 * 1e9) for k in range(markers)]
    assert fire == [38_043, 255_435]
    # The peaks are not in the caption except marker 0's third (4095): these are the
    # vector's (the spec gives them no rule); everything else is from the caption.
    body = (
        struct.pack("<I", fire[0])
        + _ccd(1024.5, 2000, 0)
        + _ccd(1000.25, 1800, 0)
        + _ccd(-1.0, 4095, 3)
        + struct.pack("<I", fire[1])
        + _ccd(1100.0, 1500, 0)
        + _ccd(None, 0, 2)
        + _ccd(980.75, 1200, 10)
    )
    before = header + body
    expected = before + struct.pack("<I", zlib.crc32(before))
    golden = _golden("Frame")
    assert golden == expected
    assert struct.unpack_from("<f", MISSING)[0] < -3.0e28  # the missing value's test
    assert abs(struct.unpack_from("<f", MISSING)[0] - -3.697314e28) < 1e22


def test_event() -> None:
    expected = _pack(
        [(0, "4s", b"WSXE"), (4, "H", 1), (6, "H", 0), (8, "I", 1234), (12, "I", 3)], 16
    )
    assert _golden("Event") == expected


# -- §8 USB over a socket -----------------------------------------------------------------


def test_link_status_request_and_reply() -> None:
    args = struct.pack("<BBHHHI", 0xC0, 0x04, 0, 0, 16, 1000)
    body = struct.pack("<B", 7) + args
    assert _golden("Link STATUS request") == struct.pack("<I", len(body)) + body
    status = _golden("Status")
    reply = struct.pack("<i", len(status)) + status
    assert _golden("Link STATUS reply") == struct.pack("<I", len(reply)) + reply


def test_link_read_request_and_stall() -> None:
    body = struct.pack("<BBII", 8, 0x81, 16_384, 100)
    assert _golden("Link READ request") == struct.pack("<I", len(body)) + body
    assert _golden("Link stall reply") == struct.pack("<Ii", 4, -9)
