"""The entry points of ``spotlab.processing``, called step by step from a script, give
what ``spotlab export`` writes for the same recording.

Two short recordings of in-process simulators (``sim://``): one SELSPOT-style device
alone (reconstructed by frame number) and two devices with a timer (on session times).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import spotlab.simulators  # noqa: F401  (registers sim://)
from spotlab import processing
from spotlab.acquisition.recorder import Recorder
from spotlab.acquisition.session import Session
from spotlab.console.cli import main
from spotlab.drivers.selspot import SelspotDriver
from spotlab.io import read_c3d


@pytest.fixture(scope="module")
def one_device(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``run.spj``: 0.4 s of a 3-camera x 6-LED system; ``rig.toml``: its true rig."""
    path = tmp_path_factory.mktemp("one_device")
    url = (
        f"sim://selspot?cameras=3&leds=6&rate=100&reflectance=0&seed=3&rig_out={path / 'rig.toml'}"
    )
    driver = SelspotDriver(url, cameras=3, leds=6, rate_hz=100)
    with Session([driver], [Recorder(path / "run.spj")], close_devices=True) as session:
        session.run_for(0.4)
    return path


@pytest.fixture(scope="module")
def with_timer(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``run.spj``: 0.6 s of a 3-camera x 6-LED system and a timer; ``rig.toml``."""
    path = tmp_path_factory.mktemp("with_timer")
    device = (
        f"selspot=sim://selspot?seed=3&cameras=3&leds=6&rig_out={path / 'rig.toml'}"
        ",cameras=3,leds=6"
    )
    argv = ["record", "--device", device, "--device", "timer=sim://timer"]
    assert main([*argv, "--seconds", "0.6", "--out", str(path / "run.spj"), "--json"]) == 0
    return path


def _export(folder: Path, out: Path, capsys: pytest.CaptureFixture[str]) -> dict[str, object]:
    """``spotlab export run.spj --calibration rig.toml --c3d OUT --json``: its summary."""
    capsys.readouterr()
    args = ["export", str(folder / "run.spj"), "--calibration", str(folder / "rig.toml")]
    assert main([*args, "--c3d", str(out), "--json"]) == 0
    summary: dict[str, object] = json.loads(capsys.readouterr().out)
    return summary


def test_one_device_step_by_step_is_what_export_writes(
    one_device: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cli = tmp_path / "cli.c3d"
    summary = _export(one_device, cli, capsys)
    # Steps 2 and 3: observations of the one stream, triangulated with the rig.
    rig = processing.load_rig(one_device / "rig.toml")
    obs = processing.load_observations(one_device / "run.spj")
    assert obs.uv.shape[1:] == (3, 6, 2) and obs.rate_hz == 100.0
    result = processing.reconstruct(rig, obs)
    exported = read_c3d(cli)
    assert result.trial.labels == exported.labels
    assert result.trial.point_rate == exported.point_rate
    assert np.allclose(result.trial.points, exported.points, atol=1e-3, equal_nan=True)
    # Steps 1 to 4 in one call, then step 5: the same file, byte for byte.
    whole = processing.reconstruct_recording(one_device / "run.spj", one_device / "rig.toml")
    assert whole.notes == [f"note: {processing.synchronised_export.NO_TIMER_NOTE}"]
    assert {**whole.summary, "outputs": [str(cli)]} == summary
    mine = tmp_path / "mine.c3d"
    processing.write_trial(mine, whole.trial)
    assert mine.read_bytes() == cli.read_bytes()


def test_with_a_timer_step_by_step_is_what_export_writes(
    with_timer: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cli = tmp_path / "cli.c3d"
    summary = _export(with_timer, cli, capsys)
    # Step 1: every stream on session time; the one image2d stream kept.
    opened = processing.open_recording(with_timer / "run.spj")
    assert [s.name for s in opened.streams] == ["selspot"]
    assert opened.timebase.reference == "timer"
    # Step 2: its readings at common session instants; step 3: triangulated.
    obs = processing.synchronise_observations(opened.streams)
    assert obs.uv.shape[1:] == (3, 6, 2) and obs.rate_hz == opened.streams[0].spec.rate_hz
    rig = processing.load_rig(with_timer / "rig.toml")
    result = processing.reconstruct(rig, processing.MarkerObservations(obs.uv, obs.rate_hz))
    exported = read_c3d(cli)
    assert exported.first_frame == obs.first_frame
    assert np.allclose(result.trial.points, exported.points, atol=1e-3, equal_nan=True)
    # Steps 1 to 4 in one call, then step 5: the same file, byte for byte.
    whole = processing.reconstruct_recording(with_timer / "run.spj", with_timer / "rig.toml")
    assert {**whole.summary, "outputs": [str(cli)]} == summary
    mine = tmp_path / "mine.c3d"
    processing.write_trial(mine, whole.trial)
    assert mine.read_bytes() == cli.read_bytes()
