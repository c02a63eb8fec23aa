"""What a recording holds, per stream: frames, losses, errors, gaps, duration, rate.

Computed by decoding the journal again (streaming, constant memory), so the
figures are those of the recorded bytes, whatever the live session saw.
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from spotlab.acquisition._replay_engine import DecoderFactory, StreamState, Walk
from spotlab.core.frames import FrameBlock
from spotlab.core.units import NS_PER_S


@dataclass(frozen=True)
class StreamSummary:
    """One stream of a recording.

    Attributes
    ----------
    name, family : str
        Stream name and device family (from the recorded metadata).
    frames : int
        Valid frames decoded.
    lost_frames : int
        Frames missing by sequence and frame number (decoder count).
    device_dropped : int
        The part of ``lost_frames`` the device dropped itself (FIFO overflow);
        ``lost_frames - device_dropped`` were lost on the link.
    crc_errors, resyncs : int
        Checksum failures and resynchronisations (decoder counts).
    gaps : int
        Runs of lost frames (decoder count) plus outages (recorded disconnections
        and device resets), as the live driver counts them.
    duration_s : float
        First to last frame, in s: from device ticks when the stream never broke
        and its tick rate is known, otherwise from host arrival stamps.
    rate_hz : float
        Measured frame rate: sequence-number advance over elapsed time, summed
        over the stream's unbroken stretches (lost frames count, disconnections
        do not). 0 with fewer than two frames.
    reconnects, disconnections, device_resets : int
        Recorded link events.
    faults : dict of str to int
        Faults the driver detected and journalled (``error`` events naming a
        ``fault``), by name; for a WSX hub ``stall``, ``timeout``, ``short``,
        ``babble`` (an unplugged hub is a disconnection, its return a reconnect).
    bytes : int
        RX bytes recorded.
    tx_bytes : int
        TX bytes recorded.
    duplicates, bytes_skipped : int
        Decoder counts.
    undecoded_bytes : int
        RX bytes not decoded: the start-up dialogue before the metadata, the
        recovery dialogue after a disconnection or device reset (until
        ``reconnected`` or ``started``), or a stream no decoder could be built
        for (see ``undecodable``).
    decode_errors : int
        Protocol errors the decoder raised.
    duration_source : str
        ``"ticks"``, ``"arrival"`` or ``""`` (fewer than two frames).
    undecodable : str
        Why the stream could not be decoded, empty if it could.
    live_stats : dict or None
        The driver's counters when the recording stopped, for comparison.
    device_summary : dict or None
        Family figures from the decoder's ``summary()`` if it has one (CEN: blobs
        per frame, overflows and gaps per camera).
    """

    name: str
    family: str
    frames: int
    lost_frames: int
    crc_errors: int
    resyncs: int
    gaps: int
    duration_s: float
    rate_hz: float
    reconnects: int
    bytes: int
    disconnections: int = 0
    device_resets: int = 0
    faults: dict[str, int] = field(default_factory=dict)
    tx_bytes: int = 0
    duplicates: int = 0
    device_dropped: int = 0
    bytes_skipped: int = 0
    undecoded_bytes: int = 0
    decode_errors: int = 0
    duration_source: str = ""
    undecodable: str = ""
    live_stats: dict[str, Any] | None = None
    device_summary: dict[str, Any] | None = None


@dataclass(frozen=True)
class RecordingSummary:
    """A recording: journal facts and one :class:`StreamSummary` per stream.

    Attributes
    ----------
    path : str
        The journal.
    complete : bool
        Closed cleanly (END record present); false for a killed recording.
    truncated_bytes : int
        Partial record at the end (a killed recording), 0 otherwise.
    corrupt_records : int
        Damaged stretches skipped.
    session : dict
        Session metadata (start time, host, spotlab version, user entries).
    streams : list of StreamSummary
        In declaration order.
    """

    path: str
    complete: bool
    truncated_bytes: int
    corrupt_records: int
    session: dict[str, Any] = field(default_factory=dict)
    streams: list[StreamSummary] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe dictionary: journal facts, ``session`` and a ``streams`` list."""
        return asdict(self)

    def to_json(self, indent: int | None = None) -> str:
        """One JSON object (see :meth:`to_dict`)."""
        return json.dumps(self.to_dict(), indent=indent)


