"""``spotlab hil``: a scenario run end to end, Ctrl-C in the middle, and bad input.

The shipped scenarios (gait lab, fault storm, ...) take 20-60 s each: they run in
``make hil`` (``pytest --hil``), not here. Here a 3 s scenario of one SELSPOT
system runs through every stage (simulator process, ``spotlab record``,
reconstruction and C3D export, scoring against the truth, JSON, JUnit and HTML).
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest
from _e2e import run_cli, spawn_cli, stop_process

from spotlab.console.cli import main

SCENARIO = """\
name = "one system"
description = "one SELSPOT system with link faults, reconstructed and exported"
duration = {duration}
seed = 3

[motion]
kind = "wand"

[[device]]
family = "selspot"
name = "selspot0"
rate = 200
cameras = 4
leds = 32
[device.sim]
faults = "bitflip@1,drop@1.5,duplicate@2"
reflectance = 0.0                 # a dark floor (docs/simulators.md)

[processing]
steps = ["reconstruction", "export"]

[criteria]
error_3d_rms_mm = {{ max = 3.0 }}
record_exit_code = {{ max = 0 }}
[criteria.selspot0]
frames_missing = {{ max = 0 }}
duplicates = {{ min = 1, max = 1 }}
frames = {{ min = 1 }}
"""


def _scenario(folder: Path, duration: float, extra: str = "") -> Path:
    path = folder / "one.toml"
    path.write_text(SCENARIO.format(duration=duration) + extra)
    return path


def test_hil_list_names_the_shipped_scenarios() -> None:
    result = run_cli("hil", "list", "--json")
    assert result.returncode == 0, result.stderr
    names = {row["name"] for row in json.loads(result.stdout)}
    assert {"gait-lab", "fault-storm"} <= names


def test_a_scenario_runs_and_is_scored_against_the_truth(tmp_path: Path) -> None:
    report, junit = tmp_path / "report", tmp_path / "ci.xml"
    result = run_cli(
        "hil", "run", _scenario(tmp_path, 2.0), "--report", report, "--junit", junit,
        timeout=120,
    )  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr
    assert "verdict pass" in result.stdout
    summary = json.loads((report / "summary.json").read_text())
    assert summary["verdict"] == "pass" and summary["problem"] is None
    device = summary["devices"]["selspot0"]
    assert device["faults_injected"] == 3 and device["crc_errors"] >= 1
    assert summary["run"]["error_3d_rms_mm"] < 3.0
    assert (report / "one.c3d").stat().st_size > 0
    suite = ET.parse(junit).getroot()
    assert suite.get("tests") == "5" and suite.get("failures") == "0"
    assert "selspot0.duplicates" in (report / "report.html").read_text()


def test_ctrl_c_stops_every_simulator_and_keeps_a_partial_report(tmp_path: Path) -> None:
    report = tmp_path / "report"
    out, err = tmp_path / "hil.stdout", tmp_path / "hil.stderr"
    proc = spawn_cli(["hil", "run", _scenario(tmp_path, 60.0), "--report", report], out, err)
    try:
        deadline = time.monotonic() + 60
        while b"recording" not in err.read_bytes() and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.5)
        proc.send_signal(signal.SIGINT)
        code = proc.wait(timeout=60)
    finally:
        stop_process(proc)
    assert code == 130, err.read_text()
    summary = json.loads((report / "summary.json").read_text())
    assert summary["verdict"] == "fail" and "interrupted" in summary["problem"]
    for pid in summary["run"]["simulator_pids"].values():
        assert (
            not Path(f"/proc/{pid}").exists()
            or "zombie" in Path(f"/proc/{pid}/status").read_text().lower()
        ), pid
    assert (report / "junit.xml").is_file() and (report / "report.html").is_file()


@pytest.mark.long
def test_ctrl_c_while_calibrating_stops_its_simulator_and_recorder(tmp_path: Path) -> None:
    """The lab's preparation runs commands of its own: Ctrl-C stops them too."""
    report = tmp_path / "report"
    path = _scenario(tmp_path, 3.0)
    text = path.read_text().replace('"reconstruction", "export"', '"calibration", "reconstruction"')
    path.write_text(text)
    out, err = tmp_path / "hil.stdout", tmp_path / "hil.stderr"
    proc = spawn_cli(["hil", "run", path, "--report", report], out, err)
    try:
        deadline = time.monotonic() + 60
        while b"calibrating" not in err.read_bytes() and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(3.0)  # the wand's simulator and recorder are running
        children = subprocess.run(["pgrep", "-P", str(proc.pid)], capture_output=True, text=True)
        pids = [int(p) for p in children.stdout.split()]
        proc.send_signal(signal.SIGINT)
        code = proc.wait(timeout=60)
    finally:
        stop_process(proc)
    assert code == 130, err.read_text()
    assert pids, "no simulator or recorder was running"
    for pid in pids:
        status = Path(f"/proc/{pid}/status")
        assert not status.exists() or "zombie" in status.read_text().lower(), pid
    summary = json.loads((report / "summary.json").read_text())
    assert summary["verdict"] == "fail" and "interrupted" in summary["problem"]
    assert (report / "prepare" / "selspot0.wand.sim.stdout").is_file()


def _one_error_in_process(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """``spotlab ARGV`` in this process: non-zero, one ``spotlab: error:`` line, returned."""
    code = main(argv)
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("spotlab: error:")]
    assert code != 0 and len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_a_busy_port_and_an_unknown_key_are_one_line_naming_file_line_and_key(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        path = tmp_path / "busy.toml"
        path.write_text(
            'duration = 3\n\n[[device]]\nfamily = "selspot"\nname = "a"\n\n'
            f'[[device]]\nfamily = "qualisys"\nname = "qtm"\n[device.sim]\nport = {port}\n'
        )
        line = _one_error_in_process(
            ["hil", "run", str(path), "--report", str(tmp_path / "r1")], capsys
        )
    assert f"{path}:11: device[1].sim.port: port {port} on 127.0.0.1 is busy" in line, line
    bad = _scenario(tmp_path, 3.0).read_text().replace("leds = 32", "leds = 32\nlenses = 2")
    path = tmp_path / "one.toml"
    path.write_text(bad)
    line = _one_error_in_process(["hil", "run", str(path)], capsys)
    assert f"{path}:15: device[0].lenses: unknown key" in line, line
    assert not (tmp_path / "r1").exists()  # refused before any output
    assert "hil-one" not in os.listdir(Path.cwd())


def test_a_device_that_cannot_start_is_one_line_naming_file_line_and_device(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "nostart.toml"
    path.write_text(
        'duration = 3\n\n[[device]]\nfamily = "selspot"\nname = "a"\n'
        '[device.sim]\nfaults = "explode@1"\n'
    )
    line = _one_error_in_process(["hil", "run", str(path), "--report", str(tmp_path / "r")], capsys)
    assert f"{path}:3: device[0]: the selspot simulator did not start: --faults" in line, line
    assert "unknown kind 'explode'" in line, line


def test_pytest_hil_collects_scenarios_by_name_and_folder_and_nothing_else(
    tmp_path: Path,
) -> None:
    _scenario(tmp_path, 3.0)
    result = subprocess.run(
        [sys.executable, "-m", "pytest", "--hil", "gait-lab", "--hil", str(tmp_path),
         "--collect-only", "-q", "-p", "no:randomly"],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr
    collected = [line for line in result.stdout.splitlines() if "::" in line]
    assert len(collected) == 2, result.stdout
    assert any(line.endswith("::gait-lab") for line in collected), collected
    assert any(line.endswith("one.toml::one") for line in collected), collected
