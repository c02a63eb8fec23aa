"""A lab recorded as a lab records: several devices at their own rates, through real ptys.

Issue 12, done when: two SELSPOT systems at 200 and 150 Hz and a timer at 100 Hz, their
frame pulses wired to the timer, recorded together with one ``spotlab record --device
... --device ... --device ...`` line: every frame kept, and ``spotlab export REC
--timestamps`` (no ``--wiring``: the recording stores it) puts every frame within 50 µs
of the simulators' truth after one common affine map. The 30 s run of the issue is
marked ``slow``; the same checks run on an 8 s recording in the normal suite.

Also through real ptys: a lab file (devices, settings, wiring) recorded open-ended and
stopped with SIGTERM (exit 0, summary printed, the same counts as ``spotlab info``), a
device with no settings given keeping the rate it powered up with, ``spotlab devices``
listing the simulators' ports, and a wrong ``--driver`` naming the family that answered.
"""

from __future__ import annotations

import csv
import json
import signal
import time
from contextlib import ExitStack
from pathlib import Path

import numpy as np
import pytest
from _e2e import _first_line as first_line
from _e2e import assert_one_clear_error, info, run_cli, spawn_cli, stop_process
from test_e2e_sync import TOLERANCE_S, Lab, _procs, affine_residuals

RATES = {"selspot0": 200, "selspot1": 150, "timer": 100}


def _start_sims(
    folder: Path, procs: list, power_up_rate: float = 100.0
) -> tuple[dict[str, str], dict[str, Path]]:
    """System A (+200 ppm), system B (-150 ppm), the timer (inputs 0 = A, 1 = B); returns
    their ports and truth files by stream name."""
    lab = folder / "lab"
    common = ["--cameras", 1, "--leds", 8, "--rate", power_up_rate, "--lab", lab]
    sims = {
        "selspot0": ["sim", "selspot", "--pty", *common, "--seed", 1, "--lab-name", "sysA",
                     "--clock-offset", 3.25, "--clock-drift-ppm", 200],
        "selspot1": ["sim", "selspot", "--pty", *common, "--seed", 2, "--lab-name", "sysB",
                     "--clock-offset", 41.5, "--clock-drift-ppm", -150],
        "timer": ["sim", "timer", "--pty", "--input", "0=sysA", "--input", "1=sysB",
                  "--lab", lab, "--seed", 3, "--clock-offset", 1000, "--clock-drift-ppm", 30],
    }  # fmt: skip
    truth = {k: folder / f"{k}-truth.csv" for k in sims}
    outs = {}
    for key, args in sims.items():
        out, err = folder / f"{key}.stdout", folder / f"{key}.stderr"
        procs.append(spawn_cli([*args, "--truth", truth[key]], out, err))
        outs[key] = (out, procs[-1], err)
    ports = {k: first_line(*v, timeout=30.0) for k, v in outs.items()}
    return ports, truth


def _sent_frames(truth: Path) -> int:
    with open(truth, newline="") as fh:
        return sum(r["sent"] == "1" for r in csv.DictReader(fh))


