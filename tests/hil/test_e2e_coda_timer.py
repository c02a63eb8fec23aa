"""Two simulated CSX scanners and a timer, recorded together through real pseudo-terminals.

The scanners publish their scan pulses to a shared lab folder; the timer's inputs 0
and 1 are wired to them. Every recorded scan of each scanner must have exactly one
timer edge, at the scan's true start as read by the timer's own clock (issue 18:
synchronisation with the timer family). Unit B stands 800 mm aside, turned 15
degrees; a static L-frame both see carries B's trajectories into A's frame, the
timer puts both on session time, and B's markers interpolated at A's instants must
agree with A's. ``long``: run with ``make long``.
"""

from __future__ import annotations

import csv
import json
import os
from pathlib import Path

import numpy as np
import pytest
from _e2e import _first_line as first_line
from _e2e import run_cli, spawn_cli, stop_process

from spotlab.acquisition.replay import replay
from spotlab.drivers.timer import edges_from_recording
from spotlab.processing.decoding import decoder_for
from spotlab.processing.scanner_alignment import align_scanners
from spotlab.processing.scanner_trajectories import read_scanner_recording, scanner_points
from spotlab.processing.session_times import recording_timebase

#: Four moving markers and the static L-frame (IDs 50-53) that aligns the two units.
TABLE = "RO+RY+RG+RC+WR+WO+WY+WG"
#: Recording length; issue 18 asks for 60 s (``SPOTLAB_CODA_SECONDS=60 make long``).
SECONDS = float(os.environ.get("SPOTLAB_CODA_SECONDS", "4"))


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.long
@pytest.mark.timeout(120 + 2 * SECONDS)
def test_two_scanners_and_a_timer_keep_every_frame_and_sync(tmp_path: Path) -> None:
    lab = tmp_path / "lab"
    journal = tmp_path / "run.spj"
    procs, ports, truths = [], {}, {}
    try:
        units = (("codaA", 3, 150, "0,0,0,0"), ("codaB", 11, -80, "15,800,0,0"))
        for k, (name, offset, drift, pose) in enumerate(units):
            truths[name] = tmp_path / f"{name}.csv"
            out, err = tmp_path / f"{name}.out", tmp_path / f"{name}.err"
            p = spawn_cli(
                ["sim", "coda", "--pty", "--markers", 4, "--seed", k + 1, "--truth",
                 truths[name], "--lab", lab, "--lab-name", name, "--clock-offset", offset,
                 "--clock-drift-ppm", drift, "--pose", pose, "--reference"],
                out, err,
            )  # fmt: skip
            procs.append(p)
            ports[name] = first_line(out, p, err, timeout=30.0)
        timer_truth = tmp_path / "timer.csv"
        out, err = tmp_path / "timer.out", tmp_path / "timer.err"
        timer = spawn_cli(
            ["sim", "timer", "--pty", "--rate", 100, "--input", "0=codaA", "--input",
             "1=codaB", "--lab", lab, "--truth", timer_truth, "--clock-offset", 1000],
            out, err,
        )  # fmt: skip
        procs.append(timer)
        timer_port = first_line(out, timer, err, timeout=30.0)
        result = run_cli(
            "record", "--device", f"timer={timer_port}",
            "--device", f"coda={ports['codaA']},name=codaA,markers={TABLE}",
            "--device", f"coda={ports['codaB']},name=codaB,markers={TABLE}",
            "--wiring", "codaA=0", "--wiring", "codaB=1",
            "--seconds", SECONDS, "--out", journal, "--json", timeout=90 + 2 * SECONDS,
        )  # fmt: skip
    finally:
        for p in procs:
            assert stop_process(p) == 0
    assert result.returncode == 0, result.stderr
    streams = {s["name"]: s for s in json.loads(result.stdout)["streams"]}
    assert all(streams[n]["lost_frames"] == 0 for n in ("timer", "codaA", "codaB"))

    rows = _rows(timer_truth)
    t_true = np.array([float(r["true_time_s"]) for r in rows])
    counter = np.array([10 * int(r["device_us"]) for r in rows], dtype=np.float64)
    slope, icept = np.polyfit(t_true - t_true[0], counter, 1)
    for channel, name in enumerate(("codaA", "codaB")):
        seqs = np.concatenate([b.seq for n, b in replay(journal, decoder_for) if n == name])
        assert len(seqs) > 0.8 * 300 * SECONDS and np.all(np.diff(seqs) == 1)
        edges = edges_from_recording(journal, decoder_for, "timer").select(channel)
        true = {int(r["seq"]): float(r["true_time_s"]) for r in _rows(truths[name])
                if r["sent"] == "1"}  # fmt: skip
        frame_true = np.array([true[int(s) % 65536] for s in seqs])
        edge_true = (edges.tick - icept) / slope + t_true[0]
        span = (edges.frame_ticks[[0, -1]] - icept) / slope + t_true[0]
        listened = (frame_true > span[0]) & (frame_true <= span[1])
        assert listened.sum() > 0.8 * len(seqs)
        frame_true = frame_true[listened]
        nearest = np.clip(np.searchsorted(edge_true, frame_true), 1, len(edge_true) - 1)
        err_s = np.minimum(
            np.abs(edge_true[nearest - 1] - frame_true), np.abs(edge_true[nearest] - frame_true)
        )
        assert err_s.max() < 1e-6, err_s.max()
        inside = (edge_true >= frame_true[0] - 1e-6) & (edge_true <= frame_true[-1] + 1e-6)
        assert int(inside.sum()) == len(frame_true)

    # One frame: unit B (800 mm aside, turned 15 degrees) carried into A's by the L-frame.
    rec = {n: read_scanner_recording(journal, n) for n in ("codaA", "codaB")}
    pts = {n: scanner_points(r) for n, r in rec.items()}
    labels = rec["codaA"].labels
    alignment = align_scanners(pts["codaA"], labels, pts["codaB"], labels, labels[4:])
    assert alignment.rms < 0.5
    # One time base: every scan on session time through the timer's edges; B's aligned
    # markers interpolated at A's instants (mid-sweep) agree with A's.
    base = recording_timebase(journal)
    at = {}
    for n, r in rec.items():
        s = base.streams[n]
        k = s.seq - s.seq[0]
        assert np.array_equal(k, np.arange(r.values.shape[0])[: len(k)])
        at[n] = s.time_s + 0.4 / r.rate_hz
    b_in_a = alignment.apply(pts["codaB"][:, :4])
    diffs = []
    for m in range(4):
        ok = np.isfinite(b_in_a[:, m]).all(axis=1) & np.isfinite(at["codaB"])
        tb = at["codaB"][ok]
        # Only between two of B's scans in a row (not across an occlusion).
        i = np.clip(np.searchsorted(tb, at["codaA"]), 1, len(tb) - 1)
        near = (tb[i] - tb[i - 1]) < 1.5 / rec["codaB"].rate_hz
        for axis in range(3):
            b_at_a = np.interp(at["codaA"], tb, b_in_a[ok, m, axis], np.nan, np.nan)
            diffs.append(np.where(near, b_at_a, np.nan) - pts["codaA"][:, m, axis])
    d = np.abs(np.asarray(diffs))
    print(
        "B in A's frame and time - A (mm): median", np.nanmedian(d), "p99", np.nanpercentile(d, 99)
    )
    assert np.nanmedian(d) < 1.0 and np.nanpercentile(d, 99) < 5.0
