"""One run of inputs through three decoders of one layout, fed three ways.

Each input is fed to three decoders of one layout: whole, in random chunks
(1 byte to more than a frame; stamps are the chunks' end offsets), and through
``feed_many`` with the same chunks; each then ``flush()``-es. Decoders live for
a run of inputs, with ``mark_discontinuity()`` between some of them (and, in a
few runs, ``flush()`` / ``mark_discontinuity()`` in the middle of an input).
Besides the checks of :class:`~fuzzing.invariants.Checked`, the three ways of
feeding must agree exactly (frames, values, counters, events; arrival stamps
between the chunked two).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .invariants import Checked, Failure, same
from .streams import Layout


@dataclass
class Step:
    """One input and how it is fed (saved with a failure, to replay it)."""

    data: bytes
    cuts: list[int]
    mark_before: bool = False
    many: bool = True
    mid: list[tuple[int, str]] = field(default_factory=list)  # (chunk index, flush|mark)

    def to_json(self) -> dict[str, Any]:
        return {
            "data": self.data.hex(),
            "cuts": self.cuts,
            "mark_before": self.mark_before,
            "many": self.many,
            "mid": self.mid,
        }

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> Step:
        return cls(
            bytes.fromhex(d["data"]),
            d["cuts"],
            d["mark_before"],
            d["many"],
            [(int(i), str(w)) for i, w in d["mid"]],
        )


class DecoderRun:
    """Three decoders of one layout fed the same inputs three ways."""

    def __init__(self, layout: Layout) -> None:
        self.layout = layout
        self.whole = Checked(*layout)
        self.chunked = Checked(*layout)
        self.many = Checked(*layout)
        self.decoders = (self.whole, self.chunked, self.many)
        self.offset = 0  # stamps: stream offset of each read's end, over the run
        self.diverged = False  # mid-input flush/mark given to the chunked decoder only
        self.steps: list[Step] = []

    def step(self, st: Step) -> list[bytes]:
        """Feed one input; return the event payloads found (for the reply parser)."""
        self.steps.append(st)
        data, base = st.data, self.offset
        self.offset += len(data) + 1
        if st.mark_before:
            for c in self.decoders:
                c.mark()
        for c in self.decoders:
            c.reset_outputs()
        chunks, pos = [], 0
        for end in st.cuts:
            chunks.append((data[pos:end], base + end))
            pos = end
        stamps = {t for chunk, t in chunks if chunk}
        end_stamp = base + len(data)
        self.whole.feed(data, end_stamp, {end_stamp})
        self.whole.flush(end_stamp, {end_stamp})
        mid = dict(st.mid)
        for k, (chunk, t) in enumerate(chunks):
            self.chunked.feed(chunk, t, stamps)
            if k in mid:
                self.diverged = True
                if mid[k] == "flush":
                    self.chunked.flush(t, stamps)
                else:
                    self.chunked.mark()
        self.chunked.flush(end_stamp, stamps)
        if st.many:
            self.many.feed_many(chunks, stamps)
        else:
            for chunk, t in chunks:
                self.many.feed(chunk, t, stamps)
        self.many.flush(end_stamp, stamps)
        for c in self.decoders:
            c.end_input(data)
        if not self.diverged:
            self.check_agreement()
        return list(self.chunked.events)

    def check_agreement(self) -> None:
        """The three ways of feeding gave the same frames, counters and events."""
        reference = self.chunked.result()
        if not same(self.whole.result(), reference):
            raise Failure("whole input and chunks decode differently")
        if not same(self.many.result(), reference):
            raise Failure("feed_many and feed decode differently")
        a, b = self.chunked.arrivals(), self.many.arrivals()
        if (a is None) != (b is None) or (a is not None and not np.array_equal(a, b)):
            raise Failure("feed_many and feed give different arrival stamps")
