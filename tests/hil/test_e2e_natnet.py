"""A lab session with an OptiTrack system: ``spotlab sim natnet`` and ``spotlab sim timer
--pty`` as separate processes, recorded by one ``spotlab record`` into one journal.

Every NatNet frame the simulated Motive sent while the recorder listened is in the
journal (frame numbers contiguous, nothing lost), ``spotlab export --c3d`` of the
journal equals the simulator's truth (as NatNet's float32 carries it), the rigid
bodies beside it equal the served poses, and the session clock report puts the
NatNet stream on the timer's session time through its arrival stamps.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from _e2e import _first_line as first_line
from _e2e import run_cli, spawn_cli, stop_process

from spotlab.acquisition.replay import replay
from spotlab.io import TRIAL_READERS
from spotlab.processing.decoding import decoder_for
from spotlab.simulators.natnet_scene import NatNetScene

RATE = 100.0
SEED = 3


@pytest.mark.timeout(60)
def test_natnet_and_timer_recorded_together_keep_every_frame(tmp_path: Path) -> None:
    truth, journal, c3d = tmp_path / "truth.npz", tmp_path / "run.spj", tmp_path / "run.c3d"
    natnet = spawn_cli(
        ["sim", "natnet", "--port", 0, "--rate", RATE, "--markers", 40, "--seed", SEED,
         "--truth", truth, "--clock-drift-ppm", 120, "--clock-offset", 50],
        tmp_path / "natnet.out", tmp_path / "natnet.err",
    )  # fmt: skip
    timer = spawn_cli(
        ["sim", "timer", "--pty", "--rate", 100],
        tmp_path / "timer.out", tmp_path / "timer.err",
    )  # fmt: skip
    try:
        address = first_line(tmp_path / "natnet.out", natnet, tmp_path / "natnet.err", 30.0)
        timer_port = first_line(tmp_path / "timer.out", timer, tmp_path / "timer.err", 30.0)
        result = run_cli(
            "record", "--device", f"natnet={address}", "--device", f"timer={timer_port}",
            "--seconds", 5, "--out", journal, "--json", timeout=45,
        )  # fmt: skip
    finally:
        assert stop_process(timer) == 0
        assert stop_process(natnet) == 0
    assert result.returncode == 0, result.stderr
    streams = {s["name"]: s for s in json.loads(result.stdout)["streams"]}
    assert streams["natnet"]["lost_frames"] == 0 and streams["timer"]["lost_frames"] == 0

    blocks = [b for name, b in replay(journal, decoder_for) if name == "natnet"]
    seq = np.concatenate([b.seq for b in blocks])
    data = np.concatenate([b.data for b in blocks])
    assert len(seq) >= 0.9 * 5 * RATE
    assert np.all(np.diff(seq) == 1), "a NatNet frame is missing from the journal"

    t = np.load(truth)
    sent = {int(k): i for i, k in enumerate(t["frame"])}
    assert all(int(k) in sent for k in seq)
    # every frame sent between the first and the last recorded one is recorded
    between = [k for k in t["frame"] if seq[0] <= k <= seq[-1]]
    assert len(between) == len(seq) and len(t["dropped"]) == 0
    rows = [sent[int(k)] for k in seq]
    want = (t["markers_mm"][rows] / 1000.0).astype(np.float32).astype(np.float64) * 1000.0
    np.testing.assert_array_equal(data[:, :, 0, :], want)

    exported = run_cli("export", journal, "--c3d", c3d, timeout=60)
    assert exported.returncode == 0, exported.stderr
    trial = TRIAL_READERS[".c3d"](c3d)
    assert trial.labels == [str(x) for x in t["labels"]] and trial.point_rate == RATE
    assert trial.n_frames == len(seq)
    np.testing.assert_allclose(trial.points, want, atol=1e-3)

    scene = NatNetScene(markers=40, cameras=8, rate_hz=RATE, seed=SEED)
    with open(tmp_path / "run.bodies.csv", newline="") as fh:
        table = [r for r in csv.DictReader(fh) if r["stream"] == "natnet"]
    assert [int(r["frame"]) for r in table] == [int(k) for k in seq]
    for r, i in zip(table[::50], rows[::50], strict=False):
        (pose,) = scene.poses(t["markers_mm"][i])
        got = [float(r[c]) for c in ("x_mm", "y_mm", "z_mm")]
        np.testing.assert_allclose(got, np.float32(pose.position_m) * 1000.0, atol=1e-3)

    report_path = tmp_path / "sync.json"
    synced = run_cli("export", journal, "--sync-report", report_path, timeout=60)
    assert synced.returncode == 0, synced.stderr
    report = json.loads(report_path.read_text())
    assert report["reference"] == "timer"
    (nat,) = [s for s in report["streams"] if s["stream"] == "natnet"]
    assert nat["method"] == "arrivals" and nat["frames"] == len(seq)
