"""The byte-side plumbing every MCS-1 family decoder shares (a ``StreamDecoder``).

:class:`Mcs1StreamDecoder` holds the family's frame decoder (``_frames``), the
sequence tracker (``_tracker``) and the link counters (``stats``), and forwards
bytes, flushes, discontinuities, event frames and the reset banner between
them. A family subclass builds those three in its ``__init__`` and implements
:meth:`Mcs1StreamDecoder._decode`: one :class:`FrameBatch` of checked frames to
a :class:`FrameBlock` (its payload layout).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from spotlab.core.frames import FrameBlock
from spotlab.core.stats import LinkStats
from spotlab.drivers.mcs1.framing import EventFrame, FrameBatch, FrameDecoder
from spotlab.drivers.mcs1.sequence import SequenceTracker

#: The MCS-1 frame header and data-frame prefix (mcs1.md §2, §4): ``(name, format, offset)``.
PREFIX_FIELDS: tuple[tuple[str, Any, int], ...] = (
    ("sync", "<u2", 0),
    ("type", "u1", 2),
    ("version", "u1", 3),
    ("seq", "<u2", 4),
    ("len", "<u2", 6),
    ("hcrc", "<u2", 8),
    ("frame_no", "<u4", 10),
    ("tick", "<u4", 14),
    ("status", "<u2", 18),
    ("n_items", "<u2", 20),
)


def packed_dtype(fields: Sequence[tuple[str, Any, int]], itemsize: int) -> np.dtype[Any]:
    """A structured dtype of ``(name, format, offset)`` fields, ``itemsize`` bytes a frame.

    Fields may overlap (views of the same bytes under another name).
    """
    return np.dtype(
        {
            "names": [f[0] for f in fields],
            "formats": [f[1] for f in fields],
            "offsets": [f[2] for f in fields],
            "itemsize": itemsize,
        }
    )


class Mcs1StreamDecoder(ABC):
    """Bytes of an MCS-1 link in, :class:`FrameBlock` out; the family decodes the payload.

    Attributes
    ----------
    stats : LinkStats
        Frames, losses, duplicates, gaps, CRC errors, resyncs, bytes.

    Notes
    -----
    ``feed`` never raises on bad bytes: damage is counted in ``stats``.
    Frame ``arrival_ns`` is the stamp of the read that brought its last byte.
    """

    stats: LinkStats
    _frames: FrameDecoder
    _tracker: SequenceTracker

    @abstractmethod
    def _decode(self, batch: FrameBatch) -> FrameBlock:
        """The frames of ``batch`` (checked MCS-1 data frames) as a block (family layout)."""

    # -- StreamDecoder ---------------------------------------------------------------
    def feed(self, data: bytes | bytearray | memoryview, arrival_ns: int) -> FrameBlock:
        """Decode ``data`` (appended to what is buffered).

        Parameters
        ----------
        data : bytes-like
            Bytes as read from the link.
        arrival_ns : int
            Host monotonic time of that read in ns.

        Returns
        -------
        FrameBlock
            Frames completed by ``data`` (possibly none), in the family's layout.
        """
        self.stats.bytes += len(data)
        return self._decode(self._frames.feed(data, arrival_ns))

    def feed_many(self, chunks: Iterable[tuple[bytes | bytearray | memoryview, int]]) -> FrameBlock:
        """Decode several reads (``(data, arrival_ns)`` in read order) in one pass (replay).

        The same frames as feeding the chunks one by one, at bulk speed; stamps stay per read.
        """
        chunks = list(chunks)
        self.stats.bytes += sum(len(data) for data, _ in chunks)
        return self._decode(self._frames.feed_many(chunks))

    def flush(self) -> FrameBlock:
        """End of input, or the link went quiet: resolve the bytes still buffered.

        A frame still waiting for its end is counted as truncated.
        """
        return self._decode(self._frames.flush())

    def mark_discontinuity(self) -> None:
        """The link was broken (reset, reconnect): drop buffered bytes, restart the counters."""
        self._frames.discard()
        self._tracker.mark_discontinuity()

    # -- extras --------------------------------------------------------------------------
    def take_events(self) -> list[EventFrame]:
        """Replies received inside event frames since the last call."""
        return self._frames.take_events()

    @property
    def banner_seen(self) -> bool:
        """Whether the reset banner appeared between frames (the device reset itself)."""
        return self._frames.banner_seen

    @banner_seen.setter
    def banner_seen(self, value: bool) -> None:
        self._frames.banner_seen = value

    @property
    def buffered(self) -> int:
        """Bytes received and not yet decoded or discarded."""
        return self._frames.buffered

    @property
    def restarts(self) -> int:
        """Streams restarted without :meth:`mark_discontinuity` (counters went back)."""
        return self._tracker.restarts
