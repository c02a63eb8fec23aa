"""A recording's labelled 3-D marker stream (QTM's, Motive's) as a trial, no reconstruction.

A stream of kind ``point3d`` whose spec names its markers (``spec.metadata["marker_labels"]``,
as the Qualisys and NatNet drivers write) already holds labelled
trajectories: ``spotlab export --c3d`` writes them as they are. Frames are placed by
their sequence number (the system's own frame number), so frames the device lost and outages
are NaN rows and the time axis stays true.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from spotlab.acquisition._replay_engine import Walk
from spotlab.core.frames import FrameBlock
from spotlab.io import Trial
from spotlab.io.journal import JournalReader
from spotlab.processing.decoding import decoder_for

#: Longest run of missing frames placed as NaN rows (a longer one is a damaged seq).
MAX_FILL = 1_000_000


def _labels(meta: dict[str, Any]) -> list[str] | None:
    spec = meta.get("spec") or {}
    labels = (spec.get("metadata") or {}).get("marker_labels")
    if spec.get("kind") != "point3d" or not isinstance(labels, list) or not labels:
        return None
    if spec.get("n_markers") != len(labels) or tuple(spec.get("values", ())) != ("x", "y", "z"):
        return None
    return [str(x) for x in labels]


def labelled_trial(path: str | Path) -> tuple[Trial, dict[str, Any]] | None:
    """The first labelled ``point3d`` stream of a recording as a trial and a summary.

    Returns
    -------
    (Trial, dict) or None
        The trial (points (F, M, 3) mm, NaN where not seen or not received; labels;
        rate) and ``{"input", "stream", "frames", "markers", "rate_hz", "missing_frames"}``;
        None if the recording holds no such stream.
    """
    # One pass over the records, without decoding: is any stream labelled? (A stream's
    # metadata may come after another's data: the session starts devices one by one.)
    if not any(_labels(meta) is not None for meta in JournalReader(path).streams.values()):
        return None
    blocks: list[FrameBlock] = []
    chosen: str | None = None
    labels: list[str] = []
    rate = 0.0
    for _kind, state, block in Walk(Path(path), decoder_for).steps():
        if block is None or not len(block):
            continue
        if chosen is None:
            found = _labels(state.metadata)
            if found is None:
                continue
            chosen, labels = state.name, found
            rate = float(state.metadata["spec"]["rate_hz"])
        if state.name == chosen:
            blocks.append(block)
    if chosen is None:
        return None
    all_frames = FrameBlock.concat(blocks)
    seq = all_frames.seq - all_frames.seq[0]
    n = int(seq[-1]) + 1 if len(seq) else 0
    if n > len(seq) + MAX_FILL:
        seq, n = np.arange(len(seq)), len(seq)
    points = np.full((n, len(labels), 3), np.nan)
    points[seq] = all_frames.data[:, :, 0, :]
    trial = Trial(points=points, labels=labels, point_rate=rate, metadata={"stream": chosen})
    summary = {
        "input": str(path),
        "stream": chosen,
        "frames": n,
        "markers": len(labels),
        "rate_hz": rate,
        "missing_frames": n - len(all_frames),
    }
    return trial, summary