def _timestamps(journal: Path, folder: Path) -> dict[str, list[dict[str, str]]]:
    """``spotlab export REC --timestamps`` with no ``--wiring``: rows per stream."""
    ts = folder / "ts.csv"
    result = run_cli("export", journal, "--timestamps", ts, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    rows: dict[str, list[dict[str, str]]] = {}
    with open(ts, newline="") as fh:
        for row in csv.DictReader(fh):
            rows.setdefault(row["stream"], []).append(row)
    return rows


def _check_every_frame_on_time(lab: Lab, folder: Path, seconds: float) -> None:
    assert lab.record.returncode == 0, lab.record.stderr
    summary = {s["name"]: s for s in info(lab.journal)["streams"]}
    rows = _timestamps(lab.journal, folder)
    assert set(rows) == set(RATES)
    for name, rate in RATES.items():
        s = summary[name]
        # every frame the device sent is in the journal, decoded and exported
        assert s["lost_frames"] == 0 and s["crc_errors"] == 0, s
        assert s["frames"] == _sent_frames(lab.truth[name]) == len(rows[name]), name
        assert s["rate_hz"] == pytest.approx(rate, rel=2e-3), s
        assert s["frames"] > 0.9 * seconds * rate, s
        # timestamps from the timer's edges (the stored wiring), not from arrival; the
        # frames after the timer stopped (it stops first) are extrapolated from them
        if name != "timer":
            methods = [r["method"] for r in rows[name]]
            assert set(methods) <= {"edge", "extrapolated"}, (name, set(methods))
            assert methods.count("edge") > 0.9 * len(methods), (name, set(methods))
    res = affine_residuals(lab, rows, list(RATES))
    for name, r in res.items():
        assert len(r) == len(rows[name])  # every frame matched to its truth
        assert np.max(np.abs(r)) < TOLERANCE_S, (name, np.max(np.abs(r)))


def run_multi_rate(folder: Path, seconds: float) -> Lab:
    with ExitStack() as stack:
        procs = stack.enter_context(_procs())
        ports, truth = _start_sims(folder, procs)
        journal = folder / "rec.spj"
        result = run_cli(
            "record",
            "--device", f"timer={ports['timer']},rate=100",
            "--device", f"selspot={ports['selspot0']},rate=200,cameras=1,leds=8",
            "--device", f"selspot={ports['selspot1']},rate=150,cameras=1,leds=8",
            "--wiring", "selspot0=0", "--wiring", "selspot1=1",
            "--seconds", seconds, "--out", journal,
            timeout=seconds + 60,
        )  # fmt: skip
    return Lab(journal, truth, result)


@pytest.mark.timeout(90)
def test_two_systems_at_200_and_150_hz_and_a_timer_at_100_hz_8s(tmp_path: Path) -> None:
    _check_every_frame_on_time(run_multi_rate(tmp_path, 8.0), tmp_path, 8.0)


@pytest.mark.long
@pytest.mark.timeout(180)
def test_two_systems_at_200_and_150_hz_and_a_timer_at_100_hz_30s(tmp_path: Path) -> None:
    _check_every_frame_on_time(run_multi_rate(tmp_path, 30.0), tmp_path, 30.0)


def _wait_for_frames(journal: Path, frames: int, timeout: float) -> None:
    """Poll ``spotlab info`` until every stream has ``frames`` frames (or give up)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if journal.exists():
            result = run_cli("info", journal, "--json")
            if result.returncode == 0:
                streams = json.loads(result.stdout)["streams"]
                if len(streams) == 2 and all(s.get("frames", 0) >= frames for s in streams):
                    return
        time.sleep(0.5)
    raise AssertionError(f"no {frames} frames in {journal} within {timeout} s")


@pytest.mark.timeout(120)
def test_lab_file_recorded_open_ended_and_stopped_by_sigterm(tmp_path: Path) -> None:
    """The lab file gives the timer's rate and the wiring, not system A's settings:
    A keeps the 200 Hz it powered up with."""
    with ExitStack() as stack:
        procs: list = stack.enter_context(_procs())
        ports, truth = _start_sims(tmp_path, procs, power_up_rate=200.0)
        devices = run_cli("devices", "--json")
        assert devices.returncode == 0, devices.stderr
        listed = {p["device"] for p in json.loads(devices.stdout)["serial_ports"]}
        assert {ports["selspot0"], ports["timer"]} <= listed
        lab = tmp_path / "lab.toml"
        lab.write_text(
            f'[[device]]\nfamily = "selspot"\nport = "{ports["selspot0"]}"\nleds = 8\n\n'
            f'[[device]]\nfamily = "timer"\nport = "{ports["timer"]}"\nrate = 100\n\n'
            "[wiring]\nselspot = 0\n"
        )
        journal = tmp_path / "rec"  # no suffix: a journal all the same
        out, err = tmp_path / "record.stdout", tmp_path / "record.stderr"
        rec = spawn_cli(["record", "--lab", lab, "--out", journal, "--json"], out, err)
        try:
            _wait_for_frames(journal, 300, timeout=60)
        finally:
            code = stop_process(rec, signal.SIGTERM)
        wrong = run_cli("record", "--driver", "timer", ports["selspot1"], "--seconds", 1,
                        "--out", tmp_path / "wrong.spj")  # fmt: skip
    assert code == 0, err.read_text()
    assert "error" not in err.read_text()
    result = json.loads(out.read_text())
    assert result["stopped_by"] == ["SIGTERM"]
    summary = {s["name"]: s for s in info(journal)["streams"]}
    keys = ("frames", "lost_frames", "crc_errors", "resyncs", "gaps")
    for s in result["streams"]:
        assert {k: s[k] for k in keys} == {k: summary[s["name"]][k] for k in keys}
    assert summary["selspot"]["lost_frames"] == 0
    assert summary["selspot"]["rate_hz"] == pytest.approx(200, rel=2e-3)
    assert summary["selspot"]["frames"] == _sent_frames(truth["selspot0"])
    rows = _timestamps(journal, tmp_path)
    methods = [r["method"] for r in rows["selspot"]]
    assert methods.count("edge") > 0.9 * len(methods), set(methods)
    assert_one_clear_error(wrong, "selspot device", "--driver selspot")
