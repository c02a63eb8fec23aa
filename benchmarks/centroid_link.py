"""A clean CEN link through a real pseudo-terminal: what is lost at 1x and 2x the data rate.

Starts ``spotlab sim centroid --pty`` and ``spotlab record`` as separate processes
(as a lab runs them), records ``--seconds`` and prints one JSON object per line
and configuration: frames recorded, frames lost on the link, frames the hub's
FIFO dropped (whole frames, flagged), CRC errors, resynchronisations, reconnects,
the data rate, the CPU time the simulator and the recorder each used per second
recorded (cores), and the machine's load average over the run. No fault is injected:
a clean link loses nothing on the wire; a host that falls behind sees only whole
frames dropped by the device (flow control, docs/protocols/mcs1.md §4).

The default configurations are the family's largest of the issue (8 cameras x 40
markers at 300 Hz) and twice its data rate (the same at 600 Hz).

The line runs at the driver's default rate (24 Mbaud) unless ``--baud`` says otherwise.

Usage: ``python benchmarks/centroid_link.py [--seconds 20] [--configs 300 600] [--repeats 1]
[--baud 12000000]``
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _spotlab(*args: object) -> list[str]:
    return [sys.executable, "-m", "spotlab.console.cli", *map(str, args)]


def _children_cpu_s() -> float:
    """User + system CPU seconds of this process's finished children."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _proc_cpu_s(pid: int) -> float:
    """User + system CPU seconds of a running process (Linux ``/proc``)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def run_once(
    rate: float, seconds: float, cameras: int, markers: int, baud: int | None = None
) -> dict[str, object]:
    """One recording of a clean simulated hub; its live link statistics."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "sim.out"
        with out.open("w") as stdout:
            sim = subprocess.Popen(
                _spotlab("sim", "centroid", "--pty", "--cameras", cameras, "--markers", markers,
                         "--rate", rate, "--seed", 3),
                stdout=stdout, stderr=subprocess.DEVNULL,
            )  # fmt: skip
        try:
            deadline = time.monotonic() + 30
            while not out.read_text().strip() and time.monotonic() < deadline:
                time.sleep(0.05)
            port = out.read_text().split()[0]
            load0 = os.getloadavg()[0]
            cpu0 = _children_cpu_s()
            sim_cpu0 = _proc_cpu_s(sim.pid)
            rec = subprocess.run(
                _spotlab("record", "--device", f"centroid={port}", "--cameras", cameras,
                         "--rate", rate, "--seconds", seconds, "--out", Path(tmp) / "run.spj",
                         "--json", *(["--baud", baud] if baud else [])),
                capture_output=True, text=True, timeout=seconds + 60,
            )  # fmt: skip
            load1 = os.getloadavg()[0]
            sim_cpu = _proc_cpu_s(sim.pid) - sim_cpu0
            rec_cpu = _children_cpu_s() - cpu0
        finally:
            sim.terminate()
            try:
                sim.wait(timeout=60)
            except subprocess.TimeoutExpired:
                sim.kill()
                sim.wait()
    row: dict[str, object] = {
        "bench": "centroid_link", "baud": baud or "default", "cameras": cameras,
        "markers": markers, "rate_hz": rate,
        "seconds": seconds, "exit": rec.returncode, "load_1min": [load0, load1],
        "cpu_s_per_s": {"simulator": round(sim_cpu / seconds, 3),
                        "record": round(rec_cpu / seconds, 3)},
    }  # fmt: skip
    if rec.returncode != 0 or not rec.stdout.strip():
        row["error"] = rec.stderr.strip().splitlines()[-1:] or ["no output"]
        return row
    (stream,) = json.loads(rec.stdout)["streams"]
    for key in ("frames", "lost_frames", "device_dropped", "crc_errors", "resyncs", "reconnects"):
        row[key] = stream[key]
    row["data_rate_kB_s"] = round(stream["bytes"] / seconds / 1e3, 1)
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--configs", type=float, nargs="+", default=[300.0, 600.0],
                    help="frame rates (Hz) of 8 x 40 hubs")  # fmt: skip
    ap.add_argument("--cameras", type=int, default=8)
    ap.add_argument("--markers", type=int, default=40)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--baud", type=int, default=None, help="line rate (default: the driver's)")
    args = ap.parse_args()
    for _ in range(args.repeats):
        for rate in args.configs:
            print(
                json.dumps(run_once(rate, args.seconds, args.cameras, args.markers, args.baud)),
                flush=True,
            )


if __name__ == "__main__":
    main()
