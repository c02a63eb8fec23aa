"""``spotlab bench`` against a SELSPOT simulator on a real pty, as a bench engineer runs it.

A clean simulator passes the conformance suite and gets its report (JSON, HTML, a
PNG of plots); one with a bitflip fault fails, and the failure names the test and
its reason, and the comparison with a baseline names the test that passed there.
"""

from __future__ import annotations

import json
from pathlib import Path

from _e2e import run_cli, sim_pty

BENCH = ("--driver", "selspot", "--cameras", 4, "--leds", 32, "--rate", 200)


def test_bench_passes_a_clean_simulator_and_writes_its_report(tmp_path: Path) -> None:
    report = tmp_path / "report"
    with sim_pty(tmp_path, seed=3) as sim:
        result = run_cli("bench", sim.path, *BENCH, "--seconds", 2, "--report", report, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "verdict pass" in result.stdout
    data = json.loads((report / "report.json").read_text())
    assert data["verdict"] == "pass" and not data["failures"]
    (device,) = data["devices"]
    names = {t["name"] for t in device["conformance"]}
    assert "test_driver_streams_every_frame_in_order" in names
    assert "test_bad_led_tables_are_error_81" in names  # the SPX tests, not only MCS-1's
    assert all(t["outcome"] == "passed" for t in device["conformance"])
    figures = device["figures"]
    assert abs(figures["rate_hz"] - 200.0) < 5.0
    assert figures["lost_frames"] == 0 and figures["crc_errors"] == 0
    assert 0 < figures["latency_p50_us"] <= figures["latency_p99_us"] <= figures["latency_max_us"]
    assert 0 < figures["line_use"] < 1
    assert (report / "selspot.png").stat().st_size > 1000
    assert "selspot.png" in (report / "report.html").read_text()


def test_bench_fails_a_simulator_that_breaks_conformance_and_names_the_test(
    tmp_path: Path,
) -> None:
    report = tmp_path / "faulty"
    baseline = tmp_path / "baseline.json"
    test = "test_driver_streams_every_frame_in_order"
    passed = {"name": test, "outcome": "passed", "reason": "", "seconds": 1.0}
    figures = {"lost_frames": 0, "crc_errors": 0, "latency_p50_us": 1e6}
    baseline.write_text(json.dumps(
        {"devices": [{"stream": "selspot", "conformance": [passed], "figures": figures}]}
    ))  # fmt: skip
    # The first START: anchors the schedule: the conformance stream gets a flipped bit.
    with sim_pty(tmp_path, seed=3, faults="bitflip@0.2") as sim:
        result = run_cli(
            "bench", sim.path, *BENCH, "--seconds", 1, "--report", report, "-k", "streams",
            "--baseline", baseline, timeout=120,
        )  # fmt: skip
    assert result.returncode == 1, result.stdout + result.stderr
    failed = [line for line in result.stdout.splitlines() if line.startswith("FAILED")]
    assert any(f"selspot: {test}: AssertionError" in line for line in failed), failed
    data = json.loads((report / "report.json").read_text())
    assert data["verdict"] == "fail"
    regressions = {r["figure"] for r in data["regressions"]}
    assert regressions == {f"conformance:{test}"}, regressions  # the stream after it is clean
