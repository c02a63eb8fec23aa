"""``spotlab calibrate`` on npz and CSV observations; bad input is one clear line."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from spotlab.console.cli import main
from spotlab.geometry import Rig
from spotlab.simulators.rigs import ring_rig
from spotlab.simulators.wand_dance import WandDance, wand_dance


@pytest.fixture(scope="module")
def dance() -> WandDance:
    return wand_dance(ring_rig(3, seed=1), n_frames=400, held_out_frames=10, body_frames=5)


def _write_csv(d: WandDance, folder: Path) -> tuple[Path, Path]:
    F, C = d.wand.shape[:2]
    wand_csv = folder / "wand.csv"
    with wand_csv.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([f"cam{c + 1}_end{e + 1}_{a}" for c in range(C) for e in range(2) for a in "uv"])
        for f in range(F):
            w.writerow(["" if np.isnan(v) else repr(float(v)) for v in d.wand[f].ravel()])
    frame_csv = folder / "frame.csv"
    with frame_csv.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["X", "Y", "Z"] + [f"cam{c + 1}_{a}" for c in range(C) for a in "uv"])
        for p, X in enumerate(d.frame_points):
            w.writerow([*X.tolist(), *d.frame[:, p].ravel().tolist()])
    return wand_csv, frame_csv


def test_npz_in_calibration_report_and_figure_out(
    dance: WandDance, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    obs = tmp_path / "obs.npz"
    np.savez(
        obs,
        wand=dance.wand,
        frame=dance.frame,
        frame_points=dance.frame_points,
        image_size=np.array([1280, 1024]),
        wand_length=500.0,
    )
    out = tmp_path / "rig.toml"
    assert main(["calibrate", str(obs), "--out", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["calibration"] == str(out)
    rig = Rig.load(out)
    for est, true in zip(rig, dance.rig, strict=True):
        assert np.linalg.norm(est.center - true.center) < 10.0
    saved = json.loads((tmp_path / "rig.report.json").read_text())
    assert saved["wand"]["frames"] == report["wand"]["frames"] > 300
    assert (tmp_path / "rig.report.png").read_bytes()[:4] == b"\x89PNG"


def test_csv_tables_give_the_same_calibration_as_arrays(
    dance: WandDance, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    wand_csv, frame_csv = _write_csv(dance, tmp_path)
    out = tmp_path / "csv.toml"
    args = ["calibrate", str(wand_csv), "--frame", str(frame_csv), "--image-size", "1280", "1024"]
    assert main([*args, "--wand-length", "500", "--out", str(out)]) == 0
    text = capsys.readouterr()
    assert "verdict:" in text.out
    assert "calibrate: cold start" in text.err
    rig = Rig.load(out)
    for est, true in zip(rig, dance.rig, strict=True):
        np.testing.assert_allclose(est.K, true.K, rtol=0.01, atol=5.0)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["missing.npz"], "no such file"),
        (["obs.txt"], "unknown observation format"),
        (["wand.csv"], "CSV input needs --frame"),
        (["obs.npz"], "the wand length is not known"),
        (["rec.spj"], "recording input needs --wand-markers"),
        (["broken.npz", "--wand-length", "500"], "not a readable npz"),
        (["partial.npz", "--wand-length", "500"], "missing array"),
        (["bad.csv", "--frame", "bad.csv", "--image-size", "9", "9"], "is not a number"),
    ],
)
def test_bad_input_is_one_clear_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    (tmp_path / "obs.txt").write_text("x")
    (tmp_path / "wand.csv").write_text("cam1_end1_u\n1\n")
    (tmp_path / "rec.spj").write_bytes(b"")
    (tmp_path / "broken.npz").write_bytes(b"not a zip")
    (tmp_path / "bad.csv").write_text("cam1_end1_u,cam1_u\nabc,1\n")
    np.savez(
        tmp_path / "obs.npz",
        wand=np.zeros((1, 2, 2, 2)),
        frame=np.zeros((2, 1, 2)),
        frame_points=np.zeros((1, 3)),
        image_size=np.array([10, 10]),
    )
    np.savez(tmp_path / "partial.npz", wand=np.zeros((1, 2, 2, 2)))
    argv = [str(tmp_path / argv[0]), *argv[1:]]
    argv = [str(tmp_path / a) if a.endswith(".csv") else a for a in argv]
    code = main(["calibrate", *argv, "--out", str(tmp_path / "o.toml")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0
    assert err[-1].startswith("spotlab: error:")
    assert message in err[-1]
    assert not (tmp_path / "o.toml").exists()


@pytest.mark.parametrize(
    ("option", "value", "message"),
    [
        ("--figure", "nodir/f.png", "the folder"),
        ("--report", "plain.txt/r.json", "is a file, not a folder"),
        ("--report", "o.toml", "the same file as --out"),
        ("--out", ".", "is a folder"),
    ],
)
def test_output_paths_are_checked_before_the_work(
    dance: WandDance,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    option: str,
    value: str,
    message: str,
) -> None:
    obs = tmp_path / "obs.npz"
    np.savez(
        obs,
        wand=dance.wand,
        frame=dance.frame,
        frame_points=dance.frame_points,
        image_size=np.array([1280, 1024]),
        wand_length=500.0,
    )
    (tmp_path / "plain.txt").write_text("a file\n")
    argv = ["calibrate", str(obs), "--out", str(tmp_path / "o.toml")]
    if option == "--out":
        argv = ["calibrate", str(obs)]
    code = main([*argv, option, str(tmp_path / value)])
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert code != 0
    assert err == [err[-1]] and err[-1].startswith(f"spotlab: error: {option}")
    assert message in err[-1]
    assert "calibrate: cold start" not in captured.err  # refused before the work
    assert sorted(p.name for p in tmp_path.iterdir()) == ["obs.npz", "plain.txt"]


def test_distortion_choices(
    dance: WandDance, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    obs = tmp_path / "obs.npz"
    np.savez(
        obs,
        wand=dance.wand,
        frame=dance.frame,
        frame_points=dance.frame_points,
        image_size=np.array([1280, 1024]),
        wand_length=500.0,
    )
    out = tmp_path / "rig.toml"
    for flags, mode, fitted in (
        (["--distortion", "radial"], "radial", ["k1", "k2"]),
        (["--no-distortion"], "none", []),
    ):
        assert main(["calibrate", str(obs), "--out", str(out), "--json", *flags]) == 0
        report = json.loads(capsys.readouterr().out)
        assert report["distortion_mode"] == mode
        assert [c["distortion"]["fitted"] for c in report["cameras"]] == [fitted] * 3
    # The default chooses per camera and says so in the text summary.
    assert main(["calibrate", str(obs), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert text.count("lens terms") == 3 and "(auto)" in text
    saved = json.loads(out.with_suffix(".report.json").read_text())
    assert saved["distortion_mode"] == "auto"
    assert all("k1" in c["distortion"]["fitted"] for c in saved["cameras"])
