"""WSX records on the host side, written from docs/protocols/wsx.md (§2-§6).

The set-up (§4.1) with its encoder and the device's error codes (§4.3), the
information, status and factory-calibration records, and the layout of a frame's
marker records as a numpy dtype, so that frames decode without a Python loop.
"""

from __future__ import annotations

import struct
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import ProtocolError

VENDOR_ID, PRODUCT_ID = 0x1209, 0x0010
EP_FRAMES, EP_EVENTS = 0x81, 0x82
VENDOR_IN, VENDOR_OUT = 0xC0, 0x40
INFO, SET_SETUP, GET_SETUP, STATUS, CALIBRATION, START, STOP = 1, 2, 3, 4, 5, 6, 7
NO_INTERPOLATION, FULL_RAW = 0x0001, 0x0002
FRAME_MAGIC, EVENT_MAGIC = b"WSXF", b"WSXE"
HEADER = struct.Struct("<4sIIHHBBHQI")
EVENT_SIZE = 16
#: Centroids below this are Optotrak's missing value (-3.697314e28).
MISSING_BELOW = -3.0e28
CCDS = 3
CODE_NAMES = (
    "good", "waveform too wide", "peak too small", "peak too large", "waveform off the device",
    "fell behind", "last centroid bad", "buffer overflow", "missed CCD", "bad CRC", "extra peak",
)  # fmt: skip
ERRORS = {
    0x01: "unknown request",
    0x02: "wrong data length",
    0x0C: "not while streaming",
    0x21: "markers must be 1-512",
    0x22: "the strober port counts must sum to the markers",
    0x23: "marker rate must be 1500-4600 Hz",
    0x24: "frame rate must be above 0 and at most marker rate / (markers + 2)",
    0x25: "duty cycle must be 10-85 %",
    0x26: "LED voltage must be 7-12 V",
    0x27: "threshold must be 1-255",
    0x28: "gain must be 1-1000",
    0x29: "unknown flags or reserved bytes not zero",
    0x2A: "no such position sensor",
}

_SETUP = struct.Struct("<HHHHHHIIHBBHHI")
_INFO = struct.Struct("<HBBHHIHH")
_STATUS = struct.Struct("<BBHIII")
_CAL_HEADER = struct.Struct("<BBH4s")
_CAL_CCD = struct.Struct("<BBHff9f3f")


def error_text(code: int) -> str:
    """``0x24 (frame rate must be ...)`` for a device error code."""
    return f"0x{code:02X} ({ERRORS.get(code, 'unknown error')})"


@dataclass(frozen=True)
class Setup:
    """A collection set-up (wsx.md §4.1), in the device's units."""

    markers: int
    ports: tuple[int, int, int, int]
    duty_permille: int
    marker_rate_mhz: int
    frame_rate_mhz: int
    voltage_dv: int
    threshold: int
    gain: int
    flags: int

    def encode(self) -> bytes:
        """The 32 bytes of ``SET_SETUP``."""
        return _SETUP.pack(
            self.markers, *self.ports, self.duty_permille, self.marker_rate_mhz,
            self.frame_rate_mhz, self.voltage_dv, self.threshold, 0, self.gain, self.flags, 0,
        )  # fmt: skip

    @classmethod
    def decode(cls, data: bytes) -> Setup:
        """A ``GET_SETUP`` record."""
        if len(data) != _SETUP.size:
            raise ProtocolError(f"a WSX set-up is {_SETUP.size} bytes, got {len(data)}")
        n, p1, p2, p3, p4, duty, mr, fr, volt, thr, _r, gain, flags, _r2 = _SETUP.unpack(data)
        return cls(n, (p1, p2, p3, p4), duty, mr, fr, volt, thr, gain, flags)

    @property
    def rate_hz(self) -> float:
        return self.frame_rate_mhz / 1000.0

    @property
    def marker_rate_hz(self) -> float:
        return self.marker_rate_mhz / 1000.0

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["ports"] = list(self.ports)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Setup:
        p = [int(x) for x in d["ports"]]
        return cls(
            int(d["markers"]), (p[0], p[1], p[2], p[3]), int(d["duty_permille"]),
            int(d["marker_rate_mhz"]), int(d["frame_rate_mhz"]), int(d["voltage_dv"]),
            int(d["threshold"]), int(d["gain"]), int(d["flags"]),
        )  # fmt: skip


