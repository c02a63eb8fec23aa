"""``spotlab demo``: the whole job on the simulated system, its own checks all true."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from _e2e import info, run_cli


@pytest.mark.timeout(90)
def test_demo_runs_and_every_check_holds(tmp_path: Path) -> None:
    out = tmp_path / "demo"
    result = run_cli("demo", "--seconds", 2, "--out", out, "--json", timeout=80)
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    report = json.loads(result.stdout)
    assert report["checks"] and all(report["checks"].values()), report["checks"]
    assert report["recording"]["frames"] > 300
    # What it left opens with spotlab info and says the same.
    summary = info(Path(report["journal"]))
    assert summary["complete"]
    stream = summary["streams"][0]
    for key in ("frames", "lost_frames", "device_dropped", "duplicates", "crc_errors"):
        assert stream[key] == report["recording"][key], key
    # The recording reconstructed with the simulator's true rig and exported as C3D; the
    # floor's reflections bias PSD readings by tens of mm (docs/simulators.md).
    rec = report["reconstruction"]
    assert rec["markers_reconstructed"] > 0 and Path(rec["c3d"]).stat().st_size > 0
    assert rec["error_rms_mm"] < 100.0
