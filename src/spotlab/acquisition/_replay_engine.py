"""Walk a journal and decode its streams again, one decoder per stream.

Shared by :func:`~spotlab.acquisition.replay.replay` (blocks only) and
:func:`~spotlab.acquisition.replay.summarize` (blocks, breaks and counters).
"""

from __future__ import annotations

import dataclasses
import logging
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, Literal

from spotlab.core.errors import ProtocolError, RecordingError
from spotlab.core.frames import FrameBlock
from spotlab.core.stats import LinkStats
from spotlab.core.wire import StreamDecoder
from spotlab.io.journal import SESSION_STREAM, JournalReader, Record, RecordType

log = logging.getLogger(__name__)

DecoderFactory = Callable[[dict[str, Any]], StreamDecoder]

BREAK_EVENTS = frozenset({"disconnected", "reconnected", "device_reset"})
"""Link events after which sequence numbers must not be joined."""

RECOVERY_START = frozenset({"disconnected", "device_reset"})
RECOVERY_END = frozenset({"reconnected", "started"})
"""RX bytes between a link event of ``RECOVERY_START`` and the next of ``RECOVERY_END``
are the driver's recovery dialogue (reset, commands), not stream bytes: the live
driver did not decode them, and neither does replay. Frames of a stream still
running on the device may be among them; decoded after the break they would be
compared with a restarted stream and counted as lost."""


def add_stats(a: LinkStats, b: LinkStats) -> LinkStats:
    """Field-wise sum of two sets of link counters."""
    return LinkStats(
        **{f.name: getattr(a, f.name) + getattr(b, f.name) for f in dataclasses.fields(a)}
    )


@dataclass
class StreamState:
    """What the walk knows of one stream.

    Attributes
    ----------
    index : int
        Stream index in the journal.
    name : str
        Stream name.
    metadata : dict
        Metadata in force (the latest META record of the stream).
    decoder : StreamDecoder or None
        Built at the first RX record after metadata is known.
    retired : LinkStats
        Counters of decoders replaced after a metadata change.
    rx_bytes, tx_bytes : int
        Wire bytes recorded each way.
    undecoded_bytes : int
        RX bytes recorded before the stream's metadata (start-up dialogue) or
        while the driver was recovering (recovery dialogue).
    decode_errors : int
        ``ProtocolError`` raised by the decoder (each followed by a discontinuity).
    disconnections, reconnects, device_resets : int
        Link events recorded.
    faults : dict of str to int
        ``error`` events that name a ``fault`` (a USB stall, timeout, short packet,
        babble, refused set-up...), counted by that name: the faults the driver
        detected and journalled, one event each.
    live_stats : dict or None
        The driver's own counters at the end of the recording (``link_stats`` event).
    undecodable : str
        Why no decoder could be built for the metadata in force (empty if one was).
    recovering : bool
        Between a ``disconnected`` / ``device_reset`` event and the next
        ``reconnected`` / ``started``: RX bytes are the recovery dialogue.
    """

    index: int
    name: str
    metadata: dict[str, Any] = field(default_factory=dict)
    decoder: StreamDecoder | None = None
    retired: LinkStats = field(default_factory=LinkStats)
    rx_bytes: int = 0
    tx_bytes: int = 0
    undecoded_bytes: int = 0
    decode_errors: int = 0
    disconnections: int = 0
    reconnects: int = 0
    device_resets: int = 0
    faults: dict[str, int] = field(default_factory=dict)
    live_stats: dict[str, Any] | None = None
    undecodable: str = ""
    recovering: bool = False

    def decoder_stats(self) -> LinkStats:
        """Counters of every decoder this stream used."""
        if self.decoder is None:
            return self.retired
        return add_stats(self.retired, self.decoder.stats)


Step = tuple[Literal["block"], StreamState, FrameBlock] | tuple[Literal["break"], StreamState, None]


