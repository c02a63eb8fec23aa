"""Counters of what happened on a link, common to every device family."""

from __future__ import annotations

from dataclasses import asdict, dataclass


@dataclass
class LinkStats:
    """Counts kept by a decoder and a driver.

    Attributes
    ----------
    frames : int
        Valid data frames decoded.
    lost_frames : int
        Frames missing according to the sequence and frame numbers (sent by
        the device but never decoded, or dropped in the device's FIFO).
    device_dropped : int
        The part of ``lost_frames`` the device itself reported dropping (FIFO overflow).
    crc_errors : int
        Frames whose header or payload checksum failed.
    resyncs : int
        Times the decoder skipped bytes to find the next sync word.
    bytes_skipped : int
        Bytes discarded while resynchronising.
    duplicates : int
        Frames received twice (same sequence number); kept once.
    gaps : int
        Runs of missing frames (one gap may hold many lost frames), including
        disconnections.
    reconnects : int
        Times the driver re-opened the link and resumed streaming.
    bytes : int
        Bytes read from the link.
    """

    frames: int = 0
    lost_frames: int = 0
    device_dropped: int = 0
    crc_errors: int = 0
    resyncs: int = 0
    bytes_skipped: int = 0
    duplicates: int = 0
    gaps: int = 0
    reconnects: int = 0
    bytes: int = 0

    def as_dict(self) -> dict[str, int]:
        """The counters as a plain dictionary."""
        return asdict(self)
