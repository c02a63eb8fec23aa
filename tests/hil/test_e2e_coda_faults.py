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

import pytest
from _e2e import _first_line as first_line
from _e2e import (
    check_fault_matrix,
    read_truth,
    run_cli,
    spawn_cli,
    stop_process,
)

# Seconds after the first START. Frame faults at least 0.4 s (120 scans) apart, none close
# to a break (a frame lost just before a restart has no later frame of its stream to
# reveal it); a bit flip after both restarts to check counting goes on.
SCHEDULE = (
    "bitflip@0.6,drop@1.0,garbage@1.4,truncate@1.8,duplicate@2.2,burst@2.6,"
    "overflow@3.0:3,reset@3.6,disconnect@4.8:0.5,bitflip@6.2"
)
RECORD_S = 7.0


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
    check_fault_matrix(journal, log, truth, SCHEDULE)