class Walk:
    """One pass over a journal, decoding every stream.

    Parameters
    ----------
    path : str or Path
        The journal.
    decoder_for : callable
        Builds a decoder from a stream's recorded metadata.
    strict : bool, optional
        Raise when ``decoder_for`` fails for a stream (default). Otherwise the
        stream's bytes are counted as undecoded and the cause is kept in
        ``StreamState.undecodable``.

    Raises
    ------
    RecordingError
        If the file is not a journal, or (``strict``) ``decoder_for`` fails for
        a stream (the message names the stream).
    """

    def __init__(
        self, path: str | os.PathLike[str], decoder_for: DecoderFactory, *, strict: bool = True
    ) -> None:
        self.reader = JournalReader(path)
        self.decoder_for = decoder_for
        self.strict = strict
        self.states: dict[int, StreamState] = {}

    def steps(self) -> Iterator[Step]:
        """Decoded blocks and continuity breaks, in recording order."""
        for rec in self.reader:
            if rec.stream == SESSION_STREAM:
                continue
            state = self._state(rec.stream)
            if rec.type == RecordType.RX:
                block = self._feed(state, rec)
                if block is not None and len(block):
                    yield ("block", state, block)
            elif rec.type == RecordType.TX:
                state.tx_bytes += len(rec.payload)
            elif rec.type == RecordType.META:
                self._meta(state, rec)
            elif rec.type == RecordType.EVENT and self._event(state, rec):
                yield ("break", state, None)

    def _state(self, index: int) -> StreamState:
        state = self.states.get(index)
        if state is None:
            state = self.states[index] = StreamState(index, name=f"#{index}")
        return state

    def _meta(self, state: StreamState, rec: Record) -> None:
        info = _json(rec)
        if not isinstance(info, dict):
            return
        if isinstance(info.get("name"), str) and state.name.startswith("#"):
            state.name = info["name"]
        meta = info.get("metadata")
        meta = meta if isinstance(meta, dict) else {}
        if meta != state.metadata and state.decoder is not None:
            # New configuration: its frames are decoded by a fresh decoder.
            state.retired = state.decoder_stats()
            state.decoder = None
        if meta != state.metadata:
            state.undecodable = ""
        state.metadata = meta

    def _feed(self, state: StreamState, rec: Record) -> FrameBlock | None:
        n = len(rec.payload)
        state.rx_bytes += n
        if state.recovering:
            state.undecoded_bytes += n
            return None
        if state.decoder is None:
            if not state.metadata or state.undecodable:
                state.undecoded_bytes += n
                return None
            try:
                state.decoder = self.decoder_for(state.metadata)
            except Exception as exc:
                cause = f"stream {state.name!r} cannot be decoded: {exc}"
                if self.strict:
                    raise RecordingError(f"{self.reader.path}: {cause}") from exc
                state.undecodable = cause
                state.undecoded_bytes += n
                return None
        try:
            return state.decoder.feed(rec.payload, rec.t_ns)
        except ProtocolError as exc:
            state.decode_errors += 1
            if state.decode_errors <= 3:
                log.warning("stream %s at byte %d: %s", state.name, rec.offset, exc)
            state.decoder.mark_discontinuity()
            return None

    def _event(self, state: StreamState, rec: Record) -> bool:
        """Account for an event; True if it breaks the stream's continuity."""
        info = _json(rec)
        if not isinstance(info, dict):
            return False
        kind = info.get("kind")
        detail = info.get("detail")
        if kind == "link_stats" and isinstance(detail, dict):
            state.live_stats = detail
        if kind == "error" and isinstance(detail, dict) and isinstance(detail.get("fault"), str):
            fault = detail["fault"]
            state.faults[fault] = state.faults.get(fault, 0) + 1
        if kind in RECOVERY_START:
            state.recovering = True
        elif kind in RECOVERY_END:
            state.recovering = False
        if kind not in BREAK_EVENTS:
            return False
        if kind == "disconnected":
            state.disconnections += 1
        elif kind == "reconnected":
            state.reconnects += 1
        else:
            state.device_resets += 1
        if state.decoder is not None:
            state.decoder.mark_discontinuity()
        return True


def _json(rec: Record) -> Any:
    try:
        return rec.json()
    except RecordingError as exc:
        log.warning("%s", exc)
        return None
