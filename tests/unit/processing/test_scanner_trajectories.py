"""Scanner 3-D: the unit's own against ours from the angles at their crossing instants."""

from __future__ import annotations

import math

import numpy as np
import pytest

from spotlab.drivers.coda import CodaDecoder
from spotlab.processing.scanner_trajectories import (
    COUNT_RAD,
    ScannerRecording,
    angles_at,
    scanner_points,
    scanner_trial,
)
from spotlab.reconstruction.scanner import scanner_precision
from spotlab.simulators import coda_scene as scene
from spotlab.simulators.clock import DeviceClock
from spotlab.simulators.coda import CodaConfig, CodaDevice, CodaFaults, CodaStream

M = 6
RATE = 300.0


@pytest.fixture(scope="module")
def recording() -> ScannerRecording:
    """1 000 scans of 6 markers (no faults, no occlusion), decoded by the driver's codec."""
    quiet = CodaFaults(colour=0.0, ghost=0.0, occlusion=0.0)
    device = CodaDevice(DeviceClock(epoch_ns=0), scene_markers=M, fault_rates=quiet, seed=3)
    stream = CodaStream(device, CodaConfig(300_000, 3, list(range(1, M + 1))), 0, 0)
    frames = b"".join(stream.encode(stream.take(), 0, 0x10) for _ in range(1000))
    block = CodaDecoder(tuple(range(1, M + 1)), "BOTH").feed(frames, 0)
    assert block.data.shape[0] == 1000
    return ScannerRecording(
        block.data[:, :M, 0, :], block.flags[:, :M, 0], block.ticks.astype(np.float64),
        RATE, 1000.0, [f"m{i}" for i in range(M)], "coda",
    )  # fmt: skip


def _truth(rec: ScannerRecording) -> np.ndarray:
    at_s = (rec.ticks_us + 0.4e6 / RATE) / 1e6
    return scene.marker_positions(np.arange(1, M + 1)[None, :], at_s[:, None])


def test_own_3d_beats_the_units_and_matches_the_precision_model(
    recording: ScannerRecording,
) -> None:
    truth = _truth(recording)
    ours = scanner_points(recording, "angles")
    device = scanner_points(recording, "device")
    err_ours = ours - truth
    err_dev = device - truth
    rms_ours = np.sqrt(np.nanmean(err_ours**2, axis=(0, 1)))
    rms_dev = np.sqrt(np.nanmean(err_dev**2, axis=(0, 1)))
    # The unit mixes three instants; carrying each angle to one instant removes that.
    assert rms_ours[1] < 0.6 * rms_dev[1]
    # Depth errors normalised by the precision model (angle noise of the simulated unit:
    # its noise at the range plus quantisation) have unit spread.
    r = np.linalg.norm(truth, axis=-1)
    sigma = COUNT_RAD * np.sqrt(scene.angle_sigma_counts(r, 0.0) ** 2 + 1 / 12)
    sd = scanner_precision(truth, 1.0, 1000.0)[0] * sigma[..., None]  # linear in sigma
    z = err_ours[..., 1] / sd[..., 1]
    assert np.nanstd(z) == pytest.approx(1.0, abs=0.1)
    assert abs(np.nanmean(z)) < 0.1


def test_depth_precision_grows_as_the_square_of_range() -> None:
    sd_near = scanner_precision(np.array([0.0, 2000.0, 0.0]), COUNT_RAD, 1000.0)[0][1]
    sd_far = scanner_precision(np.array([0.0, 6000.0, 0.0]), COUNT_RAD, 1000.0)[0][1]
    assert sd_far / sd_near == pytest.approx((36 + 0.25) / (4 + 0.25), rel=1e-9)


def test_angles_are_carried_to_one_instant() -> None:
    t = np.arange(20, dtype=np.float64)[:, None, None] * 1000 + np.array([100.0, 500.0, 900.0])
    a = 1e-6 * t  # angles changing at 1 µrad per µs
    at = np.arange(20, dtype=np.float64) * 1000 + 300
    out = angles_at(a, t, at)
    assert np.allclose(out, 1e-6 * at[:, None, None])


def test_trial_and_summary(recording: ScannerRecording) -> None:
    trial, summary = scanner_trial(recording)
    assert trial.points.shape == (1000, M, 3) and trial.point_rate == RATE
    sd = summary["markers"][0]["precision_sd_mm"]
    assert sd[1] > sd[0] and sd[1] == pytest.approx(
        math.sqrt(2) * COUNT_RAD * (3000**2 + 250**2) / 1000, rel=0.3
    )
