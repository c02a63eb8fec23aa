"""Markers from calibrated linear CCDs, and position sensors calibrated each in its own
frame registered with the markers they share (the simulated hub's geometry)."""

from __future__ import annotations

import numpy as np
import pytest

from spotlab.core.errors import ReconstructionError
from spotlab.drivers.wsx.protocol import parse_calibration
from spotlab.reconstruction.linear_sensors import (
    LinearSensorCalibration,
    markers_from_readings,
    register_sensors,
)
from spotlab.reconstruction.rigid import rigid_pose
from spotlab.simulators.wsx_scene import WsxScene


def _scene_and_readings(noise: float) -> tuple[WsxScene, np.ndarray, np.ndarray]:
    scene = WsxScene(3, 6, seed=5)
    truth = scene.positions(np.linspace(0.0, 8.0, 400))
    r, _ = scene.ideal(truth)
    r = r + np.random.default_rng(1).normal(0.0, noise, r.shape)
    return scene, truth, r


def _calibration(scene: WsxScene, registered: bool) -> LinearSensorCalibration:
    records = [
        ccd
        for s in range(scene.n_sensors)
        for ccd in parse_calibration(scene.calibration_record(s, registered), s)
    ]
    assert {r["frame"] for r in records} == {"device" if registered else "sensor"}
    return LinearSensorCalibration.from_records(records)


def test_exact_readings_give_the_markers() -> None:
    scene, truth, r = _scene_and_readings(0.0)
    fit = markers_from_readings(r, _calibration(scene, True))
    assert np.abs(fit.points - truth).max() < 0.01  # float32 calibration
    missing = r.copy()
    missing[:, :, :3] = np.nan  # one sensor gone: the other two still fix every marker
    assert (
        np.abs(markers_from_readings(missing, _calibration(scene, True)).points - truth).max()
        < 0.01
    )


def test_sensors_in_their_own_frames_are_registered() -> None:
    scene, truth, r = _scene_and_readings(0.02)
    reg = register_sensors(r, _calibration(scene, False))
    assert reg.rms[0] == 0.0 and all(0.0 < v < 1.0 for v in reg.rms[1:])
    got = markers_from_readings(r, reg.calibration).points
    pose = rigid_pose(got.reshape(-1, 3), truth.reshape(1, -1, 3))  # sensor 0's frame -> world
    aligned = got @ pose.R[0].T + pose.t[0]
    floor = markers_from_readings(r, _calibration(scene, True)).points
    err = np.sqrt(np.mean(np.sum((aligned - truth) ** 2, axis=-1)))
    err0 = np.sqrt(np.mean(np.sum((floor - truth) ** 2, axis=-1)))
    assert err < 1.05 * err0


def test_a_sensor_that_shares_nothing_cannot_be_registered() -> None:
    scene, _, r = _scene_and_readings(0.0)
    r[..., 6:] = np.nan
    with pytest.raises(ReconstructionError, match="position sensor 2 shares 0 marker samples"):
        register_sensors(r, _calibration(scene, False))
