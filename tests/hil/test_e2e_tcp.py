"""A simulated system served over TCP (socket://) is recorded at full rate."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from _e2e import decode, info, record_args, run_cli, sim_pty


@pytest.mark.timeout(90)
def test_tcp_link_carries_4x32_at_200_hz_without_loss(tmp_path: Path) -> None:
    journal = tmp_path / "tcp.spj"
    with sim_pty(tmp_path, seed=5, transport="tcp") as sim:
        assert sim.path.startswith("socket://127.0.0.1:")
        result = run_cli(*record_args(sim.path, journal, 2.0), "--json", timeout=60)
        assert result.returncode == 0, result.stderr
    live = json.loads(result.stdout)["streams"][0]
    (stream,) = info(journal)["streams"]
    assert stream["lost_frames"] == 0 and stream["crc_errors"] == 0, stream
    # pyserial's socket:// reports one byte waiting at most; a link that believed it
    # read a byte per call and fell seconds behind (about 350 frames in 3 s).
    assert stream["frames"] >= 0.95 * 2.0 * 200, stream
    assert stream["frames"] == live["frames"]
    seq = decode(journal).seq
    assert np.all(np.diff(seq) == 1)
