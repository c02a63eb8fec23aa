"""One timer and one SELSPOT system, recorded together through real pseudo-terminals.

Both simulators run as separate ``spotlab sim`` processes sharing a lab folder:
the timer's input 0 is wired to the SELSPOT system's frame pulses. ``spotlab
record`` records both into one journal; every recorded SELSPOT frame must have
exactly one edge in the timer stream, at the frame's true instant as read by
the timer's own clock.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from _e2e import _first_line as first_line
from _e2e import run_cli, sim_pty, spawn_cli, stop_process

from spotlab.acquisition.replay import replay
from spotlab.drivers.timer import edges_from_recording
from spotlab.processing.decoding import decoder_for


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.timeout(60)
def test_every_selspot_frame_has_one_timer_edge_at_its_true_instant(tmp_path: Path) -> None:
    lab = tmp_path / "lab"
    journal = tmp_path / "run.spj"
    timer_truth = tmp_path / "timer.csv"
    extra = ["--lab", lab, "--lab-name", "sel", "--clock-drift-ppm", 200, "--clock-offset", 7]
    with sim_pty(tmp_path, cameras=1, leds=8, rate=200, seed=2, extra=extra) as sel:
        out, err = tmp_path / "timer.stdout", tmp_path / "timer.stderr"
        timer = spawn_cli(
            ["sim", "timer", "--pty", "--rate", 200, "--input", "0=sel", "--lab", lab,
             "--truth", timer_truth, "--clock-offset", 1000, "--clock-drift-ppm", -150],
            out, err,
        )  # fmt: skip
        try:
            timer_port = first_line(out, timer, err, timeout=30.0)
            result = run_cli(
                "record", "--device", f"timer={timer_port}", "--device", f"selspot={sel.path}",
                "--cameras", 1, "--leds", 8, "--rate", 200, "--seconds", 3, "--out", journal,
                "--json", timeout=45,
            )  # fmt: skip
        finally:
            assert stop_process(timer) == 0
        assert result.returncode == 0, result.stderr
        assert sel.stop() == 0
    streams = {s["name"]: s for s in json.loads(result.stdout)["streams"]}
    assert streams["timer"]["lost_frames"] == 0 and streams["selspot"]["lost_frames"] == 0

    seqs = np.concatenate([b.seq for name, b in replay(journal, decoder_for) if name == "selspot"])
    edges = edges_from_recording(journal, decoder_for, "timer").select(0)
    assert len(seqs) > 400

    # True instant of each recorded SELSPOT frame (one stream: seq is the wire seq).
    sel_true = {
        int(r["seq"]): float(r["true_time_s"]) for r in _rows(sel.truth_path) if r["sent"] == "1"
    }
    frame_true = np.array([sel_true[int(s) % 65536] for s in seqs])
    # The timer's counter as a function of true time, from its own frame truth.
    rows = _rows(timer_truth)
    t_true = np.array([float(r["true_time_s"]) for r in rows])
    counter = np.array([10 * int(r["device_us"]) for r in rows], dtype=np.float64)
    slope, icept = np.polyfit(t_true - t_true[0], counter, 1)
    edge_true = (edges.tick - icept) / slope + t_true[0]

    # Frames while the timer streamed (the session starts and stops devices one by one):
    # exactly one edge each, within 1 µs (100 ns ticks, clock fit).
    span = (edges.frame_ticks[[0, -1]] - icept) / slope + t_true[0]
    listened = (frame_true > span[0]) & (frame_true <= span[1])
    assert listened.sum() > 0.9 * len(seqs)
    frame_true = frame_true[listened]
    nearest = np.searchsorted(edge_true, frame_true)
    lo = np.clip(nearest - 1, 0, len(edge_true) - 1)
    hi = np.clip(nearest, 0, len(edge_true) - 1)
    err_s = np.minimum(np.abs(edge_true[lo] - frame_true), np.abs(edge_true[hi] - frame_true))
    assert err_s.max() < 1e-6, err_s.max()
    inside = (edge_true >= frame_true[0] - 1e-6) & (edge_true <= frame_true[-1] + 1e-6)
    assert int(inside.sum()) == len(frame_true)
    assert np.all(np.diff(edges.edge_index) == 1)
    info = json.loads(run_cli("info", journal, "--json").stdout)
    assert {s["name"] for s in info["streams"]} == {"timer", "selspot"}
