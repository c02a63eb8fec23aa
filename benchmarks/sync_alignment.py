"""Session-time alignment of a whole recording against the simulators' truth.

Unlike benchmarks/clock_alignment.py (synthetic arrays), every scenario here runs the
real simulators as processes on pseudo-terminals: two SELSPOT systems (A and B, 1
camera x 8 LEDs at 100 Hz) and the timer (inputs 0 and 1 wired to their frame pulses,
+30 ppm, offset 1000 s), recorded together with ``spotlab record``, then timed with
``spotlab export --timestamps``. For each scenario one JSON line: the alignment error
of every frame's session time against its true instant after ONE affine map fitted over
all streams (max and RMS, µs, per stream and overall), the drift and events reported.

Scenarios: drift +-500 ppm; large offsets; a +1 ms and a -5 ms step halfway; the 32-bit
µs counter wrapping during the recording; trigger jitter of 20 µs RMS on both systems;
no timer (host arrival stamps only, the fallback).

Usage: ``python benchmarks/sync_alignment.py [--seconds 10] [--scenario NAME ...]``
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

CLI = (sys.executable, "-m", "spotlab.console.cli")
RATE = 100
LEAD_S = 3.0  # power-up of the simulators to the start of recording, about


def scenarios(seconds: float) -> dict[str, dict[str, list[object]]]:
    half = LEAD_S + seconds / 2
    return {
        "drift+-500": {"a": ["--clock-drift-ppm", 500], "b": ["--clock-drift-ppm", -500]},
        "offsets": {
            "a": ["--clock-offset", 0.001, "--clock-drift-ppm", 200],
            "b": ["--clock-offset", 3600.5, "--clock-drift-ppm", -150],
        },
        "steps": {
            "a": ["--clock-drift-ppm", 200, "--clock-step", f"{half}:0.001"],
            "b": ["--clock-drift-ppm", -150, "--clock-step", f"{half}:-0.005"],
        },
        "wrap32": {
            # 2**32 µs = 4294.967296 s: the counter wraps about 2 s into the recording
            "a": ["--clock-offset", 4294.967296 - LEAD_S - 2.0, "--clock-drift-ppm", 300],
            "b": ["--clock-drift-ppm", -150],
        },
        "trigger-jitter": {
            "a": ["--clock-drift-ppm", 200, "--clock-jitter", 20e-6],
            "b": ["--clock-drift-ppm", -150, "--clock-jitter", 20e-6],
        },
        "no-timer": {
            "a": ["--clock-drift-ppm", 200],
            "b": ["--clock-drift-ppm", -150],
            "timer": ["off"],
        },
    }


def first_line(path: Path, proc: subprocess.Popen[bytes]) -> str:
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        text = path.read_bytes()
        if b"\n" in text:
            return text.split(b"\n", 1)[0].decode()
        if proc.poll() is not None:
            break
        time.sleep(0.02)
    raise RuntimeError(f"simulator printed no device path: {path}")


def run_scenario(folder: Path, seconds: float, extra: dict[str, list[object]]) -> dict[str, Any]:
    lab = folder / "lab"
    common: list[object] = ["--cameras", 1, "--leds", 8, "--rate", RATE, "--lab", lab]
    args: dict[str, list[object]] = {
        "a": ["sim", "selspot", "--pty", *common, "--seed", 1, "--lab-name", "sysA"],
        "b": ["sim", "selspot", "--pty", *common, "--seed", 2, "--lab-name", "sysB"],
    }
    with_timer = extra.get("timer") != ["off"]
    if with_timer:
        args["t"] = ["sim", "timer", "--pty", "--rate", RATE, "--input", "0=sysA",
                     "--input", "1=sysB", "--lab", lab, "--clock-offset", 1000,
                     "--clock-drift-ppm", 30]  # fmt: skip
    procs: dict[str, subprocess.Popen[bytes]] = {}
    ports: dict[str, str] = {}
    try:
        for key, a in args.items():
            full = [*CLI, *map(str, a), *map(str, extra.get(key, [])),
                    "--truth", str(folder / f"{key}.csv")]  # fmt: skip
            with open(folder / f"{key}.out", "wb") as out, open(folder / f"{key}.err", "wb") as e:
                procs[key] = subprocess.Popen(full, stdout=out, stderr=e, stdin=subprocess.DEVNULL)
        for key, p in procs.items():
            ports[key] = first_line(folder / f"{key}.out", p)
        devices = [f"selspot={ports['a']}", f"selspot={ports['b']}"]
        if with_timer:
            devices.insert(0, f"timer={ports['t']}")
        rec = folder / "rec.spj"
        subprocess.run(
            [*CLI, "record", *[x for d in devices for x in ("--device", d)], "--cameras", "1",
             "--leds", "8", "--rate", str(RATE), "--seconds", str(seconds), "--out", str(rec)],
            check=True, capture_output=True, timeout=seconds + 60,
        )  # fmt: skip
    finally:
        for p in procs.values():
            p.terminate()
            p.wait(timeout=15)
    ts, rep = folder / "ts.csv", folder / "sync.json"
    wiring = ["--wiring", "selspot0=0", "--wiring", "selspot1=1"] if with_timer else []
    subprocess.run(
        [*CLI, "export", str(rec), "--timestamps", str(ts), "--sync-report", str(rep), *wiring],
        check=True,
        capture_output=True,
        timeout=120,
    )
    return evaluate(folder, ts, json.loads(rep.read_text()), with_timer)


def evaluate(folder: Path, ts: Path, report: dict[str, Any], with_timer: bool) -> dict[str, Any]:
    truth_files = {"selspot0": "a", "selspot1": "b", "timer": "t"}
    rows: dict[str, list[dict[str, str]]] = {}
    with open(ts, newline="") as fh:
        for r in csv.DictReader(fh):
            rows.setdefault(r["stream"], []).append(r)
    t_all, s_all, who = [], [], []
    for name, rs in rows.items():
        div = 10 if name == "timer" else 1
        with open(folder / f"{truth_files[name]}.csv", newline="") as fh:
            truth = {
                (int(r["seq"]), int(r["device_tick"]) % 2**32): float(r["true_time_s"])
                for r in csv.DictReader(fh)
                if r["sent"] == "1"
            }
        t = np.array(
            [truth.get((int(r["seq"]) % 65536, int(r["device_ticks"]) // div % 2**32), np.nan)
             for r in rs]
        )  # fmt: skip
        s = np.array([float(r["time_s"]) for r in rs])
        ok = np.isfinite(t) & np.isfinite(s)
        t_all.append(t[ok])
        s_all.append(s[ok])
        who += [name] * int(ok.sum())
    t = np.concatenate(t_all)
    s = np.concatenate(s_all)
    a = np.c_[t - t.mean(), np.ones_like(t)]
    res = s - a @ np.linalg.lstsq(a, s, rcond=None)[0]
    names = np.array(who)
    per = {}
    for name in rows:
        r = res[names == name] * 1e6
        per[name] = {"frames": int(r.size), "max_us": float(np.max(np.abs(r))),
                     "rms_us": float(np.sqrt(np.mean(r**2)))}  # fmt: skip
    streams = {s["stream"]: s for s in report["streams"]}
    return {
        "reference": report["reference"],
        "max_us": float(np.max(np.abs(res)) * 1e6),
        "rms_us": float(np.sqrt(np.mean(res**2)) * 1e6),
        "streams": per,
        "drift_ppm": {n: round(v.get("drift_ppm", 0.0), 3) for n, v in streams.items()},
        "events": {
            n: [(e["kind"], round(e["size_s"] * 1e3, 4)) for e in v["events"]]
            for n, v in streams.items()
            if v["events"]
        },
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else "")
    p.add_argument("--seconds", type=float, default=10.0, help="recording length per scenario")
    p.add_argument("--scenario", action="append", help="run only these (repeat)")
    args = p.parse_args(argv)
    table = scenarios(args.seconds)
    for name in args.scenario or list(table):
        with tempfile.TemporaryDirectory(prefix="sync-bench-") as tmp:
            t0 = time.perf_counter()
            row = run_scenario(Path(tmp), args.seconds, table[name])
            row = {"benchmark": "sync_alignment", "scenario": name, "seconds": args.seconds,
                   **row, "wall_s": round(time.perf_counter() - t0, 1)}  # fmt: skip
            print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
