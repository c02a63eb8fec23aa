"""Two SELSPOT systems and a timer recorded together, then put on one session time base.

Issue 5, done when: two simulated systems with different clock offsets and drifts of
+200 and -150 ppm, plus the timer (its inputs wired to both systems' frame pulses, with
its own offset and drift), recorded together; ``spotlab export REC --timestamps`` gives
every frame a session time within 50 µs of the simulators' truth up to one common
affine map; with a clock step injected halfway in one system, the same holds on both
sides of the step and the step is reported. Bad input (a clock jumping backwards, a
stalled stream, a timer that stops, a device missing) is reported and leaves the other
streams' times right.

Every simulator and the recorder run as separate ``spotlab`` processes on real
pseudo-terminals (the lab folder wires the frame pulses). The 60 s run of the issue is
marked ``slow``; the same checks run on 8-10 s recordings in the normal suite.
"""

from __future__ import annotations

import csv
import json
import subprocess
from collections.abc import Iterator, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest
from _e2e import _first_line as first_line
from _e2e import run_cli, spawn_cli, stop_process

TOLERANCE_S = 50e-6
RATE = 100
F64 = npt.NDArray[np.float64]


@dataclass
class Lab:
    """A finished recording of the lab and where the truth files are."""

    journal: Path
    truth: dict[str, Path]  # stream name -> truth CSV
    record: subprocess.CompletedProcess[str]


@contextmanager
def _procs() -> Iterator[list[subprocess.Popen[bytes]]]:
    procs: list[subprocess.Popen[bytes]] = []
    try:
        yield procs
    finally:
        for p in reversed(procs):
            stop_process(p)


def run_lab(
    folder: Path,
    seconds: float,
    *,
    extra_a: Sequence[object] = (),
    extra_b: Sequence[object] = (),
    extra_timer: Sequence[object] = (),
    with_timer: bool = True,
) -> Lab:
    """Start system A (+200 ppm), system B (-150 ppm) and the timer (inputs 0 = A, 1 = B),
    record them together for ``seconds``, stop everything; return the journal."""
    lab = folder / "lab"
    common = ["--cameras", 1, "--leds", 8, "--rate", RATE, "--lab", lab]
    sims = {
        "a": ["sim", "selspot", "--pty", *common, "--seed", 1, "--lab-name", "sysA",
              "--clock-offset", 3.25, "--clock-drift-ppm", 200, *extra_a],
        "b": ["sim", "selspot", "--pty", *common, "--seed", 2, "--lab-name", "sysB",
              "--clock-offset", 41.5, "--clock-drift-ppm", -150, *extra_b],
    }  # fmt: skip
    if with_timer:
        sims["t"] = [
            "sim", "timer", "--pty", "--rate", RATE, "--input", "0=sysA", "--input", "1=sysB",
            "--lab", lab, "--seed", 3, "--clock-offset", 1000, "--clock-drift-ppm", 30,
            *extra_timer,
        ]  # fmt: skip
    truth = {k: folder / f"{k}-truth.csv" for k in sims}
    journal = folder / "rec.spj"
    with ExitStack() as stack:
        procs = stack.enter_context(_procs())
        outs = {}
        for key, args in sims.items():
            out, err = folder / f"{key}.stdout", folder / f"{key}.stderr"
            procs.append(spawn_cli([*args, "--truth", truth[key]], out, err))
            outs[key] = (out, procs[-1], err)
        ports = {k: first_line(*v, timeout=30.0) for k, v in outs.items()}
        devices = [f"selspot={ports['a']}", f"selspot={ports['b']}"]
        if with_timer:
            devices.insert(0, f"timer={ports['t']}")
        result = run_cli(
            "record", *[x for d in devices for x in ("--device", d)], "--cameras", 1,
            "--leds", 8, "--rate", RATE, "--seconds", seconds, "--out", journal, "--json",
            timeout=seconds + 60,
        )  # fmt: skip
    names = {"t": "timer", "a": "selspot0", "b": "selspot1"}
    return Lab(journal, {names[k]: v for k, v in truth.items()}, result)


def export(lab: Lab, folder: Path, *extra: str) -> tuple[dict[str, list[dict[str, str]]], dict]:
    """``spotlab export REC --timestamps --sync-report``: rows per stream and the report."""
    ts, rep = folder / "ts.csv", folder / "sync.json"
    result = run_cli(
        "export", lab.journal, "--timestamps", ts, "--sync-report", rep, *extra, timeout=60
    )
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    rows: dict[str, list[dict[str, str]]] = {}
    with open(ts, newline="") as fh:
        for row in csv.DictReader(fh):
            rows.setdefault(row["stream"], []).append(row)
    report = json.loads(rep.read_text())
    report["stderr"] = result.stderr
    return rows, report


