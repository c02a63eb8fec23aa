"""A lab with no ground truth, on video-centroid recordings: ``spotlab sim centroid``
waves a 3-marker wand, shows a static L-frame, and a subject the marker models never saw
(seed 5) stands still, moves every joint (range of motion) and walks (five simulators
one after the other, separate processes on real pseudo-terminals); ``spotlab record``
records each. ``spotlab calibrate`` finds the wand and the L-frame among the blobs and
calibrates the eight cameras from a cold start; ``spotlab model init`` labels the static
pose from the ``spotlab-body`` template, ``spotlab model learn`` learns the subject's
model from the range of motion, and ``spotlab reconstruct`` labels the walk into a C3D.

Only at the end is anything compared with the simulator's truth: the walk's markers
(data neither the calibration nor the models saw), triangulated from their blobs with
the calibrated rig and with the simulator's own rig (``--rig-out``), and the labelled
C3D against their true positions.
"""

from __future__ import annotations

import json
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from _e2e import _first_line as first_line
from _e2e import assert_one_clear_error, run_cli, spawn_cli, stop_process
from numpy.typing import NDArray

from spotlab.geometry import Rig
from spotlab.io import read_c3d
from spotlab.processing.blob_trajectories import read_blob_recording
from spotlab.reconstruction import rigid_fit, triangulate

# one worker runs this module, so its session recordings are made once (make test: --dist loadgroup)
pytestmark = pytest.mark.xdist_group("centroid-lab")

CAMERAS, WAND_LENGTH_MM = 8, 500.0
#: The wand dance as docs/calibration.md advises it: 20 s at 200 Hz (4000 images per
#: camera; 15 s at 100 Hz left the world frame's placement at the walk too uncertain).
WAND_S, WAND_HZ, FRAME_S, WALK_S = 20.0, 200, 5.0, 3.0
STATIC_S, ROM_S = 2.0, 6.0
#: The subject: a seed no model or template was made from.
SUBJECT = 5
#: Recordings that end without a reply to STOP: (test_e2e_centroid_reconstruct.py)
#: on a busy machine the simulator can fall behind at the end; what arrived is recorded.
ENDING = ("no reply to STOP", "device gone when the recording ended")
FloatArray = NDArray[np.float64]


@dataclass
class Lab:
    folder: Path
    wand: Path
    frame: Path
    walk: Path
    frame_points: Path
    true_rig: Path
    walk_truth: Path
    static: Path
    rom: Path


def _record(folder: Path, out: Path, seconds: float, rate: float, *sim_args: object) -> None:
    """``spotlab sim centroid`` of one scene, recorded by ``spotlab record``, then stopped."""
    name = out.stem
    sim_out, sim_err = folder / f"{name}-sim.stdout", folder / f"{name}-sim.stderr"
    sim = spawn_cli(
        ["sim", "centroid", "--pty", "--cameras", CAMERAS, "--rate", rate, *sim_args],
        sim_out, sim_err,
    )  # fmt: skip
    try:
        port = first_line(sim_out, sim, sim_err, timeout=30.0)
        result = run_cli(
            "record", "--device", f"centroid={port}", "--cameras", CAMERAS, "--rate", rate,
            "--seconds", seconds, "--out", out, timeout=60,
        )  # fmt: skip
        assert result.returncode == 0 or any(e in result.stderr for e in ENDING), result.stderr
    finally:
        stop_process(sim)


