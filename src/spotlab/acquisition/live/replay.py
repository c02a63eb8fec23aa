"""A recording through the live pipeline, as if live: the same frames, the same points."""

from __future__ import annotations

import os
from typing import Any

from spotlab.acquisition._replay_engine import DecoderFactory
from spotlab.acquisition.live.pipeline import LivePipeline
from spotlab.acquisition.replay import replay
from spotlab.core.errors import ConfigurationError, RecordingError
from spotlab.core.streams import StreamSpec
from spotlab.io.journal import JournalReader

__all__ = ["recorded_specs", "replay_live"]


def recorded_specs(path: str | os.PathLike[str]) -> list[StreamSpec]:
    """Descriptions of the streams of a recording (their latest metadata).

    Raises
    ------
    RecordingError
        If the file is not a journal or a stream's description is malformed.
    """
    specs: list[StreamSpec] = []
    for meta in JournalReader(path).streams.values():
        spec: Any = meta.get("spec") if isinstance(meta, dict) else None
        if isinstance(spec, dict):
            try:
                specs.append(StreamSpec.from_dict(spec))
            except ConfigurationError as exc:
                raise RecordingError(f"{path}: {exc}") from None
    return specs


def replay_live(
    pipeline: LivePipeline, path: str | os.PathLike[str], decoder_for: DecoderFactory
) -> int:
    """Feed a recording through ``pipeline`` (configured from the recording), then stop it.

    Parameters
    ----------
    pipeline : LivePipeline
        A pipeline not used yet; its consumers receive the frames.
    path : str or Path
        The journal.
    decoder_for : callable
        ``decoder_for(metadata) -> StreamDecoder`` (see
        :func:`~spotlab.acquisition.replay.replay`).

    Returns
    -------
    int
        Frames replayed (of every stream).

    Notes
    -----
    Blocks are fed in recording order, one stream after another as the bytes were
    read; the pipeline's latency figures are meaningless here (the arrival stamps are
    the recorded ones).
    """
    pipeline.configure(recorded_specs(path))
    n = 0
    for name, block in replay(path, decoder_for):
        pipeline.on_block(name, block)
        n += len(block)
    pipeline.stop()
    return n
