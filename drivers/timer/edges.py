"""Edges out of decoded timer blocks: flat arrays for clock fitting.

:func:`extract_edges` turns the edge slots of ``timer`` frame blocks (layout in
:mod:`spotlab.drivers.timer.protocol`) into one row per captured edge or
emitted pulse, in capture order; :func:`edges_from_recording` does the same
for a stream of a recording.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from spotlab.acquisition.replay import replay
from spotlab.core.errors import ConfigurationError
from spotlab.core.frames import FrameBlock
from spotlab.core.wire import StreamDecoder

I64 = npt.NDArray[np.int64]
B = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class TimerEdges:
    """Edges of a timer stream, one row each, in the order the frames carried them.

    Attributes
    ----------
    input : ndarray of int64, shape (K,)
        Channel: input 0-7, or ``128 + k`` for a pulse the timer emitted on output ``k``.
    edge_index : ndarray of int64, shape (K,)
        The channel's edge number since ``START:`` (rising and falling edges
        both count); a jump shows edges the host never got.
    tick : ndarray of int64, shape (K,)
        Timer counter at the edge, 10 MHz ticks (exact).
    rising : ndarray of bool, shape (K,)
        Rising edge (False: falling).
    frame_seq : ndarray of int64, shape (K,)
        ``seq`` of the timer frame that carried the edge.
    frame_seqs, frame_ticks : ndarray of int64, shape (F,)
        ``seq`` and counter (10 MHz ticks) of every timer frame.
    """

    input: I64
    edge_index: I64
    tick: I64
    rising: B
    frame_seq: I64
    frame_seqs: I64
    frame_ticks: I64

    def __len__(self) -> int:
        return int(self.tick.shape[0])

    def select(self, channel: int, rising: bool | None = True) -> TimerEdges:
        """The edges of one channel (and one polarity, unless ``rising`` is None)."""
        keep = self.input == channel
        if rising is not None:
            keep &= self.rising == rising
        return TimerEdges(
            self.input[keep],
            self.edge_index[keep],
            self.tick[keep],
            self.rising[keep],
            self.frame_seq[keep],
            self.frame_seqs,
            self.frame_ticks,
        )


def extract_edges(blocks: Iterable[FrameBlock]) -> TimerEdges:
    """Flatten the edge slots of decoded ``timer`` blocks.

    Parameters
    ----------
    blocks : iterable of FrameBlock
        Blocks of one timer stream, in order, each with data of shape
        (F, E + 1, 1, 4) as :class:`~spotlab.drivers.timer.protocol.TimerDecoder` gives.

    Returns
    -------
    TimerEdges
        Every used slot as one edge; ticks are frame counter + offset, exact.

    Raises
    ------
    ConfigurationError
        If a block is not laid out as a timer block.
    """
    rows: list[tuple[I64, I64, I64, B, I64]] = []
    seqs: list[I64] = []
    ticks: list[I64] = []
    for block in blocks:
        if block.data.ndim != 4 or block.data.shape[2:] != (1, 4) or block.data.shape[1] < 2:
            raise ConfigurationError(
                f"not a timer frame block: data shape {block.data.shape}, expected (F, E + 1, 1, 4)"
            )
        seqs.append(block.seq)
        ticks.append(block.ticks)
        slots = block.data[:, :-1, 0, :]
        used = ~np.isnan(slots[..., 0])
        f_idx, _ = np.nonzero(used)
        vals = slots[used]
        rows.append(
            (
                vals[:, 0].astype(np.int64),
                vals[:, 1].astype(np.int64),
                block.ticks[f_idx] + vals[:, 2].astype(np.int64),
                vals[:, 3] == 1.0,
                block.seq[f_idx],
            )
        )
    if not rows:
        empty = np.zeros(0, dtype=np.int64)
        return TimerEdges(empty, empty, empty, np.zeros(0, bool), empty, empty, empty)
    cols = [np.concatenate([r[i] for r in rows]) for i in range(5)]
    return TimerEdges(
        cols[0],
        cols[1],
        cols[2],
        cols[3].astype(bool),
        cols[4],
        np.concatenate(seqs),
        np.concatenate(ticks),
    )


def edges_from_recording(
    path: str | os.PathLike[str],
    decoder_for: Callable[[dict[str, Any]], StreamDecoder],
    stream: str = "timer",
) -> TimerEdges:
    """The edges of one timer stream of a recording.

    Parameters
    ----------
    path : str or Path
        The journal (``.spj``).
    decoder_for : callable
        Decoder factory for every stream of the recording
        (``spotlab.processing.decoding.decoder_for``).
    stream : str
        Name of the timer stream.

    Raises
    ------
    ConfigurationError
        If the recording has no frames of that stream.
    """
    blocks = [block for name, block in replay(path, decoder_for) if name == stream]
    if not blocks:
        raise ConfigurationError(f"{os.fspath(path)} holds no frames of a stream {stream!r}")
    return extract_edges(blocks)
