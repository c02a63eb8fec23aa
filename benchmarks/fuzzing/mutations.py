"""Damage to valid streams, and the reads an input is cut into.

An input is one stream of the corpus mutated twice over:

* frame-aware, CRCs fixed afterwards so that the damage reaches the layers
  behind the checksums: any header or payload field set to a new value, the
  ``len`` field changed (header CRC fixed), frames resized with both CRCs
  correct (wrong length for the configuration), version 2, another frame type,
  frames turned into events (up to 4096 random bytes), duplicated, swapped,
  dropped;
* blind: bit flips, byte replacements, inserted garbage and tokens (sync words,
  headers alone, the banner, ``AT\\r``), deleted, repeated and swapped ranges,
  truncation of either end, splices of other streams (other layouts too); a
  few inputs are plain random bytes.

The reads (:func:`make_cuts`) go from 1 byte to more than a frame.
"""

from __future__ import annotations

import random
from collections.abc import Callable

from spotlab.simulators import wire

from .streams import REPLY_TEXTS, Stream, crc

TOKENS = [
    wire.SYNC,
    b"\xa5",
    b"\x5a",
    wire.BANNER,
    b"AT\r",
    wire.event_frame(wire.reply("OKAY")),
    wire.event_frame(wire.reply("ERROR80")),
    b"\r",
]
# (offset, size) of the header and payload-prefix fields of a data frame.
FIELDS = [(4, 2), (10, 4), (14, 4), (18, 2), (20, 2), (22, 2), (24, 1), (25, 1), (3, 1), (2, 1)]


def fix_crcs(b: bytearray, header: bool = True, payload: bool = True) -> None:
    if header:
        b[8:10] = crc(b[:8]).to_bytes(2, "little")
    if payload and len(b) >= 12:
        b[-2:] = crc(b[10:-2]).to_bytes(2, "little")


def mutate_frame(rng: random.Random, f: bytes) -> list[bytes]:
    """One frame-aware mutation of a data frame; CRCs fixed where it keeps them valid."""
    b = bytearray(f)
    op = rng.randrange(10)
    if op <= 2:  # one field (or a record byte) to a new value, CRCs fixed
        if rng.random() < 0.7:
            off, size = rng.choice(FIELDS)
        else:
            off, size = rng.randrange(26, len(b) - 2), 1
        old = int.from_bytes(b[off : off + size], "little")
        value = rng.choice(
            [rng.getrandbits(8 * size), old + 1, old - 1, 0, (1 << (8 * size)) - 1, old + 2]
        )
        b[off : off + size] = (value % (1 << (8 * size))).to_bytes(size, "little")
        fix_crcs(b)
    elif op == 3:  # len field changed, header CRC fixed (payload CRC now wrong)
        plen = len(b) - 12
        new = rng.choice([plen + 1, plen - 1, 0, 1, 4096, 4097, 65535, rng.getrandbits(16)])
        b[6:8] = (new % 65536).to_bytes(2, "little")
        fix_crcs(b, payload=False)
    elif op == 4:  # CRC-correct frame of the wrong length
        d = rng.choice([1, 5, 10, rng.randint(1, 40)])
        if rng.random() < 0.5 and len(b) - 12 - d >= 1:
            b = b[: -2 - d] + b[-2:]
        else:
            b = b[:-2] + bytearray(rng.randbytes(d)) + b[-2:]
        b[6:8] = (len(b) - 12).to_bytes(2, "little")
        fix_crcs(b)
    elif op == 5:  # version 2, or another frame type (header CRC fixed)
        if rng.random() < 0.5:
            b[3] = (rng.choice([0, 2, 15]) << 4) | (b[3] & 0x0F)
        else:
            b[2] = rng.choice([0x02, 0x03, 0x04, 0x00, 0xFF])
        fix_crcs(b, payload=False)
    elif op == 6:  # turned into an event frame: its payload, a reply, or random bytes
        choice = rng.random()
        if choice < 0.4:
            payload = bytes(b[10:-2])
        elif choice < 0.7:
            payload = wire.reply(rng.choice(REPLY_TEXTS))
        else:
            payload = rng.randbytes(rng.choice([1, 2, 9, 300, 4096, rng.randint(1, 4096)]))
        return [wire.event_frame(payload)]
    elif op == 7:  # duplicated (same seq), or sent twice around other bytes
        return [f, f] if rng.random() < 0.7 else [f, rng.choice(TOKENS), f]
    elif op == 8:  # dropped
        return []
    else:  # an event header claiming too much, or nothing
        head = bytearray(wire.SYNC + bytes([0x7F, 0x10, 0, 0]))
        head += rng.choice([0, 4097, 65535]).to_bytes(2, "little") + b"\0\0"
        fix_crcs(head, payload=False)
        return [bytes(head), f]
    return [bytes(b)]