class FrameTiming:
    """First and last frame of a stream and its unbroken stretches, block by block.

    Parameters
    ----------
    tick_hz : float or None
        Device tick rate; None to time with host arrival stamps only.
    """

    def __init__(self, tick_hz: float | None) -> None:
        self.tick_hz = tick_hz
        self.frames = 0
        self.breaks = 0
        self._first: tuple[int, int] = (0, 0)  # ticks, arrival_ns
        self._last: tuple[int, int] = (0, 0)
        self._seg: list[int] | None = None  # first seq, ticks, arrival; last seq, ticks, arrival
        self._seq_total = 0
        self._span_total_s = 0.0

    def add(self, block: FrameBlock) -> None:
        """Account for the frames of ``block`` (shape (F,) fields used: seq, ticks, arrival_ns)."""
        n = len(block)
        if n == 0:
            return
        seq, ticks, arr = block.seq, block.ticks, block.arrival_ns
        if self.frames == 0:
            self._first = (int(ticks[0]), int(arr[0]))
        self._last = (int(ticks[-1]), int(arr[-1]))
        self.frames += n
        # Sequence or ticks going backwards inside a block: a reset the decoder saw.
        cuts = np.flatnonzero((np.diff(seq) <= 0) | (np.diff(ticks) < 0)) + 1
        for start, stop in zip([0, *cuts.tolist()], [*cuts.tolist(), n], strict=True):
            head = (int(seq[start]), int(ticks[start]), int(arr[start]))
            seg = self._seg
            if seg is not None and (head[0] <= seg[3] or head[1] < seg[4]):
                self.discontinuity()
                seg = None
            if seg is None:
                seg = self._seg = [*head, *head]
            seg[3:] = [int(seq[stop - 1]), int(ticks[stop - 1]), int(arr[stop - 1])]

    def discontinuity(self) -> None:
        """The link broke: frames after this are not joined to those before."""
        if self._seg is None:
            return
        seg = self._seg
        self._seq_total += seg[3] - seg[0]
        if self.tick_hz:
            self._span_total_s += (seg[4] - seg[1]) / self.tick_hz
        else:
            self._span_total_s += (seg[5] - seg[2]) / NS_PER_S
        self._seg = None
        self.breaks += 1

    def result(self) -> tuple[float, float, str]:
        """``(duration_s, rate_hz, duration_source)``; call once, at the end."""
        breaks = self.breaks
        self.discontinuity()
        if self.frames < 2:
            return 0.0, 0.0, ""
        if self.tick_hz and breaks == 0:
            duration, source = (self._last[0] - self._first[0]) / self.tick_hz, "ticks"
        else:
            duration, source = (self._last[1] - self._first[1]) / NS_PER_S, "arrival"
        rate = self._seq_total / self._span_total_s if self._span_total_s > 0 else 0.0
        return float(duration), float(rate), source


def _tick_hz(metadata: dict[str, Any]) -> float | None:
    spec = metadata.get("spec")
    value = spec.get("tick_hz") if isinstance(spec, dict) else metadata.get("tick_hz")
    try:
        hz = float(value) if value is not None else None
    except (TypeError, ValueError):
        return None
    return hz if hz and hz > 0 else None


def _stream_summary(state: StreamState, timing: FrameTiming | None) -> StreamSummary:
    stats = state.decoder_stats()
    duration, rate, source = timing.result() if timing is not None else (0.0, 0.0, "")
    family = state.metadata.get("family", "")
    figures = getattr(state.decoder, "summary", None)
    return StreamSummary(
        name=state.name,
        family=family if isinstance(family, str) else str(family),
        frames=timing.frames if timing is not None else 0,
        lost_frames=stats.lost_frames,
        crc_errors=stats.crc_errors,
        resyncs=stats.resyncs,
        gaps=stats.gaps + state.disconnections + state.device_resets,
        duration_s=duration,
        rate_hz=rate,
        reconnects=state.reconnects,
        bytes=state.rx_bytes,
        disconnections=state.disconnections,
        device_resets=state.device_resets,
        faults=dict(state.faults),
        tx_bytes=state.tx_bytes,
        duplicates=stats.duplicates,
        device_dropped=stats.device_dropped,
        bytes_skipped=stats.bytes_skipped,
        undecoded_bytes=state.undecoded_bytes,
        decode_errors=state.decode_errors,
        duration_source=source,
        undecodable=state.undecodable,
        live_stats=state.live_stats,
        device_summary=figures() if callable(figures) else None,
    )


def summarize_walk(walk: Walk) -> RecordingSummary:
    """Run ``walk`` to the end and summarise it (constant memory)."""
    timings: dict[int, FrameTiming] = {}
    for _kind, state, block in walk.steps():
        timing = timings.get(state.index)
        if timing is None:
            timing = timings[state.index] = FrameTiming(_tick_hz(state.metadata))
        if block is not None:
            timing.add(block)
        else:
            timing.discontinuity()
    facts = walk.reader.scan()
    streams = [
        _stream_summary(state, timings.get(state.index)) for _, state in sorted(walk.states.items())
    ]
    return RecordingSummary(
        path=str(walk.reader.path),
        complete=facts.complete,
        truncated_bytes=facts.truncated_bytes,
        corrupt_records=facts.corrupt_records,
        session=walk.reader.session,
        streams=streams,
    )


def summarize(path: str | os.PathLike[str], decoder_for: DecoderFactory) -> RecordingSummary:
    """Decode a recording again and summarise every stream.

    Parameters
    ----------
    path : str or Path
        The journal (``.spj``).
    decoder_for : callable
        ``decoder_for(metadata) -> StreamDecoder`` for a stream's recorded
        metadata (the console passes one built on the driver table).

    Returns
    -------
    RecordingSummary
        Journal facts and per-stream figures; ``to_json()`` for machine use.
        A stream whose decoder cannot be built is reported with its bytes and
        the cause in ``undecodable`` instead of failing the whole summary.

    Raises
    ------
    RecordingError
        If the file is not a journal (not found, empty, wrong magic, newer version).

    Notes
    -----
    Streaming: memory does not grow with the length of the recording.
    """
    return summarize_walk(Walk(Path(path), decoder_for, strict=False))
