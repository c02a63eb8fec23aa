"""A recording killed with SIGKILL at a random moment opens and holds all but the last <= 100 ms."""

from __future__ import annotations

import os
import random
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from spotlab.io.journal import JournalReader, RecordType

# Writes one 256-byte RX record every 2 ms, stamped with the monotonic clock
# (system-wide on Linux, so the parent can compare it with its kill time), and
# prints "seq t_ns" once the record is handed to the writer. Stops by itself
# after 10 s should the parent fail to kill it.
CHILD = """
import sys, time
from spotlab.io.journal import JournalWriter

journal = JournalWriter(sys.argv[1], {"writer": "sigkill-test"})
stream = journal.add_stream("wire", {"family": "toy"})
print("ready", flush=True)
next_t = time.monotonic()
for seq in range(5000):
    t_ns = time.monotonic_ns()
    journal.rx(stream, seq.to_bytes(4, "little") * 64, t_ns)
    print(seq, t_ns, flush=True)
    next_t += 0.002
    time.sleep(max(0.0, next_t - time.monotonic()))
journal.close()
"""

ALLOWED_LOSS_NS = 100_000_000


def _read_until(fd: int, buf: bytearray, until: float, stop_at: bytes | None = None) -> bool:
    """Read the child's output until ``until`` (monotonic s) or ``stop_at``; False at EOF."""
    while time.monotonic() < until:
        if stop_at is not None and stop_at in buf:
            return True
        ready, _, _ = select.select([fd], [], [], max(0.0, until - time.monotonic()))
        if ready:
            chunk = os.read(fd, 65536)
            if not chunk:
                return False
            buf += chunk
    return True


@pytest.mark.parametrize("run", [0, 1])
def test_sigkill_at_a_random_moment_keeps_all_but_the_last_100_ms(tmp_path: Path, run: int) -> None:
    path = tmp_path / f"killed{run}.spj"
    delay = random.uniform(0.3, 1.0)
    out = bytearray()
    with subprocess.Popen(
        [sys.executable, "-c", CHILD, str(path)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    ) as proc:
        assert proc.stdout is not None and proc.stderr is not None
        try:
            fd = proc.stdout.fileno()
            alive = _read_until(fd, out, time.monotonic() + 30.0, stop_at=b"ready\n")
            assert alive and b"ready\n" in out, proc.stderr.read().decode(errors="replace")
            _read_until(fd, out, time.monotonic() + delay)
            kill_ns = time.monotonic_ns()
            proc.send_signal(signal.SIGKILL)
        finally:
            proc.kill()
            proc.wait()
        out += proc.stdout.read()
        proc.stderr.read()
    assert proc.returncode == -signal.SIGKILL

    printed = {}
    for line in out.decode().splitlines()[1:]:
        parts = line.split()
        if len(parts) == 2:  # the last line may be cut by the kill
            printed[int(parts[0])] = int(parts[1])
    assert len(printed) > 100, f"the child wrote only {len(printed)} records in {delay:.2f} s"

    reader = JournalReader(path)
    rx = [r for r in reader if r.type == RecordType.RX]
    assert not reader.complete and reader.corrupt_records == 0
    assert reader.session["writer"] == "sigkill-test"
    assert reader.streams == {"wire": {"family": "toy"}}
    # What the journal holds is a gap-free prefix of what the child wrote, intact.
    for seq, rec in enumerate(rx):
        assert rec.payload == seq.to_bytes(4, "little") * 64
        if seq in printed:
            assert rec.t_ns == printed[seq]
    # Everything written more than 100 ms before the kill is there.
    must_have = [seq for seq, t in printed.items() if t <= kill_ns - ALLOWED_LOSS_NS]
    assert must_have, "the kill came too early to test anything"
    lost_ms = (kill_ns - rx[-1].t_ns) / 1e6 if rx else float("inf")
    assert len(rx) > max(must_have), (
        f"killed after {delay:.3f} s: journal ends at seq {len(rx) - 1}, "
        f"{lost_ms:.1f} ms before the kill; seq {max(must_have)} was older than 100 ms"
    )
