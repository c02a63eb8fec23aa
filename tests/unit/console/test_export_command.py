"""``spotlab export``: C3D <-> TRC conversion, a recording reconstructed with the
simulator's true rig and compared with its truth, and every bad input as one clear line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import spotlab.simulators  # noqa: F401  (registers sim://)
from spotlab.acquisition.recorder import Recorder
from spotlab.acquisition.session import Session
from spotlab.console.cli import main
from spotlab.drivers.selspot import SelspotDriver
from spotlab.io import Trial, read_c3d, read_trc, write_c3d
from spotlab.processing.trajectories import reconstruct_file
from spotlab.simulators.rigs import ring_rig
from spotlab.simulators.truth import read_truth_positions


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``trial.c3d`` (3 markers, 40 frames, a gap), ``run.spj`` (0.4 s of a simulated
    3-camera x 6-LED system), its true rig ``psd.toml`` and truth ``truth.csv``."""
    path = tmp_path_factory.mktemp("export")
    rng = np.random.default_rng(1)
    points = rng.uniform(-1000.0, 1000.0, (40, 3, 3))
    points[5:9, 1] = np.nan
    write_c3d(path / "trial.c3d", Trial(points, ["a", "b", "c"], 120.0))
    url = (
        f"sim://selspot?cameras=3&leds=6&rate=100&reflectance=0&seed=3"
        f"&truth={path / 'truth.csv'}&rig_out={path / 'psd.toml'}"
    )
    driver = SelspotDriver(url, cameras=3, leds=6, rate_hz=100)
    with Session([driver], [Recorder(path / "run.spj")], close_devices=True) as session:
        session.run_for(0.4)
    return path


