"""The fault matrix of TARGETS.md in one recording, through the real command line and a pty.

One fault of every kind at distinct times: ``spotlab info`` must agree with the
simulator's fault log exactly, the reset and the disconnect must show as
explicit breaks with the driver streaming again within 1 s of the device being
back, and no frame the device sent undamaged may be missing.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from _e2e import (
    check_fault_matrix,
    record_args,
    run_cli,
    sim_pty,
)

# Seconds after the first START. Frame faults at least 0.4 s (80 frames) apart, none close
# to a break (a frame lost just before a restart has no later frame of its stream to
# reveal it); a bit flip after both restarts to check counting goes on.
SCHEDULE = (
    "bitflip@0.6,drop@1.0,garbage@1.4,truncate@1.8,duplicate@2.2,burst@2.6,"
    "overflow@3.0:3,reset@3.6,disconnect@4.8:0.5,bitflip@6.2"
)
RECORD_S = 7.0


@pytest.mark.slow
@pytest.mark.timeout(120)
def test_every_fault_kind_counted_and_no_valid_frame_lost(tmp_path: Path) -> None:
    journal = tmp_path / "faults.spj"
    with sim_pty(tmp_path, seed=3, faults=SCHEDULE) as sim:
        result = run_cli(*record_args(sim.path, journal, RECORD_S), "--json", timeout=90)
        assert result.returncode == 0, result.stderr
        assert "Traceback" not in result.stderr
        assert sim.stop() == 0
    log = sim.fault_log()
    truth = sim.truth()
    check_fault_matrix(journal, log, truth, SCHEDULE)
