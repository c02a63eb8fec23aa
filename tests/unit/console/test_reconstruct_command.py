"""``spotlab reconstruct`` on npz and CSV observations of a synthetic rig: trajectories at
the noise level, C3D and TRC out, summary and JSON; every bad input is one clear line."""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from spotlab.console.cli import main
from spotlab.console.errors import CommandError
from spotlab.console.progress import Progress
from spotlab.geometry import Rig
from spotlab.io import read_c3d, read_trc
from spotlab.processing.marker_observations import MarkerObservations
from spotlab.processing.recorded_observations import SelspotRecording, frame_numbers
from spotlab.processing.trajectories import reconstruct
from spotlab.simulators.rigs import ring_rig

NOISE_PX = 0.2
F, M, C = 120, 4, 4


@dataclass
class Scene:
    folder: Path
    rig: Path
    points: np.ndarray  # (F, M, 3) mm
    uv: np.ndarray  # (F, C, M, 2) px, noisy, NaN where unseen


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Scene:
    folder = tmp_path_factory.mktemp("reconstruct")
    rig = ring_rig(C, seed=2)
    rig.save(folder / "rig.toml")
    rng = np.random.default_rng(5)
    t = np.arange(F) / 100.0
    centre = np.stack([300 * np.cos(t), 300 * np.sin(t), 900 + 100 * t], axis=1)
    points = centre[:, None, :] + rng.uniform(-200.0, 200.0, (1, M, 3))
    uv = rig.project(points).transpose(1, 0, 2, 3) + rng.normal(0.0, NOISE_PX, (F, C, M, 2))
    uv[:10, 1:, 3] = np.nan  # marker 4 seen by one camera only in the first 10 frames
    np.savez(folder / "obs.npz", uv=uv, rate=100.0, labels=np.array(["A", "B", "C", "D"]))
    return Scene(folder, folder / "rig.toml", points, uv)


def _error(found: np.ndarray, true: np.ndarray) -> np.ndarray:
    return np.linalg.norm(found - true, axis=-1)


