"""What passes over a device link, as seen by listeners (recorder, monitors).

A driver calls a :class:`WireTap` for every chunk of bytes it reads or writes
and for every link event (disconnect, reconnect, device reset, resync), each
with the host monotonic time in ns. The recorder implements the tap and writes
the journal; a monitor counts. Both stay ignorant of the family's protocol.
"""

from __future__ import annotations

from typing import Literal, Protocol

from spotlab.core.frames import FrameBlock
from spotlab.core.stats import LinkStats

LinkEventKind = Literal[
    "open",
    "close",
    "disconnected",
    "reconnected",
    "device_reset",
    "baud_change",
    "configured",
    "started",
    "stopped",
    "error",
]


class WireTap(Protocol):
    """Listener of one device link."""

    def on_rx(self, stream: str, data: bytes, arrival_ns: int) -> None:
        """Bytes read from the device; ``arrival_ns`` is when the read returned."""

    def on_tx(self, stream: str, data: bytes, sent_ns: int) -> None:
        """Bytes written to the device."""

    def on_event(
        self, stream: str, kind: LinkEventKind, detail: dict[str, object], t_ns: int
    ) -> None:
        """A link event, with a JSON-safe detail dictionary."""


class StreamDecoder(Protocol):
    """Turns a device's received bytes into frames; the same object serves live and replay.

    Attributes
    ----------
    stats : LinkStats
        Counters of frames, losses, checksum errors and resyncs so far.
    """

    stats: LinkStats

    def feed(self, data: bytes, arrival_ns: int) -> FrameBlock:
        """Decode ``data`` after what is buffered; return the complete frames (maybe none)."""

    def mark_discontinuity(self) -> None:
        """The link was broken (reset, reconnect): do not join sequence numbers across it."""
