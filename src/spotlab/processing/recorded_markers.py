"""A recording of labelled 3-D markers as a trial, without reconstruction.

A device that streams reconstructed, labelled markers (OptiTrack's NatNet: a
``point3d`` stream, one sensor, x, y, z in mm, ``marker_labels`` in its spec)
needs no calibration: its frames are the trajectories. Frame ``k`` of the trial
is the stream's frame ``first + k`` (its sequence number), so a frame the device
numbered but that never arrived stays a row of NaN.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from spotlab.acquisition.live import recorded_specs
from spotlab.acquisition.replay import replay
from spotlab.core.streams import StreamSpec
from spotlab.io.trial import Trial
from spotlab.processing.decoding import decoder_for


def marker_stream(path: str | os.PathLike[str]) -> StreamSpec | None:
    """The recording's one labelled 3-D marker stream, or None when it has none or several,
    or other streams too (those recordings are reconstructed)."""
    specs = recorded_specs(path)
    marked = [
        s
        for s in specs
        if s.kind == "point3d"
        and tuple(s.values) == ("x", "y", "z")
        and s.n_sensors == 1
        and len(s.metadata.get("marker_labels") or []) == s.n_markers
    ]
    return marked[0] if len(marked) == 1 and len(specs) == 1 else None


def recorded_trial(path: str | os.PathLike[str], spec: StreamSpec) -> Trial:
    """The labelled markers of stream ``spec`` of a recording as a trial (mm).

    Returns
    -------
    Trial
        ``points`` (F, M, 3) mm, F = last - first frame number + 1; ``labels`` the
        stream's; ``point_rate`` its rate; ``first_frame`` 1.
    """
    seqs, data = [], []
    for name, block in replay(path, decoder_for):
        if name == spec.name and len(block):
            seqs.append(block.seq)
            data.append(block.data[:, :, 0, :])
    m = spec.n_markers
    labels = [str(x) for x in spec.metadata["marker_labels"]]
    if not seqs:
        return Trial(points=np.zeros((0, m, 3)), labels=labels, point_rate=spec.rate_hz)
    seq = np.concatenate(seqs)
    x = np.concatenate(data)
    first = int(seq.min())
    points = np.full((int(seq.max()) - first + 1, m, 3), np.nan)
    points[seq - first] = x
    return Trial(
        points=points,
        labels=labels,
        point_rate=spec.rate_hz,
        metadata={"source": str(Path(path)), "stream": spec.name, "first_device_frame": first},
    )
