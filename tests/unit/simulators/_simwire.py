"""A tiny independent host side for the simulator tests, written from mcs1.md / selspot.md.

It does not use ``spotlab.simulators.wire`` (the encoder under test) nor the
driver: frames are found and checked with ``binascii.crc_hqx`` and ``struct``.
"""

from __future__ import annotations

import binascii
import struct
from dataclasses import dataclass, field

import numpy as np

from spotlab.simulators.selspot import SelspotDevice


def crc(data: bytes) -> int:
    return binascii.crc_hqx(data, 0xFFFF)


def cmd(text: str) -> bytes:
    """A command in CRC form."""
    return f"{text}{crc(text.encode()):04X}\r".encode()


def reply_text(raw: bytes) -> str:
    """Text of a reply ``TEXT`` + CRC + ``\\r`` after checking its CRC."""
    assert raw.endswith(b"\r"), raw
    body = raw[:-1]
    text, check = body[:-4], body[-4:]
    assert f"{crc(text):04X}".encode() == check, raw
    return text.decode()


@dataclass
class Decoded:
    frames: list[dict[str, object]] = field(default_factory=list)
    crc_errors: int = 0
    resyncs: int = 0
    skipped: int = 0
    rest: bytes = b""


def decode(buf: bytes, spx_len: int | None = None) -> Decoded:
    """Find frames per MCS-1 §4 (resync rules included).

    ``spx_len``: the expected payload length of type-1 frames (a mismatch is a header error).
    """
    out = Decoded()
    i = 0
    skipping = False
    n = len(buf)
    while True:
        j = buf.find(b"\xa5\x5a", i)
        if j < 0:
            if n - i > 1:
                out.skipped += n - i - 1
                i = n - 1
            break
        if j > i:
            out.skipped += j - i
            if not skipping:
                out.resyncs += 1
            skipping = True
        i = j
        if n - i < 10:
            break
        head = buf[i : i + 8]
        (hcrc,) = struct.unpack_from("<H", buf, i + 8)
        ftype, flags, seq, length = struct.unpack_from("<BBHH", buf, i + 2)
        bad_len = length > 4096 or (ftype == 1 and spx_len is not None and length != spx_len)
        if crc(head) != hcrc or bad_len:
            out.crc_errors += 1
            i += 1
            skipping = True
            continue
        if n - i < length + 12:
            break
        payload = buf[i + 10 : i + 10 + length]
        (pcrc,) = struct.unpack_from("<H", buf, i + 10 + length)
        if crc(payload) != pcrc:
            out.crc_errors += 1
            i += 2
            skipping = True
            continue
        out.frames.append({"type": ftype, "flags": flags, "seq": seq, "payload": payload})
        i += length + 12
        skipping = False
    out.rest = buf[i:]
    return out


def spx(payload: bytes) -> dict[str, object]:
    """Decode an SPX data payload (selspot.md §4)."""
    frame_no, tick, status, n_items, slot_us, n_leds, n_cams = struct.unpack_from(
        "<IIHHHBB", payload
    )
    rec = (
        np.frombuffer(payload, dtype=np.uint8, offset=16)
        .reshape(n_leds, n_cams, 5)
        .astype(np.uint32)
    )
    word = rec[..., 0] | (rec[..., 1] << 8) | (rec[..., 2] << 16)
    return {
        "frame_no": frame_no,
        "tick": tick,
        "status": status,
        "n_items": n_items,
        "slot_us": slot_us,
        "n_leds": n_leds,
        "n_cams": n_cams,
        "x": (word & 0xFFF).astype(np.int64),
        "y": (word >> 12).astype(np.int64),
        "intensity": rec[..., 3].astype(np.int64),
        "flags": rec[..., 4].astype(np.int64),
    }


MS = 1_000_000
S = 1_000_000_000
T0 = 10**12


class Host:
    """Drives a device in simulated time: write, wait, read."""

    def __init__(self, device: SelspotDevice, t: int = T0) -> None:
        self.dev = device
        self.t = t
        self.buf = bytearray()

    def wait(self, ns: int) -> bytes:
        self.t += ns
        got = self.dev.output(self.t)
        self.buf += got
        return got

    def send(self, data: bytes, baud: int | None = None) -> None:
        self.dev.receive(data, self.t, line_baud=baud)

    def ask_raw(self, text: str, wait_ns: int = 100 * MS, raw: bytes | None = None) -> bytes:
        self.buf.clear()
        self.send(raw if raw is not None else cmd(text))
        self.wait(wait_ns)
        return bytes(self.buf)

    def ask(self, text: str, wait_ns: int = 100 * MS) -> str:
        """Reply text of a command; only the first reply when frames follow (``START:``)."""
        raw = self.ask_raw(text, wait_ns)
        return reply_text(
            raw[: raw.find(b"\r") + 1] if raw.startswith((b"OKAY", b"ERROR")) else raw
        )

    def configure(
        self, cams: int, leds: int, rate_mhz: int, comm: int = 8, extra: tuple[str, ...] = ()
    ) -> None:
        """Reset, raise the baud rate, set a table of ``leds`` LEDs at 32 mA."""
        self.dev.send_break(self.t)
        self.wait(20 * MS)
        self.buf.clear()
        assert self.ask(f"COMM:{comm}") == "OKAY"
        table = "".join(f"{i:02X}80" for i in range(leds))
        for text in (f"CAMS:{cams}", f"LEDT:{table}", f"RATE:{rate_mhz}", *extra):
            assert self.ask(text, 20 * MS) == "OKAY", text
