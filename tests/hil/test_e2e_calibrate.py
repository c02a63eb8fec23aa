"""``spotlab calibrate`` from recordings: a wand dance and a static L-frame, recorded from
two simulated 4-camera PSD systems through real pseudo-terminals, calibrated by the real
command line and compared with the simulator's own cameras (``spotlab sim --rig-out``).

The simulated floor reflects nothing here (``--reflectance 0``): a PSD reports the
centroid of all the light on it, so a reflecting floor biases every wand reading towards
the LED's mirror image and the calibration with it (docs/simulators.md).
"""

from __future__ import annotations

import json
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from _e2e import assert_one_clear_error, record_args, run_cli, sim_pty, spawn_cli, stop_process

from spotlab.geometry import Rig

CAMERAS, RATE_HZ = 4, 100.0
WAND_SECONDS, FRAME_SECONDS = 8.0, 1.0
WAND_LENGTH_MM = 500.0
#: The L-frame of the simulator's ``lframe`` motion (markers 1-4), mm.
L_FRAME = [(0, 0, 10), (200, 0, 10), (600, 0, 10), (0, 400, 10)]


@dataclass
class Recordings:
    folder: Path
    wand: Path
    frame: Path
    frame_points: Path
    truth: Path


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> Recordings:
    """A wand dance (markers 1, 2) and a static L-frame (markers 1-4), recorded at once."""
    folder = tmp_path_factory.mktemp("calibrate")
    rec = Recordings(
        folder,
        folder / "wand.spj",
        folder / "frame.spj",
        folder / "lframe.csv",
        folder / "truth.toml",
    )
    rec.frame_points.write_text("X,Y,Z\n" + "".join(f"{x},{y},{z}\n" for x, y, z in L_FRAME))
    common = ["--reflectance", 0]
    wand_sim = sim_pty(
        folder,
        cameras=CAMERAS,
        leds=2,
        rate=RATE_HZ,
        seed=1,
        name="wand",
        extra=[*common, "--motion", "wand", "--rig-out", rec.truth],
    )
    frame_sim = sim_pty(
        folder,
        cameras=CAMERAS,
        leds=4,
        rate=RATE_HZ,
        seed=1,
        name="frame",
        extra=[*common, "--motion", "lframe"],
    )
    with wand_sim as wand, frame_sim as frame:
        # The static recording runs beside the wand dance: the test waits for one only.
        frame_rec = spawn_cli(
            record_args(
                frame.path, rec.frame, FRAME_SECONDS, cameras=CAMERAS, leds=4, rate=RATE_HZ
            ),
            folder / "frame-record.stdout",
            folder / "frame-record.stderr",
        )
        try:
            result = run_cli(
                *record_args(
                    wand.path, rec.wand, WAND_SECONDS, cameras=CAMERAS, leds=2, rate=RATE_HZ
                ),
                timeout=60,
            )
            assert result.returncode == 0, result.stderr
            assert frame_rec.wait(timeout=30) == 0, (folder / "frame-record.stderr").read_text()
        finally:
            stop_process(frame_rec)
    return rec


def _calibrate(
    rec: Recordings,
    *extra: object,
    wand_markers: tuple[int, ...] = (1, 2),
    frame: Path | None = None,
    frame_markers: tuple[int, ...] = (1, 2, 3, 4),
    frame_points: Path | None = None,
) -> subprocess.CompletedProcess[str]:
    """``spotlab calibrate`` of the recordings (each input may be replaced)."""
    return run_cli(
        "calibrate",
        rec.wand,
        "--wand-markers",
        *wand_markers,
        "--frame-recording",
        frame or rec.frame,
        "--frame-markers",
        *frame_markers,
        "--frame-points",
        frame_points or rec.frame_points,
        "--wand-length",
        WAND_LENGTH_MM,
        *extra,
        timeout=60,
    )


def test_calibration_from_recordings_finds_the_simulated_cameras(recordings: Recordings) -> None:
    out = recordings.folder / "rig.toml"
    result = _calibrate(recordings, "--out", out, "--json")
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    report = json.loads(result.stdout)
    assert report["calibration"] == str(out)
    saved = json.loads(out.with_suffix(".report.json").read_text())
    assert saved["wand"] == report["wand"]
    assert out.with_suffix(".report.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    rig, truth = Rig.load(out), Rig.load(recordings.truth)
    assert len(rig) == len(truth) == CAMERAS
    pairs = list(zip(rig, truth, strict=True))
    centre_mm = np.array([np.linalg.norm(a.center - b.center) for a, b in pairs])
    focal = np.array([[a.K[0, 0] / b.K[0, 0], a.K[1, 1] / b.K[1, 1]] for a, b in pairs])
    principal = np.array([a.K[:2, 2] - b.K[:2, 2] for a, b in pairs])
    print(f"centre errors {np.round(centre_mm, 1)} mm, focal ratio {np.round(focal, 4)}")
    print(f"principal point offsets {np.round(principal, 1)} counts")
    # Measured through this pipeline, 8 s at 100 Hz: seed 1 4.8-7.0 mm; seeds 0-4, worst
    # camera of each, 7-25 mm, median 7 mm, focal length within 0.7 %. PSD noise of about
    # 2 counts per reading (1 count is 1.1 mm at 4 m) and a wand that sweeps only 10 % of
    # each detector in 8 s leave focal length and distance correlated: that is the error
    # (noise-free readings give 1-3 mm), not the camera model (docs/calibration.md).
    assert np.median(centre_mm) < 15.0 and centre_mm.max() < 30.0, centre_mm
    assert np.all(np.abs(focal - 1.0) < 0.01), focal
    assert np.all(np.abs(principal) < 60.0), principal
    # Wand dance: every recorded frame used, the length recovered, residuals at the noise.
    frames = report["wand"]["frames"]
    assert abs(frames - WAND_SECONDS * RATE_HZ) <= 0.02 * WAND_SECONDS * RATE_HZ
    assert abs(report["wand"]["mean_mm"] - WAND_LENGTH_MM) < 0.5
    assert report["wand"]["sd_mm"] < 3.0
    for cam in report["cameras"]:
        assert 0.8 < cam["reprojection_rms_px"] < 2.5, cam
        assert cam["rejected"] < 0.05 * cam["observations"], cam


def test_recording_errors_are_one_clear_line(recordings: Recordings) -> None:
    out = recordings.folder / "bad.toml"
    two = recordings.folder / "two.csv"
    two.write_text("X,Y,Z\n0,0,10\n200,0,10\n")
    # The wand's ends as the reference object: they move.
    moving = _calibrate(
        recordings, "--out", out, frame=recordings.wand, frame_markers=(1, 2), frame_points=two
    )
    assert_one_clear_error(moving, "marker", "moves", "stand still")
    beyond = _calibrate(recordings, "--out", out, wand_markers=(1, 3))
    assert_one_clear_error(beyond, "--wand-markers", "[3]", "1..2")
    rows = _calibrate(recordings, "--out", out, frame_markers=(1, 2, 3))
    assert_one_clear_error(rows, "4 rows for 3 frame markers")
    assert not out.exists()
