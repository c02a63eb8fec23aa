"""Scheduled and random link faults, and the exact log of what was injected.

A schedule is a comma-separated list ``kind@seconds[:argument]``, the time in
seconds after the device's first ``START:``::

    bitflip@1.5,drop@2.0,truncate@2.5,duplicate@3,garbage@3.5,burst@4,
    overflow@5:3,reset@6,disconnect@7:0.5

and/or a random rate of faults per data frame, seeded. Kinds:

========== ============================================================= =========
kind       effect                                                        argument
========== ============================================================= =========
bitflip    one bit of the next data frame flipped                        -
drop       one byte of the next data frame left out                      -
truncate   the next data frame cut short (the next one follows at once)  -
duplicate  the next data frame sent twice, identical                     -
garbage    ``AT\\r`` (as ModemManager sends) sent before the next frame   -
burst      every byte on the line for a while XOR-ed with noise           s (0.016)
overflow   the device's FIFO overflows: the next k frames are dropped     k (1)
           in the device (frame_no jumps, seq does not, status 0x40)
reset      spontaneous reset: 9600 baud, banner, stream stopped          -
disconnect the port goes away and comes back after a delay              s (1.0)
========== ============================================================= =========

Frame faults hit the first data frame the device *sends* at or after their
time; a frame carries at most one of them (the next waits for the next frame).
``reset`` and ``disconnect`` happen at their time, streaming or not.

The log counts per transmission, so that a host's counters can be checked
against it: see :class:`FaultEntry`.
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

FRAME_KINDS = ("bitflip", "drop", "garbage", "truncate", "duplicate", "burst", "overflow")
TIMED_KINDS = ("reset", "disconnect")
FAULT_KINDS = FRAME_KINDS + TIMED_KINDS
RANDOM_KINDS = FRAME_KINDS
DEFAULT_ARG = {"burst": 0.016, "overflow": 1.0, "disconnect": 1.0}
GARBAGE = b"AT\r"
FAULT_HELP = __doc__ or ""


@dataclass(frozen=True)
class FaultSpec:
    """One planned fault: ``kind`` at ``at_s`` seconds after the first START, with ``arg``."""

    kind: str
    at_s: float
    arg: float | None = None


def parse_schedule(text: str, kinds: tuple[str, ...] = FAULT_KINDS) -> list[FaultSpec]:
    """Parse ``"bitflip@1.5,overflow@5:3,disconnect@7:0.5"`` into fault specs, sorted by time.

    ``kinds`` are the kinds accepted (default: the MCS-1 simulator's).

    Raises
    ------
    ValueError
        Naming the offending item: unknown kind, missing or negative time, bad argument.
    """
    specs = []
    for raw in text.replace(";", ",").split(","):
        item = raw.strip()
        if not item:
            continue
        kind, at, rest = item.partition("@")
        kind = kind.strip().lower()
        if kind not in kinds:
            raise ValueError(f"fault {item!r}: unknown kind {kind!r}; known: {', '.join(kinds)}")
        if not at:
            raise ValueError(f"fault {item!r}: needs a time, as in {kind}@2.5")
        when, _, arg_text = rest.partition(":")
        try:
            at_s = float(when)
            arg = float(arg_text) if arg_text else DEFAULT_ARG.get(kind)
        except ValueError:
            raise ValueError(f"fault {item!r}: time and argument must be numbers") from None
        if at_s < 0 or (arg is not None and arg <= 0):
            raise ValueError(f"fault {item!r}: time must be >= 0 and the argument > 0")
        if kind == "overflow" and arg is not None and arg != int(arg):
            raise ValueError(f"fault {item!r}: overflow takes a whole number of frames")
        specs.append(FaultSpec(kind, at_s, arg))
    return sorted(specs, key=lambda s: s.at_s)


@dataclass
class FaultEntry:
    """What one fault did. Counts are per transmission of a data frame.

    Attributes
    ----------
    corrupted_frames : int
        Data frames put on the wire damaged (bit flip, dropped byte, truncation,
        burst): a host must count each as a CRC error or as a lost frame.
    dropped_frames : int
        Data frames taken but never sent because the device's FIFO overflowed:
        frame_no jumps by this much while seq does not, and the next frame has
        status bit 0x40 (a host's ``device_dropped``).
    duplicated_frames : int
        Extra, intact copies of a data frame (same seq): a host's ``duplicates``.
    lost_frames : int
        Data frames sent, wholly or in part, while the link was disconnected:
        a seq gap for a host that reconnects to the running stream.
    discarded_frames : int
        Data frames in the FIFO, or cut off mid-frame, at a reset: the stream
        just ends (the host sees no CRC error, it restarts).
    garbage_bytes : int
        Bytes inserted between frames (a host skips them: one resync).
    corrupted_events : int
        Event frames (replies while streaming) damaged by a burst.
    seq, frame_no : list of int
        The affected data frames, in order (one entry per counted transmission).
    """

    id: int
    kind: str
    t_s: float
    world_ns: int
    source: str = "schedule"
    arg: float | None = None
    seq: list[int] = field(default_factory=list)
    frame_no: list[int] = field(default_factory=list)
    corrupted_frames: int = 0
    dropped_frames: int = 0
    duplicated_frames: int = 0
    lost_frames: int = 0
    discarded_frames: int = 0
    garbage_bytes: int = 0
    corrupted_events: int = 0
    detail: dict[str, Any] = field(default_factory=dict)

    def count(self, what: str, seq: int, frame_no: int) -> None:
        """Add one data frame to counter ``what`` (e.g. ``"corrupted_frames"``)."""
        setattr(self, what, getattr(self, what) + 1)
        self.seq.append(seq)
        self.frame_no.append(frame_no)


COUNTERS = (
    "corrupted_frames",
    "dropped_frames",
    "duplicated_frames",
    "lost_frames",
    "discarded_frames",
    "garbage_bytes",
    "corrupted_events",
)


@dataclass
class FaultLog:
    """All faults injected into one device, plus the frame counts they are relative to."""

    schedule: str = ""
    rate: float = 0.0
    seed: int = 0
    entries: list[FaultEntry] = field(default_factory=list)
    frames_taken: int = 0
    frames_sent: int = 0

    def new(
        self, kind: str, t_s: float, world_ns: int, source: str, arg: float | None
    ) -> FaultEntry:
        """Open a new entry and return it."""
        entry = FaultEntry(len(self.entries), kind, t_s, world_ns, source, arg)
        self.entries.append(entry)
        return entry

    def totals(self) -> dict[str, int]:
        """Counters summed over every entry, with the number of resets and disconnects."""
        out = {name: sum(getattr(e, name) for e in self.entries) for name in COUNTERS}
        out["resets"] = sum(e.kind == "reset" for e in self.entries)
        out["disconnects"] = sum(e.kind == "disconnect" for e in self.entries)
        out["frames_taken"] = self.frames_taken
        out["frames_sent"] = self.frames_sent
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe form: schedule, seed, rate, every entry and the totals."""
        return {
            "version": 1,
            "schedule": self.schedule,
            "rate": self.rate,
            "seed": self.seed,
            "faults": [asdict(e) for e in self.entries],
            "totals": self.totals(),
        }

    def write(self, path: str | Path) -> None:
        """Write the log as JSON, atomically (a reader never sees half a file)."""
        target = Path(path)
        tmp = target.with_name(target.name + ".tmp")
        tmp.write_text(json.dumps(self.to_dict(), indent=1))
        os.replace(tmp, target)


class FaultInjector:
    """Decides which fault hits which frame, and when timed faults happen.

    Parameters
    ----------
    schedule : str or sequence of FaultSpec
        Planned faults (see the module docstring).
    rate : float
        Probability per sent data frame of one more random fault.
    kinds : sequence of str
        Kinds random faults are drawn from (default: every frame fault).
    seed : int
        Seeds the random faults and the damage they do.
    """

    def __init__(
        self,
        schedule: str | list[FaultSpec] = "",
        rate: float = 0.0,
        kinds: tuple[str, ...] = RANDOM_KINDS,
        seed: int = 0,
    ) -> None:
        specs = (
            parse_schedule(schedule)
            if isinstance(schedule, str)
            else sorted(schedule, key=lambda s: s.at_s)
        )
        if not 0.0 <= rate <= 1.0:
            raise ValueError(f"fault rate must be within 0-1 per frame, got {rate}")
        bad = [k for k in kinds if k not in FRAME_KINDS]
        if bad:
            raise ValueError(f"random faults can only be frame faults, not {bad}")
        self.frame_specs = [s for s in specs if s.kind in FRAME_KINDS]
        self.timed_specs = [s for s in specs if s.kind in TIMED_KINDS]
        self.rate = rate
        self.kinds = tuple(kinds)
        ss = np.random.SeedSequence([seed, 0xFA17])
        draw, damage = ss.spawn(2)
        self._draw = np.random.default_rng(draw)
        self.rng = np.random.default_rng(damage)
        text = (
            schedule if isinstance(schedule, str) else ",".join(f"{s.kind}@{s.at_s}" for s in specs)
        )
        self.log = FaultLog(schedule=text, rate=rate, seed=seed)
        self.start_ns: int | None = None

    def anchor(self, world_ns: int) -> bool:
        """Fix time zero of the schedule at the first START; True the first time only."""
        if self.start_ns is not None:
            return False
        self.start_ns = world_ns
        return True

    def since_start(self, world_ns: int) -> float:
        """Seconds since the first START (0 before it)."""
        return 0.0 if self.start_ns is None else (world_ns - self.start_ns) * 1e-9

    def at_ns(self, spec: FaultSpec) -> int:
        """World ns of a planned fault (the schedule must be anchored)."""
        assert self.start_ns is not None
        return self.start_ns + round(spec.at_s * 1e9)

    def next_frame_fault(self, world_ns: int) -> tuple[FaultSpec, str] | None:
        """The fault that hits a data frame sent at ``world_ns``, if any, and its source."""
        if self.start_ns is None:
            return None
        if self.frame_specs and self.at_ns(self.frame_specs[0]) <= world_ns:
            return self.frame_specs.pop(0), "schedule"
        if self.rate > 0.0 and self._draw.random() < self.rate:
            kind = str(self.kinds[int(self._draw.integers(len(self.kinds)))])
            arg = float(self._draw.integers(1, 4)) if kind == "overflow" else DEFAULT_ARG.get(kind)
            return FaultSpec(kind, self.since_start(world_ns), arg), "random"
        return None

    def next_timed_ns(self) -> int | None:
        """World ns of the next reset or disconnect, or None."""
        if self.start_ns is None or not self.timed_specs:
            return None
        return self.at_ns(self.timed_specs[0])

    def pop_timed(self) -> FaultSpec:
        """Take the next reset or disconnect off the schedule."""
        return self.timed_specs.pop(0)


def flip_bit(data: bytes, rng: np.random.Generator) -> tuple[bytes, dict[str, int]]:
    """Flip one random bit; returns the bytes and ``{"byte": i, "bit": b}``."""
    out = bytearray(data)
    i, b = int(rng.integers(len(out))), int(rng.integers(8))
    out[i] ^= 1 << b
    return bytes(out), {"byte": i, "bit": b}


def drop_byte(data: bytes, rng: np.random.Generator) -> tuple[bytes, dict[str, int]]:
    """Leave out one random byte; returns the bytes and ``{"byte": i}``."""
    i = int(rng.integers(len(data)))
    return data[:i] + data[i + 1 :], {"byte": i}


def truncate(data: bytes, rng: np.random.Generator) -> tuple[bytes, dict[str, int]]:
    """Keep only the first 1 .. len-1 bytes; returns the bytes and ``{"kept": n}``."""
    n = int(rng.integers(1, len(data)))
    return data[:n], {"kept": n}
