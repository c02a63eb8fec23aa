"""WSX bytes on the device side, written from docs/protocols/wsx.md.

Pure functions: descriptors (§2), vendor requests and their records (§3, §4),
bulk frames (§5), interrupt events (§6) and the messages of the USB-over-socket
link (§8). Never imported by the driver; checked against the spec's golden
vectors in ``tests/unit/simulators/test_sim_wsx_wire.py``.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

VID, PID = 0x1209, 0x0010
MANUFACTURER, PRODUCT = "spotlab", "WSX position sensor hub"
EP_FRAMES, EP_EVENTS = 0x81, 0x82
BULK_PACKET, EVENT_BYTES = 512, 16
CCDS = 3
PIXELS = 2048
PORTS = 4
FIRMWARE = 0x0102
BAD_FLOAT = struct.unpack("<f", struct.pack("<f", -3.697314e28))[0]

# Vendor requests (§3)
REQ_INFO, REQ_SET_SETUP, REQ_GET_SETUP, REQ_STATUS = 0x01, 0x02, 0x03, 0x04
REQ_CALIBRATION, REQ_START, REQ_STOP = 0x05, 0x06, 0x07
# Error codes (§4.3)
E_NONE, E_UNKNOWN, E_LENGTH, E_BUSY = 0x00, 0x01, 0x02, 0x0C
E_MARKERS, E_PORTS, E_MARKER_RATE, E_FRAME_RATE = 0x21, 0x22, 0x23, 0x24
E_DUTY, E_VOLTAGE, E_THRESHOLD, E_GAIN, E_FLAGS, E_SENSOR = 0x25, 0x26, 0x27, 0x28, 0x29, 0x2A
# Set-up flags (§4.1)
FLAG_NO_INTERPOLATION, FLAG_FULL_RAW = 0x0001, 0x0002
# Quality codes (§5)
OK, TOO_WIDE, TOO_SMALL, TOO_LARGE, OFF_DEVICE = 0, 1, 2, 3, 4
EXTRA_PEAK = 10
# Frame flags and status bits
FRAME_NO_INTERP, FRAME_AFTER_DROP = 0x0001, 0x0004
STATUS_OVERFLOW, STATUS_AMBIENT = 0x0001, 0x0002
# Events (§6)
EV_OVERFLOW, EV_AMBIENT, EV_STALL = 1, 2, 3

SETUP = struct.Struct("<HHHHHHIIHBBHHI")
INFO = struct.Struct("<HBBHHIHH")
STATUS = struct.Struct("<BBHIII")
FRAME_HEADER = struct.Struct("<4sIIHHBBHQI")  # magic length frame_no flags M S ccds 0 start dropped
CCD_RECORD = struct.Struct("<fHBB")
CAL_HEADER = struct.Struct("<BBH4s")
CAL_CCD = struct.Struct("<BBBBff9f3f")
EVENT = struct.Struct("<4sHHII")


@dataclass
class Setup:
    """A set-up record (§4.1); the defaults are the device's after power-up."""

    markers: int = 8
    ports: tuple[int, int, int, int] = (8, 0, 0, 0)
    duty_permille: int = 350
    marker_rate_mhz: int = 2_500_000
    frame_rate_mhz: int = 100_000
    voltage_dv: int = 80
    threshold: int = 30
    gain: int = 160
    flags: int = FLAG_FULL_RAW


def encode_setup(s: Setup) -> bytes:
    """The 32-byte set-up record."""
    return SETUP.pack(
        s.markers, *s.ports, s.duty_permille, s.marker_rate_mhz, s.frame_rate_mhz,
        s.voltage_dv, s.threshold, 0, s.gain, s.flags, 0,
    )  # fmt: skip


def parse_setup(data: bytes) -> tuple[Setup, int]:
    """A set-up record and the error code the device answers it with (§4.3 order)."""
    if len(data) != SETUP.size:
        return Setup(), E_LENGTH
    n, p1, p2, p3, p4, duty, mrate, frate, volt, thr, res1, gain, flags, res2 = SETUP.unpack(data)
    s = Setup(n, (p1, p2, p3, p4), duty, mrate, frate, volt, thr, gain, flags)
    if not 1 <= n <= 512:
        return s, E_MARKERS
    if p1 + p2 + p3 + p4 != n:
        return s, E_PORTS
    if not 1_500_000 <= mrate <= 4_600_000:
        return s, E_MARKER_RATE
    if frate < 1 or frate * (n + 2) > mrate:
        return s, E_FRAME_RATE
    if not 100 <= duty <= 850:
        return s, E_DUTY
    if not 70 <= volt <= 120:
        return s, E_VOLTAGE
    if thr < 1:
        return s, E_THRESHOLD
    if not 1 <= gain <= 1000:
        return s, E_GAIN
    if flags & ~(FLAG_NO_INTERPOLATION | FLAG_FULL_RAW) or res1 or res2:
        return s, E_FLAGS
    return s, E_NONE


def encode_info(n_sensors: int, max_markers: int = 512) -> bytes:
    """The 16-byte information record (§3)."""
    return INFO.pack(FIRMWARE, n_sensors, CCDS, PIXELS, max_markers, 1_000_000_000, PORTS, 0)


