"""Scoring a WSX reconstruction against the simulator's truth (tests and benches only).

The truth file of ``spotlab sim wsx --truth T.npz`` holds every frame's true marker
positions at its start and the true calibration of every CCD. The noise floor is
the error of the same reconstruction with the true calibration on the same
readings; a recording's factory calibration should match it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spotlab.processing.linear_trajectories import LinearRecording, linear_points
from spotlab.reconstruction.linear_sensors import LinearSensorCalibration
from spotlab.reconstruction.rigid import rigid_pose


@dataclass(frozen=True)
class WsxScore:
    """3-D RMS errors (mm) over the frames both have, and how many."""

    rms_recorded: float
    rms_true_calibration: float
    frames: int
    points: int

    @property
    def ratio(self) -> float:
        """Recorded-calibration error over the noise floor."""
        return self.rms_recorded / self.rms_true_calibration


def score_recording(rec: LinearRecording, truth_path: Path) -> WsxScore:
    """Compare ``rec`` (one collection, frame numbers = truth's) with the truth."""
    truth = np.load(truth_path)
    true_cal = LinearSensorCalibration(
        truth["R"], truth["t"], truth["focal"], truth["principal"], truth["axis"]
    )
    frame_no = np.arange(rec.readings.shape[0]) + rec.first_seq
    first = truth["collection"] == truth["collection"].min()
    index = {int(k): i for i, k in enumerate(truth["frame_no"][first])}
    rows = np.array([index.get(int(k), -1) for k in frame_no])
    have = rows >= 0
    expect = truth["points"][first][rows[have]]
    got, _ = linear_points(rec)
    floor, _ = linear_points(
        LinearRecording(
            rec.readings, rec.fire_ns, rec.start_ns, rec.rate_hz, true_cal, rec.interpolate,
            rec.stream, rec.first_seq,
        )
    )  # fmt: skip
    both = np.isfinite(got[have]).all(-1) & np.isfinite(floor[have]).all(-1)
    got = got[have]
    if rec.registration_rms is not None:  # in the first sensor's frame: align to the truth's
        pose = rigid_pose(got[both], expect[both][None])
        got = np.einsum("ij,...j->...i", pose.R[0], got) + pose.t[0]
    e1 = np.linalg.norm(got - expect, axis=-1)[both]
    e0 = np.linalg.norm(floor[have] - expect, axis=-1)[both]
    return WsxScore(
        float(np.sqrt(np.mean(e1**2))), float(np.sqrt(np.mean(e0**2))),
        int(have.sum()), int(both.sum()),
    )  # fmt: skip
