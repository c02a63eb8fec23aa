"""The lab of the console's video-centroid tests, made the way a lab makes one (the
fixtures are in conftest.py): the rig ``spotlab calibrate`` makes of wand and L-frame
recordings of the in-process simulated hub (sim://centroid), and subject :data:`SUBJECT`'s
marker model from its static and range-of-motion recordings (``spotlab model init`` with
the ``spotlab-body`` template, then ``spotlab model learn``). Nothing here reads the
simulator's truth.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import spotlab.simulators  # noqa: F401  (registers sim://)
from spotlab.acquisition.recorder import Recorder
from spotlab.acquisition.session import Session
from spotlab.drivers.centroid import CentroidDriver
from spotlab.geometry import Rig
from spotlab.processing.blob_calibration_inputs import load_blob_recordings
from spotlab.processing.blob_trajectories import _frames, read_blob_recording
from spotlab.processing.recording_calibration import calibrate_observations
from spotlab.reconstruction.identification import MarkerModel, RigGeometry
from spotlab.reconstruction.identification.static_cloud import static_cloud
from spotlab.reconstruction.identification.subject_model import (
    first_model,
    label_trial,
    learn_model,
    subject_template,
)
from spotlab.reconstruction.identification.template import fit_template, load_template
from spotlab.simulators.centroid_service import CentroidSimOptions, centroid_url_for

#: xdist group of the modules that share these session recordings.
LAB_GROUP = "centroid-console-lab"
#: The wand's length between its end markers (mm): the simulator's default.
WAND_LENGTH_MM = 500.0
#: The subject (seed) whose model is learnt; its walk is recorded by the tests.
SUBJECT = 1
#: Recordings of the subject (s, at :data:`MODEL_RATE_HZ`): the static trial, and the
#: range of motion: 1 s standing, 1 s easing in, then 2 s stepping in place (1.6
#: strides). Measured with the walks of test_blob_reconstruct.py: every marker-frame of
#: 0.7 s labelled (with 1 s of stepping too), and after a restart of the stream all but
#: one foot's 3 markers labelled again within 0.33 s (with 1 s of stepping: neither foot).
STATIC_S, ROM_S, MODEL_RATE_HZ = 0.3, 4.0, 50


def record(
    out: Path, seconds: float, options: CentroidSimOptions, meta: dict[str, object] | None = None
) -> None:
    """Record ``seconds`` of the hub's frames (8 cameras, as ``options`` describes) into
    ``out``: counted in frames, since the in-process hub's clock falls behind the wall's on
    a busy machine (what a recording holds then stays the same)."""
    driver = CentroidDriver(centroid_url_for(options), cameras=8, rate_hz=options.rate_hz)
    wanted = round(seconds * options.rate_hz)
    recorder = Recorder(out, meta or {"command": "record"})
    with Session([driver], [recorder], close_devices=True) as session:
        deadline = time.monotonic() + 60.0
        while sum(session.status().frames.values()) < wanted and time.monotonic() < deadline:
            time.sleep(0.02)


@dataclass(frozen=True)
class SubjectLab:
    """The lab's rig and the subject's model, as files.

    Attributes
    ----------
    rig : Path
        The rig ``spotlab calibrate`` made of conftest.py's ``calibration_recordings`` (TOML).
    model : Path
        Subject :data:`SUBJECT`'s final marker model (``MarkerModel.save`` JSON).
    """

    rig: Path
    model: Path


def calibrated_rig(recordings: Path) -> Rig:
    """The rig ``spotlab calibrate wand.spj --wand-length 500 --frame-recording frame.spj
    --frame-points lframe.csv --distortion radial`` makes of the recordings in folder
    ``recordings`` (its report and figure left out).

    Radial lens terms (k1, k2) for every camera: with 1.5 s of wand the automatic choice
    of terms is on its threshold for cam6 (p1, p2 at 2.8 standard errors of the 3 asked
    for) and flips between recordings that start a few ms apart on the hub's clock,
    moving the walk's RMS from the truth from 0.85 to 1.55 mm; radial gave 0.73-0.86 mm,
    largest 1.5-1.8 mm, over 13 recordings.
    """
    found = load_blob_recordings(
        recordings / "wand.spj", recordings / "frame.spj", recordings / "lframe.csv",
        wand_length=WAND_LENGTH_MM,
    )  # fmt: skip
    calibrated = calibrate_observations(
        found.observations, WAND_LENGTH_MM, found, distortion="radial"
    )
    return calibrated.result.rig


def lab_model(static: Path, rom: Path, rig: Rig) -> MarkerModel:
    """A subject's final model, as ``spotlab model init --template spotlab-body`` then
    ``spotlab model learn`` make it: the template fitted to the static trial's cloud
    gives M0 and the subject's static pose; the ROM trial labelled with them gives the
    final model."""
    template = load_template("spotlab-body")
    frames = [frame for frame, _ in _frames(read_blob_recording(static).blobs)]
    cloud = static_cloud(frames, RigGeometry(rig))
    fit = fit_template(cloud.points, template)
    m0 = first_model(cloud.points, fit, template)
    start = subject_template(cloud.points, fit, template, m0)
    labelled, _ = label_trial(rig, _frames(read_blob_recording(rom).blobs), m0, start)
    return learn_model(m0, labelled)