def true_times(lab: Lab, stream: str, rows: list[dict[str, str]]) -> F64:
    """True instant of each exported frame, matched by its 16-bit seq and its device tick
    (seq alone repeats after a restart, the tick after a clock jumping back)."""
    div = 10 if stream == "timer" else 1  # the timer's truth counts µs, its frames 100 ns
    with open(lab.truth[stream], newline="") as fh:
        truth = {
            (int(r["seq"]), int(r["device_tick"]) % 2**32): float(r["true_time_s"])
            for r in csv.DictReader(fh)
            if r["sent"] == "1"
        }
    return np.array(
        [
            truth.get((int(r["seq"]) % 65536, int(r["device_ticks"]) // div % 2**32), np.nan)
            for r in rows
        ]
    )


def affine_residuals(
    lab: Lab, rows: dict[str, list[dict[str, str]]], streams: Sequence[str], keep: str = ""
) -> dict[str, F64]:
    """Residuals of session time against truth after ONE affine map fitted over all
    ``streams`` together (frames whose method is in ``keep``, comma list; all if empty)."""
    t_all, s_all, names = [], [], []
    for name in streams:
        sel = [r for r in rows[name] if not keep or r["method"] in keep.split(",")]
        t = true_times(lab, name, sel)
        s = np.array([float(r["time_s"]) for r in sel])
        ok = np.isfinite(t) & np.isfinite(s)
        assert ok.sum() > 0.9 * len(sel) and ok.sum() > 100, (name, ok.sum(), len(sel))
        t_all.append(t[ok])
        s_all.append(s[ok])
        names += [name] * int(ok.sum())
    t = np.concatenate(t_all)
    s = np.concatenate(s_all)
    a = np.c_[t - t.mean(), np.ones_like(t)]
    coef = np.linalg.lstsq(a, s, rcond=None)[0]
    res = s - a @ coef
    who = np.array(names)
    return {n: res[who == n] for n in streams}


def check_lab(lab: Lab, folder: Path, seconds: float) -> None:
    assert lab.record.returncode == 0, lab.record.stderr
    rows, report = export(lab, folder, "--wiring", "selspot0=0", "--wiring", "selspot1=1")
    assert set(rows) == {"timer", "selspot0", "selspot1"}
    assert len(rows["selspot0"]) > 0.8 * seconds * RATE
    res = affine_residuals(lab, rows, ["timer", "selspot0", "selspot1"])
    for name, r in res.items():
        assert np.max(np.abs(r)) < TOLERANCE_S, (name, np.max(np.abs(r)))
    by = {s["stream"]: s for s in report["streams"]}
    # drift relative to the timer (+30 ppm): about +170 and -180 ppm
    assert abs(by["selspot0"]["drift_ppm"] - 170) < 5, by["selspot0"]
    assert abs(by["selspot1"]["drift_ppm"] + 180) < 5, by["selspot1"]
    # the step of system A, reported with its size, frames on both sides within tolerance
    steps = [e for e in by["selspot0"]["events"] if e["kind"] == "step"]
    assert len(steps) == 1 and abs(steps[0]["size_s"] - 2.5e-3) < 5e-6, by["selspot0"]
    assert by["selspot1"]["events"] == []
    assert "clock step of +2.500 ms" in report["stderr"]
    ticks = np.array([int(r["device_ticks"]) for r in rows["selspot0"]])
    before = ticks < steps[0]["at_tick"]
    assert 0.2 < before.mean() < 0.8
    assert np.max(np.abs(res["selspot0"])) < TOLERANCE_S


def _step_args(seconds: float) -> list[object]:
    # power-up to the start of recording: about 2-4 s (three processes start at once)
    return ["--clock-step", f"{3.0 + seconds / 2}:0.0025"]


@pytest.mark.timeout(60)
def test_two_systems_and_timer_10s_within_50us_and_step_reported(tmp_path: Path) -> None:
    seconds = 10.0
    lab = run_lab(tmp_path, seconds, extra_a=_step_args(seconds))
    check_lab(lab, tmp_path, seconds)


@pytest.mark.long
@pytest.mark.timeout(200)
def test_two_systems_and_timer_60s_within_50us_and_step_reported(tmp_path: Path) -> None:
    seconds = 60.0
    lab = run_lab(tmp_path, seconds, extra_a=_step_args(seconds))
    check_lab(lab, tmp_path, seconds)


# make long: make test keeps to 10 minutes on 2 cores (the clock faults are also
# in tests/unit/acquisition/clocks/test_edges.py and test_dejitter.py, in process).
@pytest.mark.long
@pytest.mark.timeout(60)
def test_clock_backwards_and_stalled_stream_reported_others_unharmed(tmp_path: Path) -> None:
    """System A's clock jumps back 0.5 s; system B's port vanishes for 1 s (stall)."""
    lab = run_lab(
        tmp_path,
        8.0,
        extra_a=["--clock-step", "6.5:-0.5"],
        extra_b=["--faults", "disconnect@2.5:1.0"],
    )
    rows, report = export(lab, tmp_path, "--wiring", "selspot0=0", "--wiring", "selspot1=1")
    by = {s["stream"]: s for s in report["streams"]}
    assert [e["kind"] for e in by["selspot0"]["events"]] == ["reset"], by["selspot0"]
    assert abs(by["selspot0"]["events"][0]["size_s"] + 0.5) < 1e-3
    assert "clock reset of -500.000 ms" in report["stderr"]
    # the stall: B's frames stop for about 1 s, then go on
    tb = np.array([float(r["time_s"]) for r in rows["selspot1"]])
    assert np.max(np.diff(tb)) > 0.5
    res = affine_residuals(lab, rows, ["timer", "selspot0", "selspot1"])
    for name, r in res.items():
        assert np.max(np.abs(r)) < TOLERANCE_S, (name, np.max(np.abs(r)))
    # spotlab replay decodes it again and reports the same clocks
    out = run_cli(
        "replay", lab.journal, "--json", "--wiring", "selspot0=0", "--wiring", "selspot1=1"
    )
    assert out.returncode == 0, out.stderr
    replayed = json.loads(out.stdout)
    assert {s["name"] for s in replayed["streams"]} == {"timer", "selspot0", "selspot1"}
    sync = {s["stream"]: s for s in replayed["sync"]["streams"]}
    assert [e["kind"] for e in sync["selspot0"]["events"]] == ["reset"]
    assert replayed["session_span"]["timer"]["first_s"] == 0.0


# make long: make test keeps to 10 minutes on 2 cores (the clock faults are also
# in tests/unit/acquisition/clocks/test_edges.py and test_dejitter.py, in process).
@pytest.mark.long
@pytest.mark.timeout(60)
def test_timer_stopping_is_reported_times_before_it_unharmed(tmp_path: Path) -> None:
    lab = run_lab(tmp_path, 8.0, extra_timer=["--seconds", 6])
    rows, report = export(lab, tmp_path, "--wiring", "selspot0=0", "--wiring", "selspot1=1")
    assert "spotlab: warning: the timer stopped" in report["stderr"]
    assert any("timer stopped" in n for n in report["notes"])
    for name in ("selspot0", "selspot1"):
        methods = [r["method"] for r in rows[name]]
        assert methods.count("extrapolated") > RATE, name  # frames after the timer stopped
    res = affine_residuals(lab, rows, ["timer", "selspot0", "selspot1"], keep="edge,reference")
    for name, r in res.items():
        assert np.max(np.abs(r)) < TOLERANCE_S, (name, np.max(np.abs(r)))


@pytest.mark.timeout(60)
def test_recording_without_timer_or_wired_device_is_reported(tmp_path: Path) -> None:
    lab = run_lab(tmp_path, 3.0, with_timer=False)
    assert lab.record.returncode == 0, lab.record.stderr
    rows, report = export(lab, tmp_path, "--wiring", "selspot9=0")
    assert report["reference"] == "host"
    assert "no timer stream in the recording" in report["stderr"]
    assert "selspot9 ignored: no timer" in report["stderr"]
    assert set(rows) == {"selspot0", "selspot1"}
    assert {r["method"] for r in rows["selspot0"]} == {"arrivals"}
    # arrival times still order the frames and keep the rate
    t = np.array([float(r["time_s"]) for r in rows["selspot0"]])
    assert np.all(np.diff(t) > 0)
    assert abs(np.median(np.diff(t)) - 1 / RATE) < 1e-4
