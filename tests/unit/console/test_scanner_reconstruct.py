"""``spotlab reconstruct`` and ``spotlab export`` of a scanner recording (no calibration),
and of a recording of two units (B carried into A's frame by the L-frame both see)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from spotlab.acquisition.recorder import Recorder
from spotlab.acquisition.session import Session
from spotlab.console.cli import main
from spotlab.drivers.coda import CodaDriver
from spotlab.io import read_c3d


def _record(path: Path, devices: list[CodaDriver]) -> Path:
    """Half a second of ``devices`` recorded in this process into ``path``."""
    with Session(list(devices), [Recorder(path)], close_devices=True) as session:
        session.run_for(0.5)
    return path


@pytest.fixture(scope="module")
def journal(tmp_path_factory: pytest.TempPathFactory) -> Path:
    device = CodaDriver("sim://coda?markers=3&seed=2", markers=3)
    return _record(tmp_path_factory.mktemp("coda") / "run.spj", [device])


def test_reconstruct_prints_the_precision_model(
    journal: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run.c3d"
    assert main(["reconstruct", str(journal), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "3-D from the angles (base 1000 mm)" in text
    assert [line.split()[0] for line in text.splitlines()[1:4]] == ["RO", "RY", "RG"]
    trial = read_c3d(out)
    assert trial.labels == ["RO", "RY", "RG"] and trial.point_rate == 300.0
    y = trial.points[..., 1]
    assert np.isfinite(y).mean() > 0.9 and 2000 < np.nanmedian(y) < 4000


def test_export_writes_the_scanner_trajectories(
    journal: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "export.c3d"
    assert main(["export", str(journal), "--c3d", str(out)]) == 0
    assert "x 3 markers at 300 Hz" in capsys.readouterr().out
    assert read_c3d(out).points.shape[1:] == (3, 3)


def test_a_calibration_is_refused_in_one_line(
    journal: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["reconstruct", str(journal), "--out", str(tmp_path / "x.c3d"), "--calibration"]
    assert main([*args, str(journal)]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "takes no --calibration" in err[0]


@pytest.fixture(scope="module")
def two_units(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("coda2") / "two.spj"
    table = "RO,RY,RG,RC,WR,WO,WY,WG"
    devices = [
        CodaDriver(f"sim://coda?markers=4&seed={k + 1}&reference=1&pose={pose}",
                   name=name, markers=table)
        for k, (name, pose) in enumerate((("codaA", "0,0,0,0"), ("codaB", "15,800,0,0")))
    ]  # fmt: skip
    return _record(path, devices)


def test_two_units_in_the_first_ones_frame(
    two_units: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "two.c3d"
    assert main(["reconstruct", str(two_units), "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    fit = summary["units"][1]["alignment"]
    assert fit["method"] == "still" and fit["markers"] == ["WR", "WO", "WY", "WG"]
    assert fit["rms_mm"] < 0.1 and summary["time_base"] == "host"
    # B stands 800 mm along A's x, turned 15 degrees: p_a = R p_b + t.
    assert np.allclose(fit["translation_mm"], [800.0, 0.0, 0.0], atol=3.0)
    yaw = np.degrees(np.arctan2(fit["rotation"][1][0], fit["rotation"][0][0]))
    assert yaw == pytest.approx(15.0, abs=0.1)
    trial = read_c3d(out)
    assert trial.labels[:2] == ["codaA.RO", "codaA.RY"] and len(trial.labels) == 16
    # The L-frame as B saw it, carried into A's frame, where A saw it.
    a, b = trial.points[:, 4:8], trial.points[:, 12:16]
    assert np.nanmedian(np.linalg.norm(a - b, axis=-1)) < 1.0
    assert main(["export", str(two_units), "--c3d", str(tmp_path / "e.c3d")]) == 0
    assert "x 16 markers" in capsys.readouterr().out
    assert read_c3d(tmp_path / "e.c3d").labels == trial.labels


def test_shared_markers_no_unit_has_is_one_line(
    two_units: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["reconstruct", str(two_units), "--out", str(tmp_path / "x.c3d")]
    assert main([*args, "--align-markers", "WR", "XX"]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no scanner has the marker code(s) XX" in err[0]
    assert main([*args, "--align-markers", "RO", "WR"]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "needs 3 shared markers" in err[0]
