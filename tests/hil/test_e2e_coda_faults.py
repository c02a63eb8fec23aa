"""The fault matrix of TARGETS.md for the CSX scanner family (issue 18), as
``test_e2e_fault_matrix.py`` does it for SPX: one recording through the real command
line and a pty, one fault of every kind at distinct times: ``spotlab info`` must agree with the
simulator's fault log exactly, the reset and the disconnect must show as
explicit breaks with the driver streaming again within 1 s of the device being
back, and no frame the device sent undamaged may be missing.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from _e2e import (
    Truth,
    decode,
    events,
    info,
    match_to_truth,
    read_truth,
    run_cli,
    spawn_cli,
    stop_process,
)
from _e2e import _first_line as first_line

# Seconds after the first START. Frame faults at least 0.4 s (120 scans) apart, none close
# to a break (a frame lost just before a restart has no later frame of its stream to
# reveal it); a bit flip after both restarts to check counting goes on.
SCHEDULE = (
    "bitflip@0.6,drop@1.0,garbage@1.4,truncate@1.8,duplicate@2.2,burst@2.6,"
    "overflow@3.0:3,reset@3.6,disconnect@4.8:0.5,bitflip@6.2"
)
RECORD_S = 7.0
#: TARGETS.md: reconnected within 1 s of the device returning.
RECONNECT_TARGET_S = 1.0
#: Fault-log counters of frames a host cannot decode.
DAMAGE = ("corrupted_frames", "lost_frames", "discarded_frames")


def _stream_of(entry: dict[str, Any], truth: Truth) -> int:
    """The device stream a fault entry's frames belong to (the sent frame nearest in time)."""
    seq = entry["seq"][0]
    rows = np.flatnonzero(truth.sent & (truth.seq == seq))
    nearest = rows[np.argmin(np.abs(truth.true_time_ns[rows] - entry["world_ns"]))]
    return int(truth.stream[nearest])


def _damaged(log: dict[str, Any], truth: Truth) -> set[tuple[int, int]]:
    """``(stream, seq)`` of every frame the log says went out damaged, lost or cut."""
    out: set[tuple[int, int]] = set()
    for entry in log["faults"]:
        if not any(entry[k] for k in DAMAGE):
            continue
        assert len(entry["seq"]) == sum(entry[k] for k in DAMAGE), entry
        stream = _stream_of(entry, truth)
        out.update((stream, int(s)) for s in entry["seq"])
    return out