@pytest.fixture(scope="session")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Lab:
    """One scene after the other (three simulators at once starve on a busy machine); the
    cameras stay put between them, each simulator has its own seed (its own trial)."""
    folder = tmp_path_factory.mktemp("centroid-calibrate")
    lab = Lab(
        folder, folder / "wand.spj", folder / "frame.spj", folder / "walk.spj",
        folder / "lframe.csv", folder / "true-rig.toml", folder / "walk-truth.npz",
        folder / "static.spj", folder / "rom.spj",
    )  # fmt: skip
    _record(folder, lab.wand, WAND_S, WAND_HZ, "--motion", "wand", "--seed", 1)
    _record(
        folder, lab.frame, FRAME_S, 200, "--motion", "lframe", "--seed", 2,
        "--frame-points-out", lab.frame_points,
    )  # fmt: skip
    _record(folder, lab.static, STATIC_S, 100, "--motion", "static", "--seed", SUBJECT)
    _record(folder, lab.rom, ROM_S, 100, "--motion", "rom", "--seed", SUBJECT)
    # Scoring data: the walk's truth and the true rig are read only at the very end.
    _record(
        folder, lab.walk, WALK_S, 100, "--motion", "walk", "--seed", SUBJECT,
        "--truth", lab.walk_truth, "--rig-out", lab.true_rig,
    )  # fmt: skip
    return lab


@pytest.fixture(scope="session")
def calibrated(lab: Lab) -> tuple[Path, dict[str, object]]:
    """The rig ``spotlab calibrate`` makes of the wand and L-frame recordings, and its
    JSON report."""
    out = lab.folder / "rig.toml"
    result = _calibrate(lab, out, "--json")
    assert result.returncode == 0, result.stderr
    return out, json.loads(result.stdout)


def _calibrate(lab: Lab, out: Path, *extra: object) -> subprocess.CompletedProcess[str]:
    return run_cli(
        "calibrate", lab.wand, "--wand-length", WAND_LENGTH_MM, "--frame-recording", lab.frame,
        "--frame-points", lab.frame_points, "--out", out, *extra, timeout=90,
    )  # fmt: skip


def _walk_views(lab: Lab) -> tuple[FloatArray, FloatArray]:
    """Scoring only: the walk's marker blobs (C, F, M, 2) by the truth's labels, and the
    true markers (F, M, 3). A decoded frame is the truth row of the same hub tick; its
    blobs are in the truth's order (merged blobs, ghosts and noise left out)."""
    blobs = read_blob_recording(lab.walk).blobs
    truth = np.load(lab.walk_truth)
    C, F = blobs.n_cameras, blobs.n_frames
    row_of = {
        int(tick) % (1 << 32): r
        for r, (tick, sent) in enumerate(zip(truth["hub_tick_us"], truth["sent"], strict=True))
        if sent
    }
    M = truth["markers_mm"].shape[1]
    uv, X = np.full((C, F, M, 2), np.nan), np.full((F, M, 3), np.nan)
    offsets = truth["blob_offsets"]
    for f in range(F):
        r = row_of[int(blobs.ticks[f]) % (1 << 32)]
        X[f] = truth["markers_mm"][r]
        for c in range(C):
            lo, hi = int(offsets[r * C + c]), int(offsets[r * C + c + 1])
            own = truth["blob_kind"][lo:hi] == 0
            decoded = blobs.uv[blobs.slice(f, c)]
            assert decoded.shape[0] == hi - lo
            uv[c, f, truth["blob_marker"][lo:hi][own]] = decoded[own]
    return uv, X


