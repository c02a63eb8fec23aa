"""Issue 14's fault matrix for OptiTrack NatNet, through the real command line.

``spotlab sim natnet --faults`` injects one fault of every kind the simulator knows
(a drop, late frames, a client too slow for the stream, a take restart, a silence
longer than the driver's 2 s) into one ``spotlab record``: ``spotlab info --json`` must
count each as the truth says, every frame the simulator sent must be in the journal,
the late ones with their late arrival, and the recording must go on after the silence.
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
OUTAGE_S = 2.5
SCHEDULE = f"drop@0.5:{DROP},late@1.0:{LATE},slow@1.5:{SLOW},restart@2.0,disconnect@3.0:{OUTAGE_S}"
RECORD_S = 7.0


@pytest.mark.timeout(60)
def test_every_natnet_fault_counted_and_no_sent_frame_lost(tmp_path: Path) -> None:
    truth_path, journal = tmp_path / "truth.npz", tmp_path / "natnet.spj"
    result = record_simulator(
        tmp_path,
        ["natnet", "--port", 0, "--rate", RATE_HZ, "--markers", 10,
         "--faults", SCHEDULE, "--truth", truth_path],
        "natnet", RECORD_S, journal,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    truth = dict(np.load(truth_path))
    (s,) = info(journal)["streams"]
    print("info:", json.dumps({k: v for k, v in s.items() if k != "live_stats"}))

    # Counted: frames lost by number (the drop, and those the slow client's full socket
    # lost), one gap per run lost, one for the restart, one for the silence.
    assert len(truth["dropped"]) == DROP and len(truth["overflowed"]) == SLOW
    assert len(truth["late"]) == LATE
    assert s["lost_frames"] == DROP + SLOW
    assert s["reconnects"] == 1 and s["disconnections"] == 1
    assert s["gaps"] == 4
    assert np.count_nonzero(np.diff(truth["number"]) < 0) == 1, "one take restart"
    assert s["device_summary"]["restarts"] == 1 and s["duplicates"] == 0

    # Every frame sent, up to the last one the driver read before it left, is in the
    # journal, in order, the restart's included.
    block = FrameBlock.concat(
        [b for name, b in replay(journal, decoder_for) if name == "natnet" and len(b)]
    )
    assert len(block) == s["frames"]
    last = int(np.flatnonzero(truth["ticks"] == block.ticks[-1])[0])
    assert np.array_equal(block.ticks, truth["ticks"][: last + 1])
    assert last + 1 >= len(truth["ticks"]) - 3, "frames sent near the stop were lost"
    np.testing.assert_allclose(block.data[:, :, 0], truth["markers_mm"][: last + 1], atol=1e-3)
    assert np.all(np.diff(block.seq) > 0), "sequence numbers go on across the restart"

    # The late frames are kept, stamped when they came: at least the hold after the
    # frame before them.
    first_late = int(np.flatnonzero(truth["frame"] == truth["late"][0])[0])
    held_s = (block.arrival_ns[first_late] - block.arrival_ns[first_late - 1]) / 1e9
    assert held_s >= 0.04, held_s

    # The recording goes on after the silence.
    back = truth["frame"][0] + (3.0 + OUTAGE_S) * RATE_HZ
    assert np.count_nonzero(truth["frame"][: last + 1] > back) >= 0.8 * RATE_HZ
