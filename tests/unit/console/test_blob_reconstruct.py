"""``spotlab reconstruct`` / ``spotlab export`` of a video-centroid recording: blobs of an
in-process simulated hub (sim://centroid) identified and named by the marker model that
``spotlab record --model`` stores, compared with the simulator's truth; every bad input
as one clear line. The rig and the model are the lab's own (conftest.py): the rig
calibrated from wand and L-frame recordings, the subject's model learnt from its static
and range-of-motion recordings; the trials labelled are the same subject walking, and
only the final scoring reads the simulator's truth."""

from __future__ import annotations

import dataclasses
import json
import shutil
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from _centroid_lab import LAB_GROUP, SUBJECT, SubjectLab

import spotlab.simulators  # noqa: F401  (registers sim://)
from spotlab.acquisition.recorder import Recorder
from spotlab.acquisition.session import Session
from spotlab.console.cli import main
from spotlab.console.errors import CommandError
from spotlab.drivers.centroid import CentroidDriver
from spotlab.geometry import Rig
from spotlab.io import read_c3d, read_trc
from spotlab.io.journal import JournalReader
from spotlab.processing.blob_trajectories import (
    MODEL_KEY,
    BlobRecording,
    _frame_numbers,
    identify_recording,
)
from spotlab.reconstruction.identification import MarkerModel
from spotlab.simulators.centroid_service import CentroidSimOptions, centroid_url_for
from spotlab.testing.centroid_scene import centroid_scene

# one worker makes the session recordings shared with the other hub tests (conftest.py)
pytestmark = pytest.mark.xdist_group(LAB_GROUP)

RATE_HZ, SECONDS = 300, 0.7


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory, subject_lab: SubjectLab) -> Path:
    """``walk.spj`` (0.7 s of 8 cameras x 40 markers of the subject walking at 300 Hz,
    with the lab's marker model in its session metadata), ``bare.spj`` (0.3 s, no model),
    their truths ``walk.npz`` and ``bare.npz`` (scoring only), and the lab's ``rig.toml``
    and ``model.json``."""
    path = tmp_path_factory.mktemp("blobs")
    shutil.copyfile(subject_lab.rig, path / "rig.toml")
    shutil.copyfile(subject_lab.model, path / "model.json")
    model = MarkerModel.load(path / "model.json").to_json()
    for name, seconds, meta in (
        ("walk", SECONDS, {"command": "record", MODEL_KEY: model}),
        ("bare", 0.3, {"command": "record"}),
    ):
        options = CentroidSimOptions(
            cameras=8, rate_hz=RATE_HZ, seed=SUBJECT, truth=path / f"{name}.npz"
        )  # fmt: skip
        driver = CentroidDriver(centroid_url_for(options), cameras=8, rate_hz=RATE_HZ)
        with Session([driver], [Recorder(path / f"{name}.spj", meta)], close_devices=True) as s:
            _run_frames(s, seconds)
    return path


def _run_frames(session: Session, seconds: float) -> None:
    """Run (started) until ``seconds`` of hub frames are recorded: the in-process simulator renders
    a frame in 2-3 ms of a core, so on a busy machine its clock falls behind the wall's
    and a wall-clock 0.7 s holds fewer of its frames (the faults below are scheduled on
    its clock)."""
    wanted, deadline = round(seconds * RATE_HZ), time.monotonic() + 60.0
    while sum(session.status().frames.values()) < wanted and time.monotonic() < deadline:
        time.sleep(0.02)


def _truth_at(trial_first: int, n_frames: int, truth: Any) -> np.ndarray:
    """True markers (F, M, 3) of C3D frames first_frame + i = hub frame first_frame - 1 + i
    (one START: here, so frame numbers are unique)."""
    row = {int(f): k for k, f in enumerate(truth["frame_no"])}
    return np.asarray(truth["markers_mm"][[row[trial_first - 1 + i] for i in range(n_frames)]])


