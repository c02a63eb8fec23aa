"""``spotlab record`` killed with SIGKILL at a random moment keeps all but the last <= 100 ms."""

from __future__ import annotations

import os
import random
import signal
import time
from pathlib import Path

import numpy as np
import pytest
from _e2e import (
    LEDS,
    decode,
    info,
    match_to_truth,
    record_args,
    run_cli,
    sim_pty,
    spawn_cli,
    stop_process,
)

#: TARGETS.md: a killed recording holds all but the last <= 100 ms.
TARGET_NS = 100_000_000
#: From a frame's true time (its first sample) to its last byte leaving the device:
#: 32 LED slots + 2 of 100 us, then 668 bytes at 2 Mbaud (3.3 ms); the pty delivers in
#: ms batches. Generous: frames due this long before the deadline must be held.
WIRE_NS = (LEDS + 2) * 100_000 + 668 * 10 * 500 + 10_000_000


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.timeout(90)
def test_killed_recording_holds_all_but_the_last_100_ms(tmp_path: Path, seed: int) -> None:
    rng = random.Random(seed)
    journal = tmp_path / "killed.spj"
    with sim_pty(tmp_path, seed=seed) as sim:
        proc = spawn_cli(
            record_args(sim.path, journal, 60.0), tmp_path / "rec.out", tmp_path / "rec.err"
        )
        try:
            # Streaming has begun once the journal holds some frames (668 bytes each).
            deadline = time.monotonic() + 30.0
            while not (journal.exists() and journal.stat().st_size > 40_000):
                assert proc.poll() is None, (tmp_path / "rec.err").read_text()
                assert time.monotonic() < deadline, "the recording never started"
                time.sleep(0.01)
            time.sleep(rng.uniform(0.05, 1.5))
            kill_ns = time.monotonic_ns()
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)
        finally:
            stop_process(proc, signal.SIGKILL)
        # The device was left streaming (no STOP:): the next recording still gets it.
        again = run_cli(*record_args(sim.path, tmp_path / "again.spj", 0.5), timeout=60)
        assert again.returncode == 0, again.stderr
        assert sim.stop() == 0
    assert proc.returncode == -signal.SIGKILL
    assert info(tmp_path / "again.spj")["streams"][0]["frames"] > 50

    summary = info(journal)
    assert not summary["complete"]
    (s,) = summary["streams"]
    assert s["lost_frames"] == 0 and s["crc_errors"] == 0 and s["gaps"] == 0

    truth = sim.truth()
    dec = decode(journal)
    assert len(dec) == s["frames"] > 0
    rows = match_to_truth(dec, truth)
    assert np.array_equal(dec.seq % 65536, np.arange(len(dec))), "contiguous from seq 0"
    assert set(truth.stream[rows].tolist()) == {0}  # (the second recording is stream 1)

    # The journal reaches to within 100 ms of the kill...
    last_arrival_ns = int(dec.arrival_ns[-1])
    assert last_arrival_ns < kill_ns
    loss_ms = (kill_ns - last_arrival_ns) / 1e6
    # ... and, by the simulator's clock, holds every frame that was on the host 100 ms before.
    sent = truth.sent & (truth.stream == 0)
    due = truth.seq[sent & (truth.true_time_ns + WIRE_NS <= kill_ns - TARGET_NS)]
    missing = np.setdiff1d(due, dec.seq % 65536)
    last_true_ns = int(truth.true_time_ns[rows[-1]])
    print(
        f"seed {seed}: {len(dec)} frames held, truncated_bytes {summary['truncated_bytes']}; "
        f"last frame held arrived {loss_ms:.1f} ms before the kill "
        f"(taken {(kill_ns - last_true_ns) / 1e6:.1f} ms before it)"
    )
    assert missing.size == 0, f"frames due before kill - 100 ms not held: {missing[:10]}"
    assert loss_ms <= TARGET_NS / 1e6