def test_npz_to_c3d_at_the_noise_level(
    scene: Scene, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run.c3d"
    with pytest.raises(SystemExit) as info:  # --out is required
        main(["reconstruct", str(scene.folder / "obs.npz"), "--calibration", str(scene.rig)])
    assert info.value.code == 2
    assert "required: --out" in capsys.readouterr().err
    args = ["reconstruct", str(scene.folder / "obs.npz"), "--calibration", str(scene.rig)]
    assert main([*args, "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"reconstructed {F} frames x {M} markers at 100 Hz" in text
    assert "RMS ray residual" in text and str(out) in text
    trial = read_c3d(out)
    assert trial.labels == ["A", "B", "C", "D"] and trial.point_rate == 100.0
    assert trial.points.shape == (F, M, 3)
    assert np.isnan(trial.points[:10, 3]).all()  # one view is not enough
    err = _error(trial.points, scene.points)
    seen = np.isfinite(err)
    assert seen.sum() == F * M - 10
    # 0.2 px at ~3.5 m with focal ~1000 px is ~0.7 mm per ray; a point from 4 rays is better.
    assert np.sqrt(np.mean(err[seen] ** 2)) < 1.0
    assert err[seen].max() < 3.0


def test_json_summary_and_labels_rate_options(
    scene: Scene, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run.trc"
    args = ["reconstruct", str(scene.folder / "obs.npz"), "--calibration", str(scene.rig)]
    labels = ["w", "x", "y", "z"]
    assert main([*args, "--out", str(out), "--json", "--rate", "50", "--labels", *labels]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["frames"] == F and summary["markers"] == M and summary["cameras"] == C
    assert summary["reconstructed_fraction"] == pytest.approx((F * M - 10) / (F * M))
    # The RMS ray residual of a 4-ray point is about the noise per axis times sqrt(2 (4-1.5)/4).
    assert 0.5 * NOISE_PX < summary["rms_ray_px"] < 2.0 * NOISE_PX
    assert set(summary["rms_ray_px_per_camera"]) == {"cam1", "cam2", "cam3", "cam4"}
    assert summary["outputs"] == [str(out)]
    trial = read_trc(out)
    assert trial.labels == labels and trial.point_rate == 50.0
    assert np.sqrt(np.nanmean(_error(trial.points, scene.points) ** 2)) < 1.0


def test_csv_table_to_c3d_with_dlt(
    scene: Scene, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    table = tmp_path / "obs.csv"
    with table.open("w", newline="") as fh:
        w = csv.writer(fh)
        names = [f"cam{c + 1}_m{m + 1}_{a}" for c in range(C) for m in range(M) for a in "uv"]
        w.writerow(["frame", *names])
        for f in range(F):
            w.writerow([f] + ["" if np.isnan(v) else repr(float(v)) for v in scene.uv[f].ravel()])
    out = tmp_path / "run.c3d"
    args = ["reconstruct", str(table), "--calibration", str(scene.rig), "--out", str(out)]
    assert main(args) == 1
    assert "give --rate" in capsys.readouterr().err
    assert main([*args, "--rate", "100", "--method", "dlt"]) == 0
    trial = read_c3d(out)
    assert trial.labels == ["M1", "M2", "M3", "M4"]
    err = _error(trial.points, scene.points)
    assert np.isfinite(err).sum() == F * M - 10
    assert np.sqrt(np.nanmean(err**2)) < 1.0


def test_cameras_matched_by_name(scene: Scene, tmp_path: Path) -> None:
    """Observations of cameras 3 and 1 (named) reconstruct with the 4-camera rig."""
    obs = tmp_path / "pair.npz"
    np.savez(obs, uv=scene.uv[:, [2, 0]], rate=100.0, camera_names=np.array(["cam3", "cam1"]))
    out = tmp_path / "pair.c3d"
    assert main(["reconstruct", str(obs), "--calibration", str(scene.rig), "--out", str(out)]) == 0
    err = _error(read_c3d(out).points, scene.points)
    assert np.sqrt(np.nanmean(err**2)) < 3.0  # two rays only


def _one_error_line(capsys: pytest.CaptureFixture[str]) -> str:
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("spotlab: error:") and "Traceback" not in captured.err
    return lines[0]


@pytest.mark.parametrize(
    ("observations", "calibration", "out", "extra", "message"),
    [
        ("missing.npz", "rig.toml", "o.c3d", [], "missing.npz: no such file"),
        ("obs.txt", "rig.toml", "o.c3d", [], "unknown observation format '.txt'"),
        ("obs.npz", "rig.toml", "o.mat", [], "unknown output format '.mat'"),
        ("obs.npz", "missing.toml", "o.c3d", [], "missing.toml: no such calibration file"),
        ("obs.npz", "bad.toml", "o.c3d", [], "bad.toml: not a valid TOML file"),
        ("obs.npz", "pair.toml", "o.c3d", [], "4 cameras but the calibration has 2"),
        ("named.npz", "rig.toml", "o.c3d", [], "no camera 'left'"),
        ("obs.npz", "rig.toml", "o.c3d", ["--labels", "a", "b"], "2 marker labels for 4"),
        ("obs.npz", "rig.toml", "o.c3d", ["--rate", "0"], "must be a positive number"),
        ("flat.npz", "rig.toml", "o.c3d", [], "must have shape (F, C, M, 2)"),
        ("nouv.npz", "rig.toml", "o.c3d", [], "missing array 'uv'"),
        ("text.npz", "rig.toml", "o.c3d", [], "not a readable npz file"),
        ("obs.npz", "rig.toml", "nofolder/o.c3d", [], "does not exist"),
        ("obs.spj", "rig.toml", "o.c3d", [], "obs.spj"),
    ],
)
def test_bad_input_is_one_clear_line(
    scene: Scene,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    observations: str,
    calibration: str,
    out: str,
    extra: list[str],
    message: str,
) -> None:
    for name in ("obs.npz", "rig.toml"):
        (tmp_path / name).write_bytes((scene.folder / name).read_bytes())
    (tmp_path / "obs.txt").write_text("1 2 3\n")
    (tmp_path / "obs.spj").write_text("not a journal\n")
    (tmp_path / "bad.toml").write_text("[cam1\nsize = 3\n")
    ring_rig(2).save(tmp_path / "pair.toml")
    np.savez(tmp_path / "named.npz", uv=scene.uv, rate=1.0, camera_names=["left", "a", "b", "c"])
    np.savez(tmp_path / "flat.npz", uv=scene.uv[0])
    np.savez(tmp_path / "nouv.npz", xy=scene.uv)
    (tmp_path / "text.npz").write_text("not a zip\n")
    code = main(
        [
            "reconstruct",
            str(tmp_path / observations),
            "--calibration",
            str(tmp_path / calibration),
            "--out",
            str(tmp_path / out),
            *extra,
        ]
    )
    assert code != 0
    assert message in _one_error_line(capsys)
    assert not (tmp_path / out).exists()


def test_progress_is_shown_per_chunk_of_frames(scene: Scene) -> None:
    stream = io.StringIO()
    progress = Progress("reconstructing", total=F, stream=stream, force=True)
    obs = MarkerObservations(scene.uv, rate_hz=100.0)
    result = reconstruct(Rig.load(scene.rig), obs, progress=progress)
    assert f"{F} of {F} frames" in stream.getvalue() and stream.getvalue().endswith("\n")
    assert result.trial.n_frames == F


def _recording(ticks: list[int]) -> SelspotRecording:
    n = len(ticks)
    data = np.full((n, 1, 2, 3), 2000.0)
    return SelspotRecording(data, np.ones((n, 1, 2), np.uint8), np.array(ticks), 200.0, 1e6)


def test_recorded_frames_keep_their_place_and_lost_ones_are_gaps() -> None:
    # 200 Hz, µs ticks: the third and fourth frames were lost on the link.
    placed = frame_numbers(_recording([1000, 6001, 20999, 26000]), Path("r.spj"))
    assert placed.tolist() == [0, 1, 4, 5]
    with pytest.raises(CommandError, match="go backwards or repeat"):
        frame_numbers(_recording([1000, 6000, 6000]), Path("r.spj"))
    recording = _recording([0, 5000])
    recording.rate_hz = float("nan")
    with pytest.raises(CommandError, match="does not state its frame and tick rates"):
        frame_numbers(recording, Path("r.spj"))