def mutate_blind(rng: random.Random, b: bytearray, corpus: list[Stream]) -> bytearray:
    if not b:
        return bytearray(rng.randbytes(rng.randint(0, 64)))
    n = len(b)
    i = rng.randrange(n)
    op = rng.randrange(11)
    if op == 0:
        for _ in range(rng.randint(1, 4)):
            b[rng.randrange(n)] ^= 1 << rng.randrange(8)
    elif op == 1:
        for _ in range(rng.randint(1, 3)):
            b[rng.randrange(n)] = rng.choice([0, 0xFF, 0xA5, 0x5A, 0x0D, rng.getrandbits(8)])
    elif op == 2:
        b[i:i] = rng.randbytes(rng.choice([1, 2, 3, 10, rng.randint(1, 64)]))
    elif op == 3:
        token = rng.choice(TOKENS) if rng.random() < 0.8 else b"\xa5\x5a" + rng.randbytes(8)
        b[i:i] = token
    elif op == 4:
        del b[i : i + rng.choice([1, 2, 5, 12, rng.randint(1, 100)])]
    elif op == 5:
        b[i:i] = b[i : i + rng.randint(1, 3000)]
    elif op == 6:
        del b[i:]
    elif op == 7:
        del b[:i]
    elif op == 8:  # splice a piece of another stream (maybe another layout)
        other = rng.choice(corpus).joined()
        j = rng.randrange(len(other))
        part = other[j : j + rng.randint(1, 4000)]
        if rng.random() < 0.5:
            b[i:i] = part
        else:
            b[i:] = part
    elif op == 9:  # swap two ranges
        j = rng.randrange(n)
        lo, hi = min(i, j), max(i, j)
        size = rng.randint(1, 200)
        if lo + size <= hi:
            b[lo : lo + size], b[hi : hi + size] = b[hi : hi + size], b[lo : lo + size]
    else:
        b[i : i + 1] = b"\xa5\x5a"
    return b


def make_input(rng: random.Random, stream: Stream, all_streams: list[Stream]) -> bytes:
    r = rng.random()
    if r < 0.02:
        return rng.randbytes(rng.randint(0, 3000))
    if r < 0.03:
        junk = bytearray(rng.randbytes(rng.randint(0, 2000)))
        for _ in range(rng.randint(1, 20)):
            k = rng.randrange(len(junk) + 1)
            junk[k:k] = wire.SYNC
        return bytes(junk)
    pieces = list(stream.pieces)
    if r < 0.06:
        return b"".join(pieces)  # valid as built
    if rng.random() < 0.6:
        frames = [k for k, f in enumerate(stream.is_frame) if f]
        for _ in range(rng.randint(1, 3)):
            if not frames:
                break
            k = rng.choice(frames)
            if rng.random() < 0.9:
                pieces[k] = b"".join(mutate_frame(rng, pieces[k]))
                frames.remove(k)  # no longer a data frame of the layout
            else:  # swap with another frame
                j = rng.choice(frames)
                pieces[k], pieces[j] = pieces[j], pieces[k]
    data = bytearray(b"".join(pieces))
    blind = rng.choice([0, 1, 1, 2, 3, 6]) if rng.random() < 0.8 else 0
    for _ in range(blind):
        data = mutate_blind(rng, data, all_streams)
    return bytes(data)


def make_cuts(rng: random.Random, n: int, frame_len: int) -> list[int]:
    """Chunk end offsets (the last one is ``n``)."""
    if n == 0:
        return [0] if rng.random() < 0.5 else []
    mode = rng.random()
    if mode < 0.04 and n <= 600:
        return list(range(1, n + 1))
    if mode < 0.45:
        top = rng.choice([4, 32, 128, 128, 600, 600])
        return _walk(n, lambda: rng.randint(1, top))
    if mode < 0.7:
        return _walk(n, lambda: max(1, frame_len + rng.randint(-12, 12)))
    cuts = sorted(rng.randint(0, n) for _ in range(rng.randint(0, 12)))
    return [*cuts, n]


def _walk(n: int, step: Callable[[], int]) -> list[int]:
    """Offsets from 0 up to ``n`` in steps of ``step()`` bytes, the last one cut at ``n``."""
    cuts, pos = [], 0
    while pos < n:
        pos = min(n, pos + step())
        cuts.append(pos)
    return cuts