@pytest.mark.timeout(180)
def test_a_rig_calibrated_from_centroid_recordings_triangulates_like_the_true_one(
    lab: Lab, calibrated: tuple[Path, dict[str, Any]]
) -> None:
    out, report = calibrated
    finder = report["finder"]
    assert finder["wand_markers"] == 3 and finder["image_size"] == [1280, 1024]
    assert abs(finder["middle_ratio"] - 0.4) < 0.01  # as the recording shows it
    decoded = read_blob_recording(lab.wand).blobs.n_frames
    print(f"wand: {decoded} frames, used per camera {[c['wand_used'] for c in finder['cameras']]}")
    for cam in finder["cameras"]:
        parts = ("wand_used", "wand_ambiguous", "wand_missing", "wand_unusable")
        assert sum(cam[k] for k in parts) == decoded, cam
        # Measured (seed 1, 1501 frames): 1471-1499 used per camera; the rest miss a
        # marker (merged or hidden), a few are ambiguous.
        assert cam["wand_used"] > 0.9 * decoded, cam
        assert cam["frame"] == "found", cam
    assert abs(report["wand"]["mean_mm"] - WAND_LENGTH_MM) < 0.1
    for cam in report["cameras"]:
        assert cam["reprojection_rms_px"] < 0.1, cam  # 0.07 px centroid noise

    for cam in report["cameras"]:
        # The L-frame's images, averaged over its recording, are far less noisy than the
        # wand's (measured 0.001-0.004 px); a blob taken for a marker that is not one
        # (a floor reflection) would leave pixels here.
        assert cam["frame_rms_px"] < 0.05, cam

    # The end: held-out body markers, triangulated with both rigs, against the truth.
    uv, X = _walk_views(lab)
    rigs = {"calibrated": Rig.load(out), "true": Rig.load(lab.true_rig)}
    assert [c.name for c in rigs["calibrated"]] == [c.name for c in rigs["true"]]
    P = {k: triangulate(rig, uv) for k, rig in rigs.items()}
    both = np.isfinite(P["calibrated"]).all(-1) & np.isfinite(P["true"]).all(-1)
    assert both.sum() > 1000
    # The target (issue 11) is in the world frame itself, what a lab gets: the raw
    # ratio. Apart, for the diagnosis: the rig's own geometry (the calibrated points
    # after the one rigid motion that best lays them on the truth) and where the wand
    # and the L-frame put the world (that rigid motion itself).
    Rs, ts, _ = rigid_fit(P["calibrated"][both], X[both][None])  # X ≈ P R^T + t
    R, t = Rs[0], ts[0]
    err = {
        "raw": np.linalg.norm(P["calibrated"][both] - X[both], axis=-1),
        "aligned": np.linalg.norm(P["calibrated"][both] @ R.T + t - X[both], axis=-1),
        "true": np.linalg.norm(P["true"][both] - X[both], axis=-1),
    }
    rms = {k: float(np.sqrt(np.mean(e**2))) for k, e in err.items()}
    raw, aligned = rms["raw"] / rms["true"], rms["aligned"] / rms["true"]
    angle = float(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0)))
    centre = X[both].mean(axis=0)
    shift = float(np.linalg.norm(centre @ R.T + t - centre))
    print(f"{both.sum()} body marker-frames: RMS {rms} mm, raw ratio {raw:.4f}, aligned "
          f"{aligned:.4f}; world frame turned {angle:.2e} rad, shifted {shift:.3f} mm at the "
          "markers' centre")  # fmt: skip
    # Target 1.05 (issue 11, docs/calibration.md). Measured through this test, five runs
    # alone on the machine (2026-11-25): raw 1.0020-1.0285, aligned 0.997-1.002, turned
    # 0.9-2.3e-5 rad, shifted 0.015-0.040 mm (the true rig's own error is 0.2 mm); in
    # process on 20 scenes of other seeds (benchmarks/centroid_calibration.py) raw
    # 1.003-1.043, aligned <= 1.012, shifted <= 0.053 mm.
    assert raw < 1.05
    assert aligned < 1.03 and angle < 1e-4 and shift < 0.1


@pytest.mark.timeout(180)
def test_a_wand_that_does_not_match_the_recordings_is_one_clear_error(lab: Lab) -> None:
    # (A wand length that the L-frame's size does not confirm needs a whole adjustment
    # to show: tests/unit/console/test_blob_calibration.py, and docs/calibration.md.)
    out = lab.folder / "bad.toml"
    middle = _calibrate(lab, out, "--wand-middle", 250)
    assert_one_clear_error(middle, "does not match", "--wand-middle 250", "shows it at 0.")
    moving = run_cli(
        "calibrate", lab.wand, "--wand-length", WAND_LENGTH_MM, "--frame-recording", lab.wand,
        "--frame-points", lab.frame_points, "--out", out,
    )  # fmt: skip
    assert_one_clear_error(moving, "told apart in 0 camera(s)", "standing still")
    assert not out.exists()


