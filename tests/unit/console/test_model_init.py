"""``spotlab model init STATIC.spj`` and ``spotlab model learn ROM.spj``: recordings of an
in-process simulated hub (sim://centroid --motion static / rom, subject 8) -> M0 -> the
final model; every bad input as one clear line. The truth scores only at the end."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

import spotlab.simulators  # noqa: F401  (registers sim://)
from spotlab.acquisition.recorder import Recorder
from spotlab.acquisition.session import Session
from spotlab.console.commands.model_init import (
    STATIC_KEY,
    add_init_parser,
    run_learn_recording,
)
from spotlab.console.errors import CommandError
from spotlab.drivers.centroid import CentroidDriver
from spotlab.reconstruction.identification import MarkerModel
from spotlab.simulators.centroid_service import CentroidSimOptions, centroid_url_for

SEED, RATE_HZ = 8, 100


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``static.spj`` (1 s), ``rom.spj`` (4 s), ``walk.spj`` (0.5 s), ``rig.toml``."""
    path = tmp_path_factory.mktemp("subject")
    for name, motion, seconds in (("static", "static", 1.0), ("rom", "rom", 4.0),
                                  ("walk", "walk", 0.5)):  # fmt: skip
        options = CentroidSimOptions(
            rate_hz=RATE_HZ, seed=SEED, motion=motion, truth=path / f"{name}.npz",
            rig_out=path / "rig.toml",
        )  # fmt: skip
        driver = CentroidDriver(centroid_url_for(options), cameras=8, rate_hz=RATE_HZ)
        with Session([driver], [Recorder(path / f"{name}.spj", {"command": "record"})],
                     close_devices=True) as session:  # fmt: skip
            session.run_for(seconds)
    return path


def _init(
    folder: Path, out: Path, source: str = "static.spj", template: str = "spotlab-body"
) -> int:
    parser = argparse.ArgumentParser(prog="spotlab model")
    add_init_parser(parser.add_subparsers())
    args = parser.parse_args(
        ["init", str(folder / source), "--template", template, "--calibration",
         str(folder / "rig.toml"), "--out", str(out)]
    )  # fmt: skip
    return int(args.run(args))


def test_init_then_learn(folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    m0 = tmp_path / "m0.json"
    assert _init(folder, m0) == 0
    out = capsys.readouterr().out
    assert "template spotlab-body: scale" in out and "worst first" in out
    data = json.loads(m0.read_text())
    assert data["template_fit"]["matched"] >= 0.95 and data["template_fit"]["rms_mm"] < 20
    assert STATIC_KEY in data and len(MarkerModel.load(m0).labels) == 40
    final = tmp_path / "model.json"
    args = argparse.Namespace(
        input=folder / "rom.spj", model=m0, calibration=folder / "rig.toml", out=final
    )
    assert run_learn_recording(args) == 0
    assert "static pose: fits frame " in capsys.readouterr().out
    model = MarkerModel.load(final)
    assert model.labels == MarkerModel.load(m0).labels and len(model.segments) == 1
    # scored only now: the static labels against the truth of the static trial
    truth = np.load(folder / "static.npz")
    labels = [str(x) for x in truth["labels"]]
    pose = np.nanmedian(truth["markers_mm"], axis=0)
    static = json.loads(m0.read_text())[STATIC_KEY]
    assert static["labels"] == labels  # same order: the subject's pose is in label order
    seg = model.segments[0]
    true_seg = pose[[labels.index(model.labels[m]) for m in seg.markers]]
    d_true = np.linalg.norm(true_seg[:, None] - true_seg[None], axis=2)
    d_model = np.linalg.norm(seg.coordinates[:, None] - seg.coordinates[None], axis=2)
    assert np.abs(d_true - d_model).max() < 10.0  # the trunk cluster's layout


def test_bad_inputs_are_one_clear_error(folder: Path, tmp_path: Path) -> None:
    with pytest.raises(CommandError, match="not static"):
        _init(folder, tmp_path / "x.json", source="walk.spj")
    with pytest.raises(CommandError, match="no template 'nobody'"):
        _init(folder, tmp_path / "x.json", template="nobody")
    with pytest.raises(CommandError, match="do not fit template 'lower-limb'"):
        _init(folder, tmp_path / "x.json", template="lower-limb")
    with pytest.raises(CommandError, match="does not exist"):
        _init(folder, tmp_path / "no" / "x.json")
    args = argparse.Namespace(
        input=folder / "rom.spj", model=tmp_path / "none.json",
        calibration=folder / "rig.toml", out=tmp_path / "m.json",
    )  # fmt: skip
    with pytest.raises(CommandError, match="no such marker model"):
        run_learn_recording(args)
