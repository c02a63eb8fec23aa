"""A rig calibrated from video-centroid recordings, as a lab with no ground truth does it:
``spotlab sim centroid`` waves a 3-marker wand, shows a static L-frame and walks a body
(three simulators, separate processes on real pseudo-terminals), ``spotlab record``
records each, ``spotlab calibrate`` finds the wand and the L-frame among the blobs and
calibrates the eight cameras from a cold start.

Only at the end is anything compared with the simulator's truth: the body markers of the
walk (data the calibration never saw), triangulated from their blobs with the calibrated
rig and with the simulator's own rig (``--rig-out``), against their true positions.
"""

from __future__ import annotations

import json
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from _e2e import _first_line as first_line
from _e2e import assert_one_clear_error, run_cli, spawn_cli, stop_process
from numpy.typing import NDArray

from spotlab.console.blob_trajectories import read_blob_recording
from spotlab.geometry import Rig
from spotlab.reconstruction import triangulate

CAMERAS, WAND_LENGTH_MM = 8, 500.0
WAND_S, FRAME_S, WALK_S = 15.0, 5.0, 2.0
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


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Lab:
    """One scene after the other (three simulators at once starve on a busy machine); the
    cameras stay put between them, each simulator has its own seed (its own trial)."""
    folder = tmp_path_factory.mktemp("centroid-calibrate")
    lab = Lab(
        folder, folder / "wand.spj", folder / "frame.spj", folder / "walk.spj",
        folder / "lframe.csv", folder / "true-rig.toml", folder / "walk-truth.npz",
    )  # fmt: skip
    _record(folder, lab.wand, WAND_S, 100, "--motion", "wand", "--seed", 1)
    _record(
        folder, lab.frame, FRAME_S, 200, "--motion", "lframe", "--seed", 2,
        "--frame-points-out", lab.frame_points,
    )  # fmt: skip
    # Scoring data: the walk's truth and the true rig are read only at the very end.
    _record(
        folder, lab.walk, WALK_S, 100, "--motion", "walk", "--seed", 3,
        "--truth", lab.walk_truth, "--rig-out", lab.true_rig,
    )  # fmt: skip
    return lab


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
    lab: Lab,
) -> None:
    out = lab.folder / "rig.toml"
    result = _calibrate(lab, out, "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
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

    # The end: held-out body markers, triangulated with both rigs, against the truth.
    uv, X = _walk_views(lab)
    rigs = {"calibrated": Rig.load(out), "true": Rig.load(lab.true_rig)}
    assert [c.name for c in rigs["calibrated"]] == [c.name for c in rigs["true"]]
    err = {k: np.linalg.norm(triangulate(rig, uv) - X, axis=-1) for k, rig in rigs.items()}
    both = np.isfinite(err["calibrated"]) & np.isfinite(err["true"])
    rms = {k: float(np.sqrt(np.mean(e[both] ** 2))) for k, e in err.items()}
    ratio = rms["calibrated"] / rms["true"]
    print(f"{both.sum()} body marker-frames: RMS {rms} mm, ratio {ratio:.4f}")
    assert both.sum() > 1000
    # The target is 5 % (docs/calibration.md). Measured through this test: 1.008, 1.009,
    # 1.015, 1.042; the same wand dance with other L-frame recordings 1.017-1.052. The
    # L-frame (600 x 400 mm) places the world frame: with 0.002-0.004 px of noise left in
    # its averaged images the body came out turned by 1.7-2.8e-5 rad and shifted by
    # 0.03-0.05 mm against the true rig's 0.21 mm error. The bound leaves room for that.
    assert ratio < 1.08


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
