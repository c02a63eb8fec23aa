"""``spotlab reconstruct`` and ``spotlab export`` of a scanner recording (no calibration)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spotlab.acquisition.recorder import Recorder
from spotlab.acquisition.session import Session
from spotlab.console.cli import main
from spotlab.drivers.coda import CodaDriver
from spotlab.io import read_c3d


@pytest.fixture(scope="module")
def journal(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("coda") / "run.spj"
    device = CodaDriver("sim://coda?markers=3&seed=2", markers=3)
    with Session([device], [Recorder(path)], close_devices=True) as session:
        session.run_for(0.5)
    return path


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