@pytest.mark.long
@pytest.mark.timeout(120)
def test_every_fault_kind_counted_and_no_valid_scan_lost(tmp_path: Path) -> None:
    journal = tmp_path / "faults.spj"
    truth_path, log_path = tmp_path / "truth.csv", tmp_path / "faults.json"
    out, err = tmp_path / "sim.stdout", tmp_path / "sim.stderr"
    sim = spawn_cli(
        ["sim", "coda", "--pty", "--markers", 4, "--seed", 3, "--faults", SCHEDULE,
         "--truth", truth_path, "--fault-log", log_path, "--lab", tmp_path / "lab"],
        out, err,
    )  # fmt: skip
    try:
        port = first_line(out, sim, err, timeout=30.0)
        result = run_cli(
            "record", "--device", f"coda={port},markers=4", "--seconds", RECORD_S,
            "--out", journal, "--json", timeout=90,
        )  # fmt: skip
        assert result.returncode == 0, result.stderr
        assert "Traceback" not in result.stderr
    finally:
        assert stop_process(sim) == 0
    log = json.loads(log_path.read_text())
    truth = read_truth(truth_path)
    totals = log["totals"]
    fired = sorted(e["kind"] for e in log["faults"])
    assert fired == sorted(item.split("@")[0] for item in SCHEDULE.split(",")), fired

    summary = info(journal)
    assert summary["complete"]
    (s,) = summary["streams"]
    print("info:", json.dumps({k: v for k, v in s.items() if k != "live_stats"}))
    print("fault log totals:", json.dumps(totals))

    # The counts agree with what was injected (the demo's checks). A restart (reset,
    # reconnect) starts the stream from seq 0, so frames lost during the outage are a
    # gap + reconnect, not lost_frames.
    assert s["lost_frames"] - s["device_dropped"] == totals["corrupted_frames"]
    assert s["device_dropped"] == totals["dropped_frames"] == 3
    assert s["duplicates"] == totals["duplicated_frames"] == 1
    assert s["device_resets"] == totals["resets"] == 1
    assert s["disconnections"] == totals["disconnects"] == 1
    assert s["reconnects"] == 2
    # One gap per run of frames lost (a burst damages a few in a row) or dropped, one per
    # outage (disconnection or device reset), as the live driver counts them.
    runs = sum(1 for e in log["faults"] if e["corrupted_frames"] or e["dropped_frames"])
    assert s["gaps"] == runs + s["disconnections"] + s["device_resets"]
    assert s["gaps"] == s["live_stats"]["gaps"]
    assert s["crc_errors"] >= 1 and s["resyncs"] >= 1

    # Frame by frame: per device stream (one per START), every frame sent undamaged
    # from seq 0 to the last one decoded is in the journal, and no damaged one is.
    dec = decode(journal)
    assert len(dec) == s["frames"]
    rows = match_to_truth(dec, truth)
    damaged = _damaged(log, truth)
    streams = sorted(set(truth.stream[rows].tolist()))
    assert streams == [0, 1, 2], streams  # the first START, after the reset, after the return
    missing_after_return = 0
    for k in streams:
        got = np.sort(truth.seq[rows][truth.stream[rows] == k])
        assert np.all(np.diff(got) > 0), "each frame once"
        sent = truth.seq[truth.sent & (truth.stream == k)]
        last = int(got[-1])
        expected = np.array(
            sorted(int(q) for q in sent if q <= last and (k, int(q)) not in damaged)
        )
        missing = sorted(set(expected.tolist()) - set(got.tolist()))
        extra = sorted(set(got.tolist()) - set(expected.tolist()))
        assert not missing and not extra, (k, missing[:20], extra[:20])
        # What the device sent after the host's last frame of the stream.
        after = [int(q) for q in sent if q > last and (k, int(q)) not in damaged]
        if k == 0:
            assert after == [], after  # ended by the reset: only its cut frame, discarded
        elif k == 1:
            # Ended by the disconnect: frames sent after the port came back, before the
            # host reset the device, went to a port that was not reading at their rate.
            missing_after_return = len(after)
        else:
            assert after == [], after  # the last stream: STOP keeps every frame
    print("frames sent after the port returned, before the host's reset:", missing_after_return)

    # Decoded frames: everything sent, less what was damaged, less that one stretch.
    assert s["frames"] == (
        totals["frames_sent"]
        - totals["corrupted_frames"]
        - totals["lost_frames"]
        - totals["discarded_frames"]
        - missing_after_return
    )

    # Both breaks are explicit, and the driver streamed again within 1 s of the device
    # being back (CLOCK_MONOTONIC ns on both sides).
    ev = events(journal)
    kinds = [e.kind for e in ev]
    assert kinds.count("device_reset") == 1 and kinds.count("disconnected") == 1
    reconnected = [e.t_ns for e in ev if e.kind == "reconnected"]
    assert len(reconnected) == 2
    by_kind = {e["kind"]: e for e in log["faults"]}
    reset_ns = by_kind["reset"]["world_ns"]
    back_ns = by_kind["disconnect"]["world_ns"] + round(by_kind["disconnect"]["arg"] * 1e9)
    after_reset = (min(t for t in reconnected if t > reset_ns) - reset_ns) / 1e9
    after_return = (min(t for t in reconnected if t > back_ns) - back_ns) / 1e9
    print(f"streaming again {after_reset:.3f} s after the reset, {after_return:.3f} s after return")
    assert 0 < after_return <= RECONNECT_TARGET_S
    assert 0 < after_reset <= RECONNECT_TARGET_S
