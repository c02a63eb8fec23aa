"""Observations from SELSPOT-style recordings (``load_recordings``): what is read, what is
dropped, and every refused input named."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import spotlab.simulators  # noqa: F401  (registers sim://)
from spotlab.acquisition.recorder import Recorder
from spotlab.acquisition.session import Session
from spotlab.console.errors import CommandError
from spotlab.drivers.selspot import SelspotDriver
from spotlab.processing import calibration_inputs
from spotlab.processing.calibration_inputs import load_recordings

URL = "sim://selspot?cameras=2&leds=6&reflectance=0"


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``wand.spj`` (0.3 s of the wand motion: wand = markers 1, 2, L-frame = 3-6),
    ``empty.spj`` (a stream declared, no frame), ``two.spj`` (two devices), ``lframe.csv``."""
    path = tmp_path_factory.mktemp("recordings")
    driver = SelspotDriver(URL, cameras=2, leds=6, rate_hz=100)
    with Session([driver], [Recorder(path / "wand.spj")], close_devices=True) as session:
        session.run_for(0.3)
    idle = SelspotDriver(URL, cameras=2, leds=6, rate_hz=100)
    with Recorder(path / "empty.spj") as recorder:
        recorder.attach([idle])
        recorder.on_start([idle])
    pair = [SelspotDriver(URL, cameras=2, leds=6, rate_hz=100, name=n) for n in ("a", "b")]
    with Session(pair, [Recorder(path / "two.spj")], close_devices=True) as session:
        session.run_for(0.05)
    (path / "lframe.csv").write_text("X,Y,Z\n0,0,10\n200,0,10\n600,0,10\n0,400,10\n")
    return path


def test_wand_and_averaged_l_frame_in_detector_counts(folder: Path) -> None:
    rec = folder / "wand.spj"
    obs = load_recordings(rec, [1, 2], rec, [3, 4, 5, 6], folder / "lframe.csv")
    F = obs.wand.shape[0]
    assert obs.wand.shape == (F, 2, 2, 2) and F >= 20
    assert obs.frame.shape == (2, 4, 2)
    assert np.array_equal(obs.image_size, [4096, 4096])
    assert np.array_equal(obs.frame_points[1], [200, 0, 10])
    assert np.isfinite(obs.wand).all() and np.isfinite(obs.frame).all()
    assert ((obs.wand > 0) & (obs.wand < 4094)).all()
    # Each wand end moves; the L-frame is the mean of what each camera read.
    assert np.ptp(obs.wand[:, 0, 0, 0]) > 5.0
    static = load_recordings(rec, [3, 4], rec, [3, 4, 5, 6], folder / "lframe.csv").wand
    assert np.allclose(obs.frame[:, :2], static.mean(axis=0))


def test_saturated_and_clipped_readings_are_dropped(
    folder: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    F, M, C = 30, 3, 2
    rng = np.random.default_rng(0)
    data = np.empty((F, M, C, 3))
    data[..., :2] = 2000.0 + rng.normal(0.0, 2.0, (F, M, C, 2))
    data[..., 2] = 80.0
    flags = np.ones((F, M, C), dtype=np.uint8)
    data[0, 0, 0, 0] = 0.0  # clipped at the left edge
    data[1, 1, 1, 1] = 4094.0  # clipped at the bottom
    flags[2, 2, 0] |= 0x02  # saturated
    data[3, 2, 1, :2] = np.nan  # not seen (the decoder's NaN)
    monkeypatch.setattr(calibration_inputs, "_selspot_readings", lambda path: (data, flags))
    points = folder / "three.csv"
    points.write_text("X,Y,Z\n0,0,0\n1,0,0\n0,1,0\n")
    obs = load_recordings(folder / "x.spj", [1, 2], folder / "x.spj", [1, 2, 3], points)
    assert np.isnan(obs.wand[0, 0, 0]).all() and np.isnan(obs.wand[1, 1, 1]).all()
    assert np.isfinite(obs.wand).all(axis=-1).sum() == F * C * 2 - 2
    kept = np.ones(F, dtype=bool)
    kept[2] = False
    assert np.allclose(obs.frame[0, 2], data[kept, 2, 0, :2].mean(axis=0))
    assert np.allclose(obs.frame[1, 2], np.delete(data[:, 2, 1, :2], 3, axis=0).mean(axis=0))
    assert np.allclose(obs.frame[0, 0], data[1:, 0, 0, :2].mean(axis=0))


def test_a_camera_that_never_sees_a_reference_marker_gives_nan_without_a_warning(
    folder: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    data = np.full((5, 2, 2, 3), 2000.0)
    data[:, 1, 0, :2] = np.nan
    flags = np.ones((5, 2, 2), dtype=np.uint8)
    monkeypatch.setattr(calibration_inputs, "_selspot_readings", lambda path: (data, flags))
    points = folder / "pair.csv"
    points.write_text("X,Y,Z\n0,0,0\n1,0,0\n")
    obs = load_recordings(folder / "x.spj", [1, 2], folder / "x.spj", [1, 2], points)
    assert np.isnan(obs.frame[0, 1]).all()
    assert np.array_equal(obs.frame[1], [[2000, 2000], [2000, 2000]])


@pytest.mark.parametrize(
    ("wand", "frame", "frame_markers", "points", "message"),
    [
        ("wand.spj", "wand.spj", [3, 4, 5, 7], "lframe.csv", "marker(s) [7] not in"),
        ("wand.spj", "wand.spj", [3, 4, 5, 0], "lframe.csv", "(it has markers 1..6)"),
        ("empty.spj", "wand.spj", [3, 4, 5, 6], "lframe.csv", "holds no frames"),
        ("wand.spj", "empty.spj", [3, 4, 5, 6], "lframe.csv", "empty.spj: the recording holds no"),
        ("two.spj", "wand.spj", [3, 4, 5, 6], "lframe.csv", "2 streams (a, b)"),
        ("wand.spj", "wand.spj", [3, 4, 5], "lframe.csv", "4 rows for 3 frame markers"),
        ("wand.spj", "wand.spj", [3, 4, 5, 6], "gap.csv", "row 3 lacks a coordinate"),
        ("wand.spj", "wand.spj", [3, 4, 5, 5], "lframe.csv", "named twice"),
        ("wand.spj", "wand.spj", [1, 4, 5, 6], "lframe.csv", "marker 1 moves in camera"),
    ],
)
def test_refused_recording_input_is_named(
    folder: Path, wand: str, frame: str, frame_markers: list[int], points: str, message: str
) -> None:
    (folder / "gap.csv").write_text("X,Y,Z\n0,0,10\n200,,10\n600,0,10\n0,400,10\n")
    with pytest.raises(CommandError) as info:
        load_recordings(folder / wand, [1, 2], folder / frame, frame_markers, folder / points)
    assert message in str(info.value)


def test_the_wand_takes_two_distinct_markers(folder: Path) -> None:
    rec, csv = folder / "wand.spj", folder / "lframe.csv"
    with pytest.raises(CommandError, match="two marker numbers"):
        load_recordings(rec, [1, 2, 3], rec, [3, 4, 5, 6], csv)
    with pytest.raises(CommandError, match="--wand-markers: a marker is named twice"):
        load_recordings(rec, [1, 1], rec, [3, 4, 5, 6], csv)