def encode_status(
    streaming: bool, last_error: int, bits: int, sent: int, dropped: int, uptime_ms: int
) -> bytes:
    """The 16-byte status record (§4.2)."""
    return STATUS.pack(int(streaming), last_error, bits, sent, dropped, uptime_ms & 0xFFFFFFFF)


def encode_calibration(
    sensor: int,
    axes: Sequence[int],
    focal: Sequence[float],
    principal: Sequence[float],
    rotations: NDArray[np.float64],
    translations: NDArray[np.float64],
    frame: int = 0,
) -> bytes:
    """A position sensor's factory calibration record (§4.4): three CCDs, in the device
    frame (``frame`` 0) or the sensor's own (1)."""
    out = bytearray(CAL_HEADER.pack(sensor, CCDS, CAL_CCD.size, bytes([frame, 0, 0, 0])))
    for c in range(CCDS):
        out += CAL_CCD.pack(
            c, int(axes[c]), 0, 0, float(focal[c]), float(principal[c]),
            *np.asarray(rotations[c], dtype=np.float64).reshape(9),
            *np.asarray(translations[c], dtype=np.float64),
        )  # fmt: skip
    return bytes(out)


def encode_frame(
    frame_no: int,
    start_ns: int,
    flags: int,
    fire_ns: NDArray[np.int64],
    centroid: NDArray[np.float64],
    peak: NDArray[np.int64],
    code: NDArray[np.int64],
    gain_code: int = 0,
    dropped: int = 0,
) -> bytes:
    """A data frame (§5).

    Parameters
    ----------
    fire_ns : ndarray, shape (M,)
        Each marker's firing instant after ``start_ns``.
    centroid : ndarray, shape (M, S, 3)
        Readings (px); NaN is written as BAD_FLOAT.
    peak, code : ndarray, shape (M, S, 3)
        Peak (12-bit counts) and quality code of each reading.
    dropped : int
        Frames the device has dropped (FIFO full) since ``START``.
    """
    m, s, c = centroid.shape
    rec = np.zeros((m,), dtype=_marker_dtype(s))
    rec["fire_ns"] = fire_ns
    rec["ccd"]["centroid"] = np.where(np.isfinite(centroid), centroid, BAD_FLOAT)
    rec["ccd"]["peak"] = peak
    rec["ccd"]["code"] = code
    rec["ccd"]["gain"] = gain_code
    length = FRAME_HEADER.size + rec.nbytes + 4
    head = FRAME_HEADER.pack(b"WSXF", length, frame_no, flags, m, s, c, 0, start_ns, dropped)
    body = head + rec.tobytes()
    return body + struct.pack("<I", zlib.crc32(body))


def _marker_dtype(s: int) -> np.dtype[np.void]:
    """One marker's record: firing time, then S x 3 CCD records of 8 bytes."""
    ccd = np.dtype([("centroid", "<f4"), ("peak", "<u2"), ("code", "u1"), ("gain", "u1")])
    return np.dtype([("fire_ns", "<u4"), ("ccd", ccd, (s, CCDS))])


def encode_event(code: int, frame_no: int, detail: int) -> bytes:
    """A 16-byte interrupt event (§6)."""
    return EVENT.pack(b"WSXE", code, 0, frame_no, detail)


# -- descriptors (§2) ------------------------------------------------------------------
def device_descriptor() -> bytes:
    """The 18-byte device descriptor."""
    return struct.pack(
        "<BBHBBBBHHHBBBB", 18, 1, 0x0200, 0xFF, 0, 0, 64, VID, PID, FIRMWARE, 1, 2, 3, 1
    )


def configuration_descriptor() -> bytes:
    """Configuration, interface and both endpoint descriptors (32 bytes)."""
    return (
        struct.pack("<BBHBBBBB", 9, 2, 32, 1, 1, 0, 0x80, 50)
        + struct.pack("<BBBBBBBBB", 9, 4, 0, 0, 2, 0xFF, 0, 0, 0)
        + struct.pack("<BBBBHB", 7, 5, EP_FRAMES, 2, BULK_PACKET, 0)
        + struct.pack("<BBBBHB", 7, 5, EP_EVENTS, 3, EVENT_BYTES, 4)
    )


def string_descriptor(index: int, serial: str) -> bytes | None:
    """String descriptor ``index`` (0: the language list), None if there is none."""
    if index == 0:
        return bytes([4, 3, 0x09, 0x04])
    text = {1: MANUFACTURER, 2: PRODUCT, 3: serial}.get(index)
    if text is None:
        return None
    body = text.encode("utf-16-le")
    return bytes([2 + len(body), 3]) + body


# -- the link (§8) ---------------------------------------------------------------------
OP_LIST, OP_OPEN, OP_CLOSE, OP_SET_CONFIG, OP_CLAIM, OP_RELEASE = 1, 2, 3, 4, 5, 6
OP_CONTROL, OP_READ, OP_WRITE, OP_CLEAR_HALT = 7, 8, 9, 10
CONTROL = struct.Struct("<BBHHHI")
READ = struct.Struct("<BII")


def reply(status: int, data: bytes = b"") -> bytes:
    """A link reply: u32 length, i32 status, data."""
    return struct.pack("<Ii", 4 + len(data), status) + data


def list_entry(bus: int, address: int, port: int) -> bytes:
    """One device of an ``OP_LIST`` reply."""
    config = configuration_descriptor()
    return (
        bytes([bus, address, port]) + device_descriptor() + struct.pack("<H", len(config)) + config
    )
