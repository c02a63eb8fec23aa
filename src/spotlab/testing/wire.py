"""Raw MCS-1 exchanges for conformance tests, written from docs/protocols/mcs1.md.

These helpers talk to a device with plain pyserial so that a conformance test
checks the device (or simulator) against the spec, not against the driver.
"""

from __future__ import annotations

import time

import serial

from spotlab.core.crc import crc16_hex

BANNER = b"RESET7DB2\r"
SYNC = b"\xa5\x5a"


def command(text: str) -> bytes:
    """``VERB:ARGS`` with its CRC and carriage return."""
    return text.encode("ascii") + crc16_hex(text).encode("ascii") + b"\r"


def read_until(port: serial.Serial, terminator: bytes, timeout: float) -> bytes:
    """Bytes up to and including ``terminator``; whatever came if the time ran out."""
    deadline = time.monotonic() + timeout
    out = bytearray()
    while time.monotonic() < deadline:
        chunk = port.read(max(1, port.in_waiting))
        if chunk:
            out += chunk
            end = out.find(terminator)
            if end >= 0:
                return bytes(out[: end + len(terminator)])
    return bytes(out)


def check_reply(raw: bytes) -> str:
    """The text of a reply after checking its CRC.

    Raises
    ------
    AssertionError
        If the reply is not ``TEXT`` + 4 hex digits of CRC + ``\\r``.
    """
    assert raw.endswith(b"\r"), f"reply not ended by CR: {raw!r}"
    body = raw[:-1].decode("ascii", errors="replace")
    assert len(body) >= 5, f"reply too short: {raw!r}"
    text, crc = body[:-4], body[-4:]
    assert crc16_hex(text) == crc, f"reply CRC {crc} does not match {crc16_hex(text)} for {text!r}"
    return text


def ask(port: serial.Serial, text: str, timeout: float = 1.0) -> str:
    """Send a command, return the checked reply text."""
    port.write(command(text))
    return check_reply(read_until(port, b"\r", timeout))


def reset(port: serial.Serial, timeout: float = 2.0) -> None:
    """Put the device at 9600 baud with its banner (BREAK, then ``RESET:``)."""
    port.baudrate = 9600
    port.reset_input_buffer()
    port.write(command("RESET:"))
    got = read_until(port, BANNER, timeout)
    assert got.endswith(BANNER), f"no reset banner, got {got[-40:]!r}"
