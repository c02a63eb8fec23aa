"""A lab's session with a Qualisys QTM: the real command line, each device its own process.

``spotlab sim qualisys`` (8 cameras, 40 labelled markers, 300 Hz, truth file) and
``spotlab sim timer --pty`` run as separate processes; one ``spotlab record
--device qualisys=ADDR --device timer=PORT`` records both into one journal. Every
QTM frame the simulator served must be in the journal (frame numbers contiguous, as
many as the truth holds), and ``spotlab export --c3d`` must give the labelled markers
of the truth to float32 precision.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from _e2e import _first_line as first_line
from _e2e import run_cli, spawn_cli, stop_process

from spotlab.acquisition.replay import replay
from spotlab.core.frames import FrameBlock
from spotlab.io import read_c3d
from spotlab.processing.decoding import decoder_for

RATE_HZ = 300.0


def _session(folder: Path, seconds: float) -> None:
    truth_path = folder / "qtm-truth.npz"
    journal = folder / "lab.spj"
    q_out, q_err = folder / "qtm.stdout", folder / "qtm.stderr"
    t_out, t_err = folder / "timer.stdout", folder / "timer.stderr"
    qtm = spawn_cli(
        ["sim", "qualisys", "--cameras", 8, "--markers", 40, "--rate", RATE_HZ, "--seed", 4,
         "--truth", truth_path],
        q_out, q_err,
    )  # fmt: skip
    timer = spawn_cli(["sim", "timer", "--pty", "--rate", 200], t_out, t_err)
    try:
        address = first_line(q_out, qtm, q_err, timeout=30.0)
        timer_port = first_line(t_out, timer, t_err, timeout=30.0)
        result = run_cli(
            "record", "--device", f"qualisys={address}", "--device", f"timer={timer_port}",
            "--seconds", seconds, "--out", journal, "--json", timeout=seconds + 40,
        )  # fmt: skip
    finally:
        assert stop_process(timer) == 0
        assert stop_process(qtm) == 0  # SIGTERM: the simulator writes its truth
    assert result.returncode == 0, result.stderr
    streams = {s["name"]: s for s in json.loads(result.stdout)["streams"]}
    assert set(streams) == {"qualisys", "timer"}
    assert streams["qualisys"]["lost_frames"] == 0 and streams["qualisys"]["gaps"] == 0
    assert streams["timer"]["lost_frames"] == 0

    truth = dict(np.load(truth_path))
    block = FrameBlock.concat(
        [b for name, b in replay(journal, decoder_for) if name == "qualisys" and len(b)]
    )
    # every frame the simulator served (to its only client, the recorder) was kept
    assert len(block) >= 0.8 * RATE_HZ * seconds
    assert np.array_equal(block.seq, truth["frame"]), (len(block), len(truth["frame"]))
    assert np.array_equal(block.ticks, truth["timestamp_us"])
    markers32 = truth["markers_mm"].astype(np.float32)
    assert np.array_equal(block.data[:, :, 0, :], markers32)

    c3d = folder / "lab.c3d"
    exported = run_cli("export", journal, "--c3d", c3d, timeout=120)
    assert exported.returncode == 0, exported.stderr
    trial = read_c3d(c3d)
    assert trial.labels == truth["labels"].tolist() and trial.point_rate == RATE_HZ
    assert trial.n_frames == len(truth["frame"])
    assert np.array_equal(trial.points.astype(np.float32), markers32)


@pytest.mark.timeout(60)
def test_qualisys_and_timer_recorded_together_every_frame_kept(tmp_path: Path) -> None:
    _session(tmp_path, 8.0)


@pytest.mark.long
@pytest.mark.timeout(180)
def test_qualisys_and_timer_60_s(tmp_path: Path) -> None:
    _session(tmp_path, 60.0)