@pytest.mark.timeout(240)
def test_a_new_subject_is_labelled_from_a_template_through_to_c3d(
    lab: Lab, calibrated: tuple[Path, dict[str, Any]]
) -> None:
    rig, _ = calibrated
    m0, model, c3d = lab.folder / "m0.json", lab.folder / "model.json", lab.folder / "walk.c3d"
    init = run_cli(
        "model", "init", lab.static, "--template", "spotlab-body", "--calibration", rig,
        "--out", m0, timeout=120,
    )  # fmt: skip
    assert init.returncode == 0, init.stderr
    print(init.stdout)
    learn = run_cli(
        "model", "learn", lab.rom, "--model", m0, "--calibration", rig, "--out", model,
        timeout=120,
    )  # fmt: skip
    assert learn.returncode == 0, learn.stderr
    print(learn.stdout)
    rec = run_cli(
        "reconstruct", lab.walk, "--calibration", rig, "--model", model, "--out", c3d,
        "--json", timeout=120,
    )  # fmt: skip
    assert rec.returncode == 0, rec.stderr

    # The end: the labelled C3D against the walk's truth (hub frame first_frame - 1 + i).
    trial, truth = read_c3d(c3d), np.load(lab.walk_truth)
    assert trial.labels == [str(x) for x in truth["labels"]]
    row = {int(f): k for k, f in enumerate(truth["frame_no"])}
    X = np.asarray(
        truth["markers_mm"][[row[trial.first_frame - 1 + i] for i in range(trial.n_frames)]]
    )
    # Each reported marker-frame is right when within 10 mm of its own marker, wrong when
    # nearer another marker's true place than 10 mm.
    err = np.linalg.norm(trial.points - X, axis=-1)
    reported = np.isfinite(err)
    right = reported & (err < 10.0)
    others = np.linalg.norm(trial.points[:, :, None] - X[:, None], axis=-1)
    m = np.arange(X.shape[1])
    others[:, m, m] = np.inf
    wrong = reported & ~right & (np.nanmin(others, axis=2) < 10.0)
    decoded = reported.any(axis=1)
    score = {
        "right_of_reported": right.sum() / reported.sum(),
        "wrong_of_reported": wrong.sum() / reported.sum(),
        "coverage": right[decoded].mean(),
    }
    names = [str(x) for x in truth["labels"]]
    print(f"walk of subject {SUBJECT}: {decoded.sum()} frames, {score}")
    print("wrong:", {names[m]: int(n) for m, n in enumerate(wrong.sum(axis=0)) if n})
    print("least covered:", {names[m]: round(float(right[decoded][:, m].mean()), 3)
                             for m in np.argsort(right[decoded].mean(axis=0))[:5]})  # fmt: skip
    # Targets (issue 11): >= 99.5 % right, <= 0.05 % wrong, >= 97 % coverage. Forward
    # only (as live labelling does), this test measured 94.9-98.1 % coverage: a foot or a
    # wrist unlabelled until its cluster is recognised, sooner or later with the walk's
    # window. reconstruct labels backward too; in process on 22 windows of the walks of
    # subjects 5 and 6 (docs/identification.md) that gave 99.91-100 %, 0 wrong.
    assert score["wrong_of_reported"] <= 0.0005 and score["right_of_reported"] >= 0.995
    assert score["coverage"] >= 0.99 and decoded.sum() >= 0.8 * WALK_S * 100


@pytest.mark.timeout(180)
def test_a_walk_is_no_static_pose_for_the_template(
    lab: Lab, calibrated: tuple[Path, dict[str, Any]]
) -> None:
    rig, _ = calibrated
    result = run_cli(
        "model", "init", lab.walk, "--template", "spotlab-body", "--calibration", rig,
        "--out", lab.folder / "never.json", timeout=120,
    )  # fmt: skip
    assert_one_clear_error(result, "static")
    assert not (lab.folder / "never.json").exists()
