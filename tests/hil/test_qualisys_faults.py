"""Issue 14's fault matrix for Qualisys QTM, through the real command line.

``spotlab sim qualisys --faults`` injects one fault of every kind the simulator knows
(a drop, late frames, a client too slow for the stream, a capture restart, a
disconnection) into one ``spotlab record``: ``spotlab info --json`` must count each as
the truth says, every frame the simulator served must be in the journal, the late
ones with their late arrival, and the recording must go on after the reconnection.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from _e2e import info, record_simulator

from spotlab.acquisition.replay import replay
from spotlab.core.frames import FrameBlock
from spotlab.processing.decoding import decoder_for

RATE_HZ = 100.0
DROP, LATE, SLOW = 3, 4, 5
SCHEDULE = f"drop@0.5:{DROP},late@1.0:{LATE},slow@1.5:{SLOW},restart@2.0,disconnect@3.0:0.5"
RECORD_S = 5.0


@pytest.mark.timeout(60)
def test_every_qualisys_fault_counted_and_no_served_frame_lost(tmp_path: Path) -> None:
    truth_path, journal = tmp_path / "truth.npz", tmp_path / "qtm.spj"
    result = record_simulator(
        tmp_path,
        ["qualisys", "--markers", 10, "--cameras", 4, "--rate", RATE_HZ,
         "--faults", SCHEDULE, "--truth", truth_path],
        "qualisys", RECORD_S, journal,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    truth = dict(np.load(truth_path))
    (s,) = info(journal)["streams"]
    print("info:", json.dumps({k: v for k, v in s.items() if k != "live_stats"}))

    # Counted: frames lost by number (the drop and the slow client's), one gap per run
    # lost, one for the restart, one for the reconnection.
    assert s["lost_frames"] == DROP + SLOW
    assert len(truth["skipped"]) == SLOW and len(truth["late"]) == LATE
    assert s["reconnects"] == 1 and s["disconnections"] == 1
    assert s["gaps"] == 4
    restarted = np.flatnonzero(np.diff(truth["qtm_frame"]) < 0)
    assert len(restarted) == 1, "the truth holds one capture restart"
    events = s["device_summary"]["events"]
    assert events.count("capture stopped") == events.count("capture started") == 1, events
    assert events.count("connection closed") == 1, events

    # Every frame served is in the journal, in order.
    block = FrameBlock.concat(
        [b for name, b in replay(journal, decoder_for) if name == "qualisys" and len(b)]
    )
    assert len(block) == len(truth["frame"]) == s["frames"]
    assert np.array_equal(block.ticks, truth["timestamp_us"])
    np.testing.assert_allclose(
        block.data[:, :, 0], truth["markers_mm"].astype(np.float32), rtol=0, atol=1e-3
    )
    assert np.all(np.diff(block.seq) > 0), "sequence numbers go on across the restart"

    # The late frames are kept, stamped when they came: at least the hold after the
    # frame before them.
    first_late = int(np.flatnonzero(truth["frame"] == truth["late"][0])[0])
    held_s = (block.arrival_ns[first_late] - block.arrival_ns[first_late - 1]) / 1e9
    assert held_s >= 0.04, held_s

    # The recording goes on after the reconnection: the frames after the outage.
    after = truth["frame"] > truth["frame"][restarted[0]] + 1.4 * RATE_HZ
    assert after.sum() >= RATE_HZ * 0.8, after.sum()