@dataclass(frozen=True)
class Info:
    """The ``INFO`` record."""

    firmware: str
    sensors: int
    ccds: int
    pixels: int
    max_markers: int
    clock_hz: int
    ports: int

    @classmethod
    def decode(cls, data: bytes) -> Info:
        if len(data) != _INFO.size:
            raise ProtocolError(f"a WSX information record is 16 bytes, got {len(data)}")
        fw, s, c, px, mm, hz, ports, _ = _INFO.unpack(data)
        return cls(f"{fw >> 8}.{fw & 0xFF}", s, c, px, mm, hz, ports)


@dataclass(frozen=True)
class Status:
    """The ``STATUS`` record."""

    streaming: bool
    last_error: int
    bits: int
    sent: int
    dropped: int
    uptime_ms: int

    @classmethod
    def decode(cls, data: bytes) -> Status:
        if len(data) != _STATUS.size:
            raise ProtocolError(f"a WSX status is 16 bytes, got {len(data)}")
        st, err, bits, sent, dropped, up = _STATUS.unpack(data)
        return cls(bool(st), err, bits, sent, dropped, up)


def parse_calibration(data: bytes, sensor: int) -> list[dict[str, Any]]:
    """The three CCDs of one position sensor's factory calibration (§4.4), JSON-safe.

    Each CCD: ``frame`` (``device``: registered at the factory; ``sensor``: in the
    position sensor's own frame), ``axis`` (0 x, 1 y), ``focal`` and ``principal`` (px),
    ``R`` (3 x 3, frame -> CCD) and ``t`` (mm), as the device stores them (float32).
    """
    if len(data) < _CAL_HEADER.size:
        raise ProtocolError(f"WSX calibration of sensor {sensor}: {len(data)} bytes")
    s, n, size, rest = _CAL_HEADER.unpack_from(data)
    frame = "device" if rest[0] == 0 else "sensor"
    if s != sensor or n != CCDS or size != _CAL_CCD.size:
        raise ProtocolError(f"WSX calibration of sensor {sensor}: bad header {data[:4].hex()}")
    if len(data) != _CAL_HEADER.size + n * size:
        raise ProtocolError(f"WSX calibration of sensor {sensor}: {len(data)} bytes")
    out = []
    for c in range(n):
        v = _CAL_CCD.unpack_from(data, _CAL_HEADER.size + c * size)
        if v[0] != c or v[1] not in (0, 1):
            raise ProtocolError(f"WSX calibration of sensor {sensor}: bad CCD record {c}")
        out.append({
            "sensor": sensor, "ccd": c, "frame": frame, "axis": v[1], "focal": v[3],
            "principal": v[4],
            "R": [list(v[5:8]), list(v[8:11]), list(v[11:14])], "t": list(v[14:17]),
        })  # fmt: skip
    return out


def marker_dtype(n_sensors: int) -> np.dtype[np.void]:
    """One marker's record in a frame (§5): firing time, then S x 3 CCD records."""
    ccd = np.dtype([("centroid", "<f4"), ("peak", "<u2"), ("code", "u1"), ("gain", "u1")])
    return np.dtype([("fire_ns", "<u4"), ("ccd", ccd, (n_sensors, CCDS))])


def frame_size(n_markers: int, n_sensors: int) -> int:
    """Bytes of one frame."""
    return HEADER.size + n_markers * marker_dtype(n_sensors).itemsize + 4


def frame_records(data: bytes, n_markers: int, n_sensors: int) -> NDArray[np.void]:
    """The marker records of one checked frame."""
    dt = marker_dtype(n_sensors)
    return np.frombuffer(data, dtype=dt, count=n_markers, offset=HEADER.size)
