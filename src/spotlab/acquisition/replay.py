"""Replay a recording through decoders, as if the devices were live.

A recording holds raw wire bytes, so any spotlab — including a newer one with
better drivers — decodes it again: :func:`replay` yields the frame blocks,
:func:`summarize` counts what the recording holds.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

from spotlab.acquisition._replay_engine import BREAK_EVENTS, DecoderFactory, Walk
from spotlab.acquisition.summary import RecordingSummary, StreamSummary, summarize
from spotlab.core.frames import FrameBlock

__all__ = [
    "BREAK_EVENTS",
    "DecoderFactory",
    "RecordingSummary",
    "StreamSummary",
    "replay",
    "summarize",
]


def replay(
    path: str | os.PathLike[str], decoder_for: DecoderFactory
) -> Iterator[tuple[str, FrameBlock]]:
    """Decode a recording again, block by block, in recording order.

    Parameters
    ----------
    path : str or Path
        The journal (``.spj``).
    decoder_for : callable
        ``decoder_for(metadata) -> StreamDecoder``, called once per stream with
        the metadata its driver recorded (``family``, ``spec``, configuration);
        the console passes one built on the driver table.

    Yields
    ------
    stream : str
        Stream name.
    block : FrameBlock
        Frames decoded from one recorded chunk of bytes, stamped with the
        recorded host arrival times.

    Raises
    ------
    RecordingError
        If the file is not a journal, or no decoder can be built for a stream.

    Notes
    -----
    RX records are fed to their stream's decoder with their arrival stamps;
    ``disconnected``, ``reconnected`` and ``device_reset`` events call the
    decoder's ``mark_discontinuity()``. Bytes recorded before a stream's
    metadata (the start-up dialogue) are not decoded. A later metadata record
    (new configuration) starts a fresh decoder. Damaged records are skipped and
    a cut-off tail ends the replay quietly (see ``JournalReader``). Memory is
    constant in the recording's length.
    """
    for _kind, state, block in Walk(Path(path), decoder_for).steps():
        if block is not None:
            yield state.name, block
