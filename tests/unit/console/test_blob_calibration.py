"""``spotlab calibrate`` of video-centroid recordings: the wand and the L-frame found in the
recordings of an in-process simulated hub (sim://centroid); every input that does not
match is one clear line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from _centroid_lab import LAB_GROUP

from spotlab.console.cli import main
from spotlab.console.errors import CommandError
from spotlab.geometry import Camera, Rig
from spotlab.processing.blob_calibration_inputs import load_blob_recordings
from spotlab.processing.calibration_inputs import WandObservations
from spotlab.processing.recording_calibration import check_scale as _check_scale
from spotlab.simulators.motions import reference_markers

# one worker makes the session recordings shared with the other hub tests (conftest.py)
pytestmark = pytest.mark.xdist_group(LAB_GROUP)


@pytest.fixture(scope="module")
def folder(calibration_recordings: Path) -> Path:
    """``wand.spj`` (1.5 s of a 3-marker wand), ``frame.spj`` (0.5 s of the L-frame),
    ``lframe.csv`` (its published points), ``rig.toml`` (the true rig, for scoring):
    conftest.py's :func:`calibration_recordings`."""
    return calibration_recordings


def _calibrate(folder: Path, *extra: str, capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    args = [
        "calibrate", str(folder / "wand.spj"), "--wand-length", "500",
        "--frame-recording", str(folder / "frame.spj"), "--frame-points",
        str(folder / "lframe.csv"), "--out", str(folder / "rig-out.toml"), *extra,
    ]  # fmt: skip
    code = main(args)
    return code, capsys.readouterr().err


def test_the_wand_and_the_frame_are_found_in_the_recordings(folder: Path) -> None:
    found = load_blob_recordings(
        folder / "wand.spj", folder / "frame.spj", folder / "lframe.csv", wand_length=500.0
    )
    assert found.markers == 3 and found.middle_ratio == pytest.approx(0.4, abs=0.01)
    assert list(found.observations.image_size) == [1280, 1024]
    w = found.wand
    F = w.ends.shape[0]
    assert F > 100 and (w.used + w.ambiguous + w.missing + w.unusable == F).all()
    assert (w.used > 0.9 * F).all(), w.used
    assert found.frame.status == ["found"] * 8
    # Scoring: the L-frame's image points against its true projection.
    truth = Rig.load(folder / "rig.toml")
    err = np.linalg.norm(
        found.observations.frame - truth.project(reference_markers(4).points), axis=-1
    )
    assert err.max() < 0.05, err  # 0.07 px noise averaged over about 50 images
    summary = found.summary()
    assert json.loads(json.dumps(summary)) == summary
    assert summary["cameras"][0]["wand_used"] == int(w.used[0])


@pytest.mark.parametrize(
    "extra, needles",
    [
        (("--wand-middle", "250"), ("does not match", "0.500", "the recording shows it at 0.")),
        (("--wand-middle", "600"), ("--wand-middle 600", "between the wand's ends")),
        (("--wand-markers", "1", "2"), ("--wand-markers", "geometry")),
        (("--image-size", "0", "10"), ("--image-size",)),
    ],
)
def test_input_that_does_not_match_is_one_clear_line(
    folder: Path,
    extra: tuple[str, ...],
    needles: tuple[str, ...],
    capsys: pytest.CaptureFixture[str],
) -> None:
    code, err = _calibrate(folder, *extra, capsys=capsys)
    lines = [line for line in err.splitlines() if line.startswith("spotlab: error:")]
    assert code != 0 and len(lines) == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    assert not (folder / "rig-out.toml").exists()


def test_a_moving_reference_object_is_one_clear_line(
    folder: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(
        ["calibrate", str(folder / "wand.spj"), "--wand-length", "500", "--frame-recording",
         str(folder / "wand.spj"), "--frame-points", str(folder / "lframe.csv"), "--out",
         str(folder / "rig-out.toml")]
    )  # fmt: skip
    err = capsys.readouterr().err
    assert code != 0 and err.count("spotlab: error:") == 1, err
    assert "told apart in 0 camera(s)" in err and "standing still" in err


def _scaled(rig: Rig, k: float) -> Rig:
    """The rig with every camera's position scaled by ``k`` about the origin."""
    return Rig([Camera(c.K, c.dist, c.R, k * c.t, c.size, name=c.name) for c in rig.cameras])


def test_a_wand_length_the_reference_object_does_not_confirm_is_refused(folder: Path) -> None:
    """A wand said to be 510 mm that is 500 mm scales the rig by 1.02: the L-frame, seen as
    it is, measures 102 % of its published size."""
    truth = Rig.load(folder / "rig.toml")
    points = reference_markers(4).points
    obs = WandObservations(
        np.zeros((1, 8, 2, 2)), truth.project(points), points, np.array([1280.0, 1024.0])
    )
    _check_scale(truth, obs, 500.0)  # the true rig: no complaint
    _check_scale(_scaled(truth, 1.004), obs, 500.0)  # within 0.5 %
    with pytest.raises(CommandError, match=r"measures 102\.0 % .* as if the wand were 500 mm"):
        _check_scale(_scaled(truth, 1.02), obs, 510.0)
