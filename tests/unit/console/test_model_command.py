"""``spotlab model learn/show/check`` on real labelled trials of several vendors, and every
bad input as one ``spotlab: error:`` line with a non-zero exit."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from spotlab.console.cli import main
from spotlab.reconstruction.identification import MarkerModel

DATA = Path(__file__).resolve().parents[3].parent / "shared" / "data"
GAIT = DATA / "bmc" / "Gait.c3d"  # Motion Analysis EVaRT, markers in frames 133-326


def _data(*parts: str) -> Path:
    path = DATA.joinpath(*parts)
    assert path.is_file(), f"reference data missing: {path}"
    return path


@pytest.mark.parametrize(
    ("parts", "markers"),
    [
        (("bmc", "walk1.trc"), 28),
        (("opensim_models", "subject01_walk1.trc"), 41),
        (("ezc3d_testfiles", "Qualisys.c3d"), 55),
        (("ezc3d_testfiles", "Vicon.c3d"), 51),
        (("c3d_org_samples", "sample01", "Eb015pi.c3d"), 26),
    ],
)
def test_learn_any_vendor_with_defaults(
    parts: tuple[str, ...], markers: int, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "m.json"
    assert main(["model", "learn", str(_data(*parts)), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "chosen from the trial's distance spreads" in text
    model = MarkerModel.load(out)
    assert len(model.labels) == markers
    assert model.tolerance_mm is not None and 5.0 <= model.tolerance_mm < 30.0  # 9-26 mm
    assert f"rigid tolerance {model.tolerance_mm:.1f} mm" in text
    assert len(model.segments) >= 1


def test_learn_show_and_check_other_frames(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "gait.json"
    assert main(["model", "learn", str(_data("bmc", "Gait.c3d")), "--frames", "130:230",
                 "--out", str(out)]) == 0  # fmt: skip
    learnt = capsys.readouterr().out
    assert "33 markers from 100 frames" in learnt
    assert main(["model", "show", str(out)]) == 0
    shown = capsys.readouterr().out
    assert "rigid tolerance" in shown and "rigid segments" in shown
    assert main(["model", "check", str(out), str(GAIT), "--frames", "230:330", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["frames"] == 100 and len(report["markers"]) == 33
    rms = [m["rms_mm"] for m in report["markers"].values() if m["rms_mm"] is not None]
    assert max(rms) < 6.0  # the same subject, other frames: a few mm of skin motion
    assert report["markers"][report["worst"]]["rms_mm"] == max(rms)
    assert 230 <= report["markers"][report["worst"]]["worst_frame"] < 330
    assert main(["model", "check", str(out), str(GAIT), "--frames", "230:330"]) == 0
    assert "worst: " + report["worst"] in capsys.readouterr().out


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["learn", "{data}/ezc3d_testfiles/Kistler.c3d"], "holds no marker trajectories"),
        (["learn", "{data}/c3d_org_samples/sample07/16bitanalog.c3d"], "hardly moves"),
        (["learn", "{data}/bmc/Gait.c3d", "--markers", "RKNE", "NOSE"], "lacks 1 of the 2 markers"),
        (["learn", "{data}/bmc/Gait.c3d", "--frames", "5:x"], "expected A:B"),
        (["learn", "{data}/bmc/Gait.c3d", "--frames", "400:600"], "not a range of its 487"),
        (["learn", "{data}/bmc/Gait.c3d", "--frames", "0:100"], "no labelled marker is seen"),
        (["learn", "{data}/bmc/walk1.forces"], "must end in .c3d or .trc"),
        (["check", "{model}", "{data}/bmc/walk1.trc"], "the trial lacks 33 of the 33"),
        (["show", "{tmp}/none.json"], "not a marker model"),
    ],
)
def test_bad_input_is_one_line(
    args: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model = tmp_path / "gait.json"
    if "{model}" in args:
        assert main(["model", "learn", str(GAIT), "--out", str(model)]) == 0
        capsys.readouterr()
    argv = [a.format(data=DATA, model=model, tmp=tmp_path) for a in args]
    if argv[0] == "learn":
        argv += ["--out", str(tmp_path / "x.json")]
    code = main(["model", *argv])
    err = capsys.readouterr().err
    assert code != 0
    assert err.count("\n") == 1 and err.startswith("spotlab: error: ")
    assert message in err
    assert not (tmp_path / "x.json").exists()
