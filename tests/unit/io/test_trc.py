"""TRC files: real Cortex and OpenSim examples, round trip, gaps, refusals."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spotlab.core.errors import RecordingError
from spotlab.io import Trial, read_trc, write_trc


def test_read_cortex_trc(shared_data: Path) -> None:
    trial = read_trc(shared_data / "bmc" / "walk1.trc")
    assert trial.points.shape == (364, 28, 3)
    assert trial.point_rate == 150.0 and trial.units == "mm" and trial.first_frame == 1
    assert trial.labels[:3] == ["R.ASIS", "L.ASIS", "R.PSIS"]
    assert trial.points[0, 0].tolist() == [-148.01762, 1039.82568, -479.70297]
    assert trial.metadata["times"][-1] == pytest.approx(2.420)


def test_read_opensim_trc(shared_data: Path) -> None:
    trial = read_trc(shared_data / "opensim_models" / "subject01_walk1.trc")
    assert trial.points.shape == (151, 41, 3)
    assert trial.point_rate == 60.0
    assert trial.labels[2] == "V.Sacral"
    assert trial.points[0, 0].tolist() == [617.24762, 1055.27502, 170.78198]


def test_real_trc_round_trip(shared_data: Path, tmp_path: Path) -> None:
    trial = read_trc(shared_data / "bmc" / "walk1.trc")
    write_trc(tmp_path / "w.trc", trial)
    back = read_trc(tmp_path / "w.trc")
    assert np.array_equal(back.points, trial.points)
    assert back.labels == trial.labels and back.point_rate == trial.point_rate


def test_round_trip_with_gaps(tmp_path: Path) -> None:
    rng = np.random.default_rng(2)
    points = rng.normal(0.0, 500.0, (30, 3, 3))
    points[5, 1] = np.nan
    points[:, 2] = np.nan
    trial = Trial(points=points, labels=["a", "b", "c"], point_rate=120.0, first_frame=11)
    write_trc(tmp_path / "g.trc", trial)
    back = read_trc(tmp_path / "g.trc")
    assert np.array_equal(back.points, points, equal_nan=True)  # repr() keeps every bit
    assert back.first_frame == 11 and back.labels == trial.labels
    assert back.metadata["times"][0] == pytest.approx(10 / 120.0, abs=1e-6)  # (f - 1) / rate


def test_metres_are_converted(tmp_path: Path) -> None:
    points = np.arange(18, dtype=float).reshape(2, 3, 3) / 1000.0
    trial = Trial(points=points, labels=["a", "b", "c"], point_rate=50.0, units="m")
    write_trc(tmp_path / "m.trc", trial)
    back = read_trc(tmp_path / "m.trc")
    assert back.units == "mm" and back.metadata["file_units"] == "m"
    assert np.allclose(back.points, points * 1000.0)


@pytest.mark.parametrize(
    ("text", "cause"),
    [
        ("", "not a TRC file"),
        ("hello\n" * 6, "not a TRC file"),
        ("PathFileType\t4\n" + "a\tb\n" * 5, "bad header"),
    ],
)
def test_refusals(tmp_path: Path, text: str, cause: str) -> None:
    path = tmp_path / "bad.trc"
    path.write_text(text)
    with pytest.raises(RecordingError, match=cause) as info:
        read_trc(path)
    assert str(path) in str(info.value)


def test_bad_rows_and_counts(shared_data: Path, tmp_path: Path) -> None:
    lines = (shared_data / "bmc" / "walk1.trc").read_text().splitlines()
    (tmp_path / "short.trc").write_text("\n".join(lines[:-3]) + "\n")
    with pytest.raises(RecordingError, match="NumFrames says 364"):
        read_trc(tmp_path / "short.trc")
    lines[10] = lines[10].replace("\t", "\tx", 3)
    (tmp_path / "text.trc").write_text("\n".join(lines) + "\n")
    with pytest.raises(RecordingError, match="line 11"):
        read_trc(tmp_path / "text.trc")
    with pytest.raises(RecordingError, match="cannot read the file"):
        read_trc(tmp_path / "absent.trc")


@pytest.mark.parametrize("name", ["bmc/walk1.trc", "opensim_models/subject01_walk1.trc"])
def test_round_trip_keeps_the_time_column_and_the_header(
    shared_data: Path, tmp_path: Path, name: str
) -> None:
    """OpenSim's file has 0.017 at 60 Hz (not 1/60) and Cortex's 150.00: both kept as written."""
    source = shared_data / name
    write_trc(tmp_path / "w.trc", read_trc(source))
    original = source.read_text().splitlines()
    written = (tmp_path / "w.trc").read_text().splitlines()
    assert written[2].split("\t") == [v.strip() for v in original[2].split("\t")]

    def times(lines: list[str]) -> list[str]:
        return [line.split("\t")[1].strip() for line in lines[5:] if line.strip()]

    assert times(written) == times(original)
    assert len(times(written)) == read_trc(source).n_frames


def test_time_column_recomputed_when_it_no_longer_fits(shared_data: Path, tmp_path: Path) -> None:
    trial = read_trc(shared_data / "opensim_models" / "subject01_walk1.trc")
    trial.points = trial.points[:10]  # cut: the read times no longer describe the trial
    write_trc(tmp_path / "cut.trc", trial)
    back = read_trc(tmp_path / "cut.trc")
    assert back.metadata["time_text"][1] == f"{1 / 60:.6f}"
    assert back.metadata["header"]["NumFrames"] == "10"
