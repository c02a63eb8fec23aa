"""What the MCS-1 state machine needs of a family's configuration and stream decoder."""

from __future__ import annotations

from typing import Any, Protocol

from spotlab.core.frames import FrameBlock
from spotlab.core.stats import LinkStats
from spotlab.drivers.mcs1.framing import EventFrame


class Mcs1Config(Protocol):
    """What the state machine needs of a family's configuration."""

    @property
    def baud(self) -> int:
        """Line rate while streaming."""

    @property
    def rate_hz(self) -> float:
        """Frame rate in Hz."""

    @property
    def frame_bytes(self) -> int:
        """Bytes of one data frame."""

    @property
    def line_bits_per_s(self) -> float:
        """Bits per second the stream occupies on the line."""

    def commands(self) -> list[tuple[str, str]]:
        """``(verb, args)`` of the configuration commands, in the order to send them."""

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe form."""


class Mcs1Decoder(Protocol):
    """What the state machine needs of a family's stream decoder."""

    stats: LinkStats
    banner_seen: bool

    @property
    def buffered(self) -> int:
        """Bytes received and not yet decoded."""

    def feed(self, data: bytes | bytearray | memoryview, arrival_ns: int) -> FrameBlock:
        """Decode received bytes."""

    def flush(self) -> FrameBlock:
        """Resolve the bytes still buffered."""

    def mark_discontinuity(self) -> None:
        """The link was broken: drop buffered bytes, restart the counters."""

    def take_events(self) -> list[EventFrame]:
        """Replies received inside event frames since the last call."""
