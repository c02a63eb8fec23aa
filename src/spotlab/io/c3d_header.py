"""The 512-byte C3D header, read in any processor format and written as Intel.

Word numbers below are the C3D manual's (16-bit words counted from 1).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

import numpy as np

from spotlab.io.c3d_parameters import PROCESSORS, dec_to_ieee

#: Key in word 150 that marks 4-character header event labels.
EVENT_KEY = 0x3039
MAX_HEADER_EVENTS = 18


@dataclass
class C3DHeader:
    """The header's fields.

    Attributes
    ----------
    parameter_block : int
        Block (of 512 bytes, counted from 1) where the parameter section starts.
    point_count : int
        3-D points per frame (word 2).
    analog_count : int
        Analog values per frame, all channels and samples (word 3).
    first_frame, last_frame : int
        Frame numbers (words 4, 5; 16-bit unsigned).
    scale_factor : float
        POINT:SCALE as the header has it (negative: float storage).
    data_block : int
        Block where the data section starts (word 9).
    analog_per_frame : int
        Analog samples per channel and frame (word 10).
    frame_rate : float
        Point frames per second (words 11-12).
    events : list of (str, float)
        Header events (up to 18): 4-character label and time in seconds.
    """

    parameter_block: int = 2
    point_count: int = 0
    analog_count: int = 0
    first_frame: int = 1
    last_frame: int = 1
    max_gap: int = 0
    scale_factor: float = -1.0
    data_block: int = 3
    analog_per_frame: int = 0
    frame_rate: float = 0.0
    events: list[tuple[str, float]] = field(default_factory=list)


def read_processor(raw: bytes, section: bytes) -> str:
    """The processor format from byte 4 of the parameter section.

    Raises
    ------
    ValueError
        The header's second byte is not 0x50 (not a C3D file) or the code is unknown.
    """
    if len(raw) < 512 or raw[1] != 0x50:
        raise ValueError("no C3D header (the second byte is not 0x50)")
    code = section[3] if len(section) >= 4 else 0
    if code not in PROCESSORS:
        raise ValueError(f"unknown processor type {code} in the parameter section")
    return PROCESSORS[code]


def parse_header(raw: bytes, processor: str) -> C3DHeader:
    """The header of a file whose parameter section says ``processor``.

    Parameters
    ----------
    raw : bytes, length >= 512
    processor : str
        "INTEL", "DEC" or "MIPS" (word order and float format of the whole file).
    """
    order = ">" if processor == "MIPS" else "<"
    words = struct.unpack(order + "256H", raw[:512])

    def real(offset: int) -> float:
        four = raw[offset : offset + 4]
        if processor == "DEC":
            return float(dec_to_ieee(four)[0])
        return float(struct.unpack(order + "f", four)[0])

    header = C3DHeader(
        parameter_block=raw[0],
        point_count=words[1],
        analog_count=words[2],
        first_frame=words[3],
        last_frame=words[4],
        max_gap=words[5],
        scale_factor=real(12),
        data_block=words[8],
        analog_per_frame=words[9],
        frame_rate=real(20),
    )
    n_events = min(words[150], MAX_HEADER_EVENTS)
    for i in range(n_events):
        label = raw[396 + 4 * i : 400 + 4 * i].decode("latin-1").replace("\x00", " ").strip()
        header.events.append((label, real(304 + 4 * i)))
    return header


def serialize_header(header: C3DHeader) -> bytes:
    """An Intel header (512 bytes) with ``header``'s fields; 16-bit fields capped at 65535."""
    raw = bytearray(512)
    raw[0] = header.parameter_block
    raw[1] = 0x50

    def word(number: int, value: int) -> None:
        struct.pack_into("<H", raw, 2 * (number - 1), min(max(int(value), 0), 65535))

    word(2, header.point_count)
    word(3, header.analog_count)
    word(4, header.first_frame)
    word(5, header.last_frame)
    word(6, header.max_gap)
    struct.pack_into("<f", raw, 12, header.scale_factor)
    word(9, header.data_block)
    word(10, header.analog_per_frame)
    struct.pack_into("<f", raw, 20, header.frame_rate)
    events = header.events[:MAX_HEADER_EVENTS]
    if events:
        word(150, EVENT_KEY)
        word(151, len(events))
        times = np.array([t for _, t in events], dtype="<f4")
        raw[304 : 304 + 4 * len(events)] = times.tobytes()
        raw[376 : 376 + len(events)] = b"\x01" * len(events)  # displayed
        labels = b"".join(lab.encode("latin-1", "replace")[:4].ljust(4) for lab, _ in events)
        raw[396 : 396 + len(labels)] = labels
    return bytes(raw)