def test_reconstruct_names_and_places_the_markers_of_the_truth(
    folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "walk.c3d"
    args = ["reconstruct", str(folder / "walk.spj"), "--calibration", str(folder / "rig.toml")]
    assert main([*args, "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["method"] == "identification" and summary["cameras"] == 8
    assert summary["markers"] == 40 and summary["rate_hz"] == RATE_HZ
    trial, truth = read_c3d(out), np.load(folder / "walk.npz")
    assert trial.labels == [str(x) for x in truth["labels"]]
    # A host too busy to render 300 Hz in real time runs the in-process hub's clock slow
    # (fewer frames, none lost): 115 of 210 at load 10.
    assert trial.n_frames == summary["frames"] >= 0.25 * SECONDS * RATE_HZ
    err = np.linalg.norm(
        trial.points - _truth_at(trial.first_frame, trial.n_frames, truth), axis=-1
    )
    reported = np.isfinite(err)
    decoded = reported.any(axis=1)  # frames lost on a busy machine are gaps
    # Measured (seed 1, 0.7 s at 300 Hz, the lab's rig and model, 6 runs): 100 % of
    # marker-frames labelled, none wrong, every one within 1.8 mm, RMS 0.73-0.95 mm (the
    # calibrated rig's error; the simulator's true rig and truth-learnt model gave
    # 99.3-99.4 %, within 1 mm).
    assert reported[decoded].mean() > 0.9 and decoded.mean() > 0.5
    assert (err[reported] < 5.0).mean() >= 0.99
    assert np.sqrt(np.mean(err[reported] ** 2)) < 1.2
    assert (err[reported] > 20.0).mean() <= 0.003
    assert abs(summary["labelled_fraction"] - reported[decoded].mean()) < 0.02
    assert summary["ghosts_rejected"] >= 0 and summary["marker_gaps"] >= 0
    assert set(summary["camera_frames"]["cam1"]) == {"offline", "overflow", "flooded", "no_blobs"}
    # The text summary.
    assert main([*args, "--out", str(tmp_path / "walk.trc")]) == 0
    text = capsys.readouterr().out
    assert "identified" in text and "labelled" in text and "walk.trc" in text
    assert np.allclose(
        read_trc(tmp_path / "walk.trc").points, trial.points, atol=1e-3, equal_nan=True
    )


def test_export_writes_the_same_labelled_trajectories(
    folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec, rig = folder / "walk.spj", folder / "rig.toml"
    a, b = tmp_path / "a.c3d", tmp_path / "b.c3d"
    assert main(["reconstruct", str(rec), "--calibration", str(rig), "--out", str(a)]) == 0
    assert main(["export", str(rec), "--calibration", str(rig), "--c3d", str(b)]) == 0
    assert "identified" in capsys.readouterr().out
    ta, tb = read_c3d(a), read_c3d(b)
    assert ta.labels == tb.labels and ta.first_frame == tb.first_frame
    assert np.allclose(ta.points, tb.points, atol=1e-3, equal_nan=True)


def test_record_stores_the_model_given(folder: Path, tmp_path: Path) -> None:
    url = "sim://centroid?cameras=2&markers=40&rate=50"
    journal = tmp_path / "r.spj"
    args = ["record", "--device", f"centroid={url}", "--cameras", "2", "--rate", "50"]
    assert (
        main(
            [
                *args,
                "--seconds",
                "0.1",
                "--out",
                str(journal),
                "--model",
                str(folder / "model.json"),
            ]
        )
        == 0
    )
    stored = JournalReader(journal).session[MODEL_KEY]
    assert stored == MarkerModel.load(folder / "model.json").to_json()


def _one_error_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_a_bad_model_file_for_record_is_one_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text('{"labels": ["A"]}')
    journal = tmp_path / "r.spj"
    args = ["record", "--device", "centroid=sim://centroid", "--seconds", "0.1"]
    assert main([*args, "--out", str(journal), "--model", str(bad)]) != 0
    assert "not a marker model" in _one_error_line(capsys)
    assert not journal.exists()


def test_no_model_is_one_clear_error_naming_both_ways(
    folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "bare.c3d"
    args = ["reconstruct", str(folder / "bare.spj"), "--calibration", str(folder / "rig.toml")]
    assert main([*args, "--out", str(out)]) == 1
    line = _one_error_line(capsys)
    assert "--model MODEL.json" in line and "spotlab record --model" in line
    assert not out.exists()
    assert main([*args, "--out", str(out), "--model", str(folder / "model.json")]) == 0
    assert read_c3d(out).labels == list(MarkerModel.load(folder / "model.json").labels)


def test_a_rig_of_other_cameras_is_one_clear_error(
    folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    small = tmp_path / "four.toml"
    Rig(Rig.load(folder / "rig.toml").cameras[:4]).save(small)
    out = tmp_path / "x.c3d"
    assert (
        main(
            [
                "reconstruct",
                str(folder / "walk.spj"),
                "--calibration",
                str(small),
                "--out",
                str(out),
            ]
        )
        == 1
    )
    line = _one_error_line(capsys)
    assert "8 cameras" in line and "calibration has 4" in line
    assert not out.exists()


def test_labels_option_is_refused_for_blobs(
    folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["reconstruct", str(folder / "walk.spj"), "--calibration", str(folder / "rig.toml")]
    assert main([*args, "--out", str(tmp_path / "x.c3d"), "--labels", "A"]) == 1
    assert "marker model" in _one_error_line(capsys)


def test_a_restarted_stream_goes_on_after_a_gap_on_the_hubs_clock(folder: Path) -> None:
    # The hub's frames decoded in process (no pacing: every frame, the same each run).
    scene = centroid_scene(0.5, RATE_HZ, seed=SUBJECT, cameras=8)
    model = MarkerModel.load(folder / "model.json")
    b, k, path = scene.blobs, 50, folder / "scene.spj"
    rec = BlobRecording(b, _frame_numbers(b, RATE_HZ, path), RATE_HZ, "centroid", None)
    np.testing.assert_array_equal(rec.frame_no, rec.frame_no[0] + np.arange(b.n_frames))
    # The driver restarted the stream after frame k - 1: counters start again from 0,
    # and the hub's clock shows 40 frame periods more than the recording had.
    shift = np.zeros(b.n_frames, np.int64)
    shift[k:] = round(40e6 / RATE_HZ)
    frames = b.camera_frame.copy()
    frames[k:] -= frames[k]
    blobs = dataclasses.replace(b, camera_frame=frames, ticks=b.ticks + shift)
    number = _frame_numbers(blobs, RATE_HZ, path)
    np.testing.assert_array_equal(number[k:] - number[k - 1], np.arange(b.n_frames - k) + 41)
    rig = Rig.load(folder / "rig.toml")  # the lab's: scene.rig is the simulator's truth
    done = identify_recording(rig, BlobRecording(blobs, number, RATE_HZ, "c", None), model)
    assert done.summary["lost_frames"] == 40 and done.trial.n_frames == b.n_frames + 40
    assert done.summary["identification_restarts"] == 1
    assert np.isnan(done.trial.points[k : k + 40]).all()
    # Labels are earned again after the gap, at the true positions. Measured with the lab's
    # model: 92.5 % (LANK, LHEE, LTOE not earned again in the 100 frames; the simulator's
    # truth-learnt model earned every one).
    after = done.trial.points[-20:]
    err = np.linalg.norm(after - scene.markers_mm[-20:], axis=-1)
    assert np.isfinite(err).mean() > 0.9 and np.nanmax(err) < 5.0
    # A hub whose clock went back (it restarted itself) cannot be placed.
    back = dataclasses.replace(b, camera_frame=frames, ticks=b.ticks - shift)
    with pytest.raises(CommandError, match="clock went backwards"):
        _frame_numbers(back, RATE_HZ, path)


def test_the_labs_model_names_the_truth_labels_and_the_subjects_clusters(folder: Path) -> None:
    model = MarkerModel.load(folder / "model.json")
    truth = np.load(folder / "walk.npz")  # scoring: the model never saw this walk
    labels = [str(x) for x in truth["labels"]]
    assert list(model.labels) == labels
    assert len(model.segments) >= 1
    true = np.asarray(truth["markers_mm"])
    for seg in model.segments:
        X = true[:, [labels.index(model.labels[m]) for m in seg.markers]]
        d_true = np.nanmedian(np.linalg.norm(X[:, :, None] - X[:, None], axis=-1), axis=0)
        d_model = np.linalg.norm(seg.coordinates[:, None] - seg.coordinates[None], axis=-1)
        # measured: 2.2 mm at most (one segment, the trunk's 16 markers)
        assert np.abs(d_true - d_model).max() < 5.0, (seg.name, np.abs(d_true - d_model).max())


def test_a_camera_dropping_out_and_a_sunlit_camera_are_flagged_not_mislabelled(
    folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    options = CentroidSimOptions(
        cameras=8, rate_hz=RATE_HZ, seed=1, truth=tmp_path / "t.npz",
        camera_off="3@0.2:0.3", sunlight="5@0.3:0.2",
    )  # fmt: skip
    driver = CentroidDriver(centroid_url_for(options), cameras=8, rate_hz=RATE_HZ)
    meta = {MODEL_KEY: MarkerModel.load(folder / "model.json").to_json()}
    with Session([driver], [Recorder(tmp_path / "r.spj", meta)], close_devices=True) as s:
        _run_frames(s, 0.7)
    out = tmp_path / "r.c3d"
    args = ["reconstruct", str(tmp_path / "r.spj"), "--calibration", str(folder / "rig.toml")]
    assert main([*args, "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    cameras = summary["camera_frames"]
    assert cameras["cam4"]["offline"] >= 20 and cameras["cam1"]["offline"] == 0
    assert cameras["cam6"]["overflow"] >= 10 and cameras["cam1"]["overflow"] == 0
    trial = read_c3d(out)
    truth = np.load(tmp_path / "t.npz")
    err = np.linalg.norm(
        trial.points - _truth_at(trial.first_frame, trial.n_frames, truth), axis=-1
    )
    reported = np.isfinite(err)
    decoded = reported.any(axis=1)  # frames lost on a busy machine are gaps
    # Measured with the lab's rig and model (6 runs): 100 % labelled, every one within
    # 1.8 mm, RMS 0.73-0.95 mm (the truth-learnt model and true rig: all within 5 mm).
    assert reported[decoded].mean() > 0.8
    assert (err[reported] < 5.0).mean() >= 0.99
