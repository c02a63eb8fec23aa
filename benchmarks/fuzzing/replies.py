"""Mutated reply lines through the MCS-1 reply parser.

Replies: mutated reply lines (every ``ERRORxx`` code, ``WARNxx``, data replies,
the banner; blind damage, or damage inside the text with the CRC made valid
again) and every event payload the decoders found go to ``parse_reply`` (may
raise ``ProtocolError`` only), then ``Reply.raise_for_error`` (raises exactly the
documented ``DeviceError`` subclass for ``ERRORxx``, nothing otherwise),
``parse_version`` for ``VER:0`` replies (``ProtocolError`` only) and
``find_reply`` (never raises; returns a CRC-valid tail of the line or None).
"""

from __future__ import annotations

import random

from spotlab.core.errors import DeviceError, ProtocolError
from spotlab.drivers.mcs1.commands import (
    DeviceBandwidthError,
    DeviceConfigurationError,
    parse_reply,
)
from spotlab.drivers.mcs1.session import find_reply
from spotlab.drivers.selspot.protocol import parse_version
from spotlab.simulators import wire

from .invariants import Failure, call
from .streams import REPLY_TEXTS, crc

PREFIXES = [None, "TIME", "SPX", "STAT", "LEDQ"]


def make_reply(rng: random.Random) -> tuple[bytes, str | None]:
    """A reply line, valid or damaged, and the data prefix the parser is told to expect."""
    text = rng.choice(REPLY_TEXTS).encode()
    prefix = rng.choice(PREFIXES)
    r = rng.random()
    if r < 0.05:
        return wire.reply(text.decode()), prefix
    if r < 0.5:  # damage inside the text, CRC made valid again
        body = bytearray(text)
        for _ in range(rng.randint(1, 3)):
            body = mutate_text(rng, body)
        return bytes(body) + f"{crc(body):04X}\r".encode(), prefix
    line = bytearray(wire.reply(text.decode()))
    for _ in range(rng.randint(1, 3)):
        line = mutate_text(rng, line)
    return bytes(line), prefix


def mutate_text(rng: random.Random, b: bytearray) -> bytearray:
    if not b:
        return bytearray(rng.randbytes(rng.randint(0, 8)))
    i = rng.randrange(len(b))
    op = rng.randrange(6)
    if op == 0:
        b[i] ^= 1 << rng.randrange(8)
    elif op == 1:
        b[i] = rng.choice([0x20, 0x0D, 0x00, 0x7F, 0xFF, ord("a"), ord("F"), rng.getrandbits(8)])
    elif op == 2:
        b[i:i] = rng.choice([b" ", b"\r", b"AT", b"0", rng.randbytes(rng.randint(1, 6))])
    elif op == 3:
        del b[i : i + rng.randint(1, 4)]
    elif op == 4:
        del b[i:]
    else:
        b[i:i] = b[i : i + rng.randint(1, 20)]
    return b


def check_reply(line: bytes, prefix: str | None) -> None:
    """parse_reply and what follows it: only the documented errors, right results."""
    tail = call("find_reply", find_reply, line)
    if tail is not None and (not line.endswith(tail) or not tail.endswith(b"\r")):
        raise Failure(f"find_reply gave {tail!r}, not a reply at the end of {line!r}")
    try:
        reply = call("parse_reply", parse_reply, line, prefix, allowed=(ProtocolError,))
    except ProtocolError:
        return
    body, crc_text = line[:-5], line[-5:-1]
    ok_crc = line.endswith(b"\r") and crc_text == f"{crc(body):04X}".encode()
    if not ok_crc or reply.raw != line or reply.text.encode("ascii") != body or tail != line:
        raise Failure(f"parse_reply accepted {line!r} as {reply!r}")
    kind, text, code = reply.kind, reply.text, reply.code
    if kind == "okay":
        good = text == "OKAY" and code is None
    elif kind in ("error", "warn"):
        word = "ERROR" if kind == "error" else "WARN"
        good = code is not None and text == f"{word}{code:02X}"
    elif kind == "data":
        good = prefix is not None and (text == prefix or text.startswith(prefix + " "))
    else:
        good = False
    if not good:
        raise Failure(f"parse_reply({line!r}, {prefix!r}) gave {reply!r}")
    try:
        same_reply = call("raise_for_error", reply.raise_for_error, "X:", allowed=(DeviceError,))
    except DeviceError as exc:
        if kind != "error" or exc.code != code:
            raise Failure(f"raise_for_error raised {exc!r} for {reply!r}") from exc
        expected: type[DeviceError] = DeviceError
        if code == 0x80:
            expected = DeviceBandwidthError
        elif code in (0x23, 0x81, 0x82):
            expected = DeviceConfigurationError
        if type(exc) is not expected:
            raise Failure(
                f"{reply.text} raised {type(exc).__name__}, not {expected.__name__}"
            ) from exc
    else:
        if kind == "error" or same_reply is not reply:
            raise Failure(f"raise_for_error did not raise for {reply!r}")
    if kind == "data" and prefix == "SPX":
        try:
            call("parse_version", parse_version, text, allowed=(ProtocolError,))
        except ProtocolError:
            pass