def test_c3d_to_trc_to_c3d_keeps_the_trajectories(
    folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    original = read_c3d(folder / "trial.c3d")
    trc, back = tmp_path / "t.trc", tmp_path / "t.c3d"
    assert main(["export", str(folder / "trial.c3d"), "--trc", str(trc)]) == 0
    assert "converted 40 frames x 3 markers at 120 Hz" in capsys.readouterr().out
    assert main(["export", str(trc), "--c3d", str(back), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["frames"] == 40 and summary["outputs"] == [str(back)]
    for trial in (read_trc(trc), read_c3d(back)):
        assert trial.labels == original.labels and trial.point_rate == 120.0
        assert np.array_equal(np.isnan(trial.points), np.isnan(original.points))
        assert np.allclose(trial.points, original.points, atol=1e-3, equal_nan=True)


def test_recording_with_the_true_rig_to_c3d_and_trc_at_once(
    folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    c3d, trc = tmp_path / "run.c3d", tmp_path / "run.trc"
    args = ["export", str(folder / "run.spj"), "--calibration", str(folder / "psd.toml")]
    assert main([*args, "--c3d", str(c3d), "--trc", str(trc), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["markers"] == 6 and summary["cameras"] == 3 and summary["rate_hz"] == 100.0
    assert summary["units"] == "detector counts" and summary["reconstructed_fraction"] > 0.9
    trial = read_c3d(c3d)
    assert np.allclose(read_trc(trc).points, trial.points, atol=1e-3, equal_nan=True)
    # Frame k of the trial is the recorded frame stamped ticks[k]: compare with the truth.
    ticks = reconstruct_file(folder / "run.spj", folder / "psd.toml").ticks
    assert ticks is not None and ticks.shape == (trial.n_frames,)
    truth = read_truth_positions(folder / "truth.csv").at_ticks(ticks)
    error = np.linalg.norm(trial.points - truth, axis=-1)
    assert np.isfinite(error).mean() > 0.9
    # PSD noise of ~2 counts at 3.5 m and focal 3500 counts is ~2 mm per ray.
    assert np.sqrt(np.nanmean(error**2)) < 5.0


def _one_error_line(capsys: pytest.CaptureFixture[str]) -> str:
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("spotlab: error:") and "Traceback" not in captured.err
    return lines[0]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["run.spj", "--c3d", "o.c3d"], "needs --calibration"),
        (["trial.c3d"], "give --c3d OUT and/or --trc OUT"),
        (["missing.c3d", "--trc", "o.trc"], "missing.c3d: no such file"),
        (["trial.xyz", "--trc", "o.trc"], "unknown input format '.xyz'"),
        (["trial.c3d", "--c3d", "o.trc"], "--c3d"),
        (["trial.c3d", "--trc", "o.c3d"], "must end in .trc"),
        (["broken.c3d", "--trc", "o.trc"], "broken.c3d"),
        (["run.spj", "--calibration", "missing.toml", "--c3d", "o.c3d"], "no such calibration"),
        (["run.spj", "--calibration", "bad.toml", "--c3d", "o.c3d"], "bad.toml"),
        (["run.spj", "--calibration", "pair.toml", "--c3d", "o.c3d"], "the calibration has 2"),
    ],
)
def test_bad_input_is_one_clear_line(
    folder: Path, capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    (folder / "trial.xyz").write_text("x\n")
    (folder / "broken.c3d").write_bytes(b"\x02P" + bytes(100))
    (folder / "bad.toml").write_text("[cam1]\nmatrix = 3\n")
    ring_rig(2).save(folder / "pair.toml")
    code = main(["export", *[a if a.startswith("-") else str(folder / a) for a in args]])
    assert code != 0
    assert message in _one_error_line(capsys)
    assert not (folder / "o.c3d").exists() and not (folder / "o.trc").exists()


def test_c3d_to_c3d_keeps_the_force_plates_unless_dropped(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from spotlab.io.c3d_files import read_c3d_parameters

    source = shared_data / "c3d_org_samples" / "sample10" / "TYPE-4.C3D"
    kept, dropped = tmp_path / "kept.c3d", tmp_path / "dropped.c3d"
    assert main(["export", str(source), "--c3d", str(kept)]) == 0
    drop = ["--drop-group", "force_platform"]
    assert main(["export", str(source), "--c3d", str(dropped), *drop]) == 0
    capsys.readouterr()
    original = read_c3d_parameters(source)[1]
    copy = read_c3d_parameters(kept)[1]
    assert set(original.groups) <= set(copy.groups)
    for name in ("TYPE", "CORNERS", "ORIGIN", "CHANNEL", "CAL_MATRIX"):
        key = f"FORCE_PLATFORM:{name}"
        assert np.array_equal(copy.get(key).floats(), original.get(key).floats()), key
    assert "FORCE_PLATFORM" not in read_c3d_parameters(dropped)[1].groups


def test_trc_to_trc_keeps_the_time_column(shared_data: Path, tmp_path: Path) -> None:
    source = shared_data / "opensim_models" / "subject01_walk1.trc"
    out = tmp_path / "copy.trc"
    assert main(["export", str(source), "--trc", str(out), "--json"]) == 0
    assert read_trc(out).metadata["time_text"] == read_trc(source).metadata["time_text"]
    assert read_trc(out).metadata["time_text"][1] == "0.017000"


def test_smooth_writes_each_coordinate_smoothed_and_keeps_gaps(
    folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from spotlab.kinematics import smooth_trial

    out = tmp_path / "smooth.c3d"
    source = folder / "trial.c3d"
    assert main(["export", str(source), "--c3d", str(out), "--smooth", "--json"]) == 0
    assert "spline" in json.loads(capsys.readouterr().out)["smoothed"]
    original, written = read_c3d(source), read_c3d(out)
    assert np.array_equal(np.isnan(written.points), np.isnan(original.points))
    expected = smooth_trial(original).points
    assert np.allclose(written.points, expected, atol=1e-3, equal_nan=True)
    assert not np.allclose(written.points, original.points, atol=1.0, equal_nan=True)
    trc = tmp_path / "smooth.trc"
    assert main(["export", str(source), "--trc", str(trc), "--smooth"]) == 0
    assert "smoothed           quintic GCV spline" in capsys.readouterr().out
