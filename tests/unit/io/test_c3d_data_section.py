"""The bytes of write_c3d's data section, against a frame-by-frame layout built here."""

from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np
import pytest

from spotlab.io import Trial, write_c3d


def _expected(trial: Trial, per_frame: int) -> bytes:
    """The data section as the C3D manual lays it out, one frame and one marker at a time."""
    out = bytearray()
    for f in range(trial.n_frames):
        for m in range(trial.n_markers):
            xyz = [float(v) for v in trial.points[f, m]]
            if all(math.isfinite(v) for v in xyz):
                out += struct.pack("<4f", *xyz, 0.0)
            else:
                out += struct.pack("<4f", 0.0, 0.0, 0.0, -1.0)
        for s in trial.analog[f * per_frame : (f + 1) * per_frame]:
            out += struct.pack(f"<{len(s)}f", *(float(v) for v in s))
    return bytes(out)


def _data_section(path: Path) -> bytes:
    """Everything from the data start block (header word 9) to the end of the file."""
    raw = path.read_bytes()
    data_block = int(np.frombuffer(raw[:18], dtype="<u2")[8])
    return raw[(data_block - 1) * 512 :]


@pytest.mark.parametrize(("markers", "channels", "per_frame"), [(5, 0, 0), (5, 3, 4), (0, 2, 1)])
def test_data_section_bytes(tmp_path: Path, markers: int, channels: int, per_frame: int) -> None:
    rng = np.random.default_rng(7)
    frames = 40
    points = rng.normal(0.0, 800.0, (frames, markers, 3))
    if markers:
        points[rng.random((frames, markers)) < 0.2, rng.integers(0, 3)] = np.nan
        points[2, 0] = (np.inf, 1.0, 2.0)
        points[3, 1] = (1.0, -np.inf, np.nan)
        points[4, 2] = (-0.0, 0.0, -0.0)  # signed zeros of a seen sample are kept
    trial = Trial(
        points=points,
        labels=[f"M{i}" for i in range(markers)],
        point_rate=50.0,
        analog=rng.normal(0.0, 2.0, (frames * per_frame, channels)),
        analog_labels=[f"A{i}" for i in range(channels)],
        analog_rate=50.0 * per_frame,
    )
    path = tmp_path / "t.c3d"
    write_c3d(path, trial)
    expected = _expected(trial, per_frame)
    assert len(expected) == frames * (4 * markers + channels * per_frame) * 4
    section = _data_section(path)
    assert section[: len(expected)] == expected
    # then zeros up to the end of the 512-byte block, and nothing more
    assert section[len(expected) :] == bytes(-len(expected) % 512)


def test_noncontiguous_inputs_give_the_same_bytes(tmp_path: Path) -> None:
    rng = np.random.default_rng(8)
    points = rng.normal(0.0, 800.0, (30, 6, 3))
    points[5, 2, 1] = np.nan
    analog = rng.normal(0.0, 2.0, (60, 4))
    contiguous = Trial(
        points, [f"M{i}" for i in range(6)], 100.0, analog, ["A", "B", "C", "D"], 200.0
    )
    strided = Trial(
        np.asfortranarray(points)[:, ::-1][:, ::-1],
        contiguous.labels,
        100.0,
        np.asfortranarray(analog),
        contiguous.analog_labels,
        200.0,
    )
    write_c3d(tmp_path / "a.c3d", contiguous)
    write_c3d(tmp_path / "b.c3d", strided)
    assert (tmp_path / "a.c3d").read_bytes() == (tmp_path / "b.c3d").read_bytes()
