"""The lab console under load: does an open page cost the acquisition anything?

The issue's lab, each simulator a process of its own on a real pseudo-terminal
(``spotlab sim ... --pty``): a video-centroid hub of 8 cameras x 40 markers at 300 Hz and
a SELSPOT-style system of 2 cameras x 8 LEDs at 200 Hz (its true rig for the live 3-D).
Each round records one trial of ``--seconds`` twice, in turn:

* ``without``: the console's acquisition (``console.web.acquisition.Acquisition``: the
  same session, recorder, view sink and live pipeline) in a process of its own with no
  web server and no page: the live pipeline's host latency without the console;
* ``with``: ``spotlab console --lab`` with the page open in headless Chromium (Debian's
  ``chromium``, driven by Playwright) for the whole trial, the trial started and stopped
  through the API.

Each run prints one JSON line: the trial's frames and lost frames per stream (its
sidecar, from the journal); how far each device kept real time (``realtime``: the
device time its frames span over the trial's duration); the live pipeline's host
latency (p50, p99, mean µs, read just before the stop); with the page, the 3-D view's
update rate measured in the browser (new marker frames the page drew per second,
``window.spotlab.frames3d``, over the middle of the trial) and the live messages it
received per second; the machine's load average, the share of a core each simulator
process used over the run and the acquiring process over the trial (``host_cpu_share``:
the console, or the acquisition alone), and with the page, the share of a core all of
Chromium's processes used over the trial (``browser_cpu_share``: it draws the 3-D view
with a software renderer on this machine, beside the acquisition). A last line
(``summary``) gives the medians
over the rounds and the targets: no frame lost, the latency with the console within
10 % of the figure without, >= 30 updates a second. ``hub_in_real_time`` false means
the hub's simulator fell behind 300 Hz (a loaded machine starves it: it needs about a
third of a core at 300 Hz), so the run is not conclusive; the simulators' serving
threads ask for nice -10 (``SPOTLAB_SIM_NICE``, unless set) to keep them in time.

``--realtime PRIO`` runs both the same way as ``spotlab console --realtime PRIO``: the
sessions' threads and the main thread under ``SCHED_FIFO`` (needs root or CAP_SYS_NICE).

Usage: ``python benchmarks/console_load.py [--seconds 10] [--rounds 2] [--realtime 10]``.
A shared 2-core machine is noisy: the rounds alternate the two runs so that both see the same load.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path
from typing import Any

CLI = (sys.executable, "-m", "spotlab.console.cli")
CHROMIUM = "/usr/bin/chromium"
HUB_HZ, SPX_HZ = 300.0, 200.0


def _first_line(proc: subprocess.Popen[bytes], out: Path, timeout: float = 90.0) -> str:
    deadline = time.monotonic() + timeout
    while not out.read_text().endswith("\n"):
        if proc.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"{proc.args}: no first line")
        time.sleep(0.05)
    return out.read_text().splitlines()[0]


def _spawn(args: list[str], folder: Path, name: str) -> tuple[subprocess.Popen[bytes], str]:
    out = folder / f"{name}.out"
    with open(out, "wb") as o, open(folder / f"{name}.err", "wb") as e:
        proc = subprocess.Popen(args, stdout=o, stderr=e, stdin=subprocess.DEVNULL)
    return proc, _first_line(proc, out)


def _call(base: str, path: str, body: dict[str, Any] | None = None) -> Any:
    data = None if body is None else json.dumps(body).encode()
    request = urllib.request.Request(base + path, data=data, method="POST" if data else "GET")
    with urllib.request.urlopen(request, timeout=60) as response:
        return json.loads(response.read())


def _stop(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def _cpu_s(pid: int) -> float:
    """CPU time (user + system) a process used so far, s."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _browser_cpu_s() -> float:
    """CPU time all Chromium processes on the machine used so far, s."""
    total = 0.0
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            if "chromium" not in (entry / "cmdline").read_bytes().split(b"\0", 1)[0].decode():
                continue
            total += _cpu_s(int(entry.name))
        except (OSError, ValueError, IndexError):  # gone meanwhile
            continue
    return total


class Load:
    """The machine's load and the simulators' CPU share over one run."""

    def __init__(self, sims: dict[str, int]) -> None:
        self.sims = sims
        self.t0 = time.monotonic()
        self.cpu0 = {name: _cpu_s(pid) for name, pid in sims.items()}

    def result(self) -> dict[str, Any]:
        wall = time.monotonic() - self.t0
        return {
            "loadavg_1min": round(os.getloadavg()[0], 2),
            "sim_cpu_share": {
                name: round((_cpu_s(pid) - self.cpu0[name]) / wall, 3)
                for name, pid in self.sims.items()
            },
        }


def _latency(latency: dict[str, Any] | None) -> dict[str, Any]:
    if latency is None:
        return {"live_frames": 0, "live_p50_us": None, "live_p99_us": None, "live_mean_us": None}
    return {
        "live_frames": latency["frames"],
        "live_p50_us": round(latency["p50_us"], 1),
        "live_p99_us": round(latency["p99_us"], 1),
        "live_mean_us": round(latency["mean_us"], 1),
    }


def _trial(info: dict[str, Any], data: Path) -> dict[str, Any]:
    """The trial's figures; ``realtime``: per stream the device time its frames span
    (ticks) over the trial's duration (the session's, after the start-up dialogue): 1
    for a device that kept real time, below for a simulator that fell behind (above for
    one that started streaming before the others were up)."""
    from spotlab.acquisition.summary import summarize
    from spotlab.processing.decoding import decoder_for

    seconds = float(info["duration_s"] or 0.0)
    journal = data / info["subject"] / info["session"] / f"{info['trial']}.spj"
    spans = {
        s["name"]: s["duration_s"] for s in summarize(journal, decoder_for).to_dict()["streams"]
    }
    return {
        "seconds": seconds,
        "frames": info["frames"],
        "lost": info["lost"],
        "realtime": {k: round(v / seconds, 3) if seconds else None for k, v in spans.items()},
        "messages": info["messages"],
    }


# ---- without the console: the acquisition alone, in a child process ---------------------
def _headless(lab: Path, data: Path, seconds: float, realtime: int | None) -> int:
    """Record one trial with the console's acquisition and no web side; print JSON."""
    from spotlab.console.web.acquisition import Acquisition
    from spotlab.console.web.lab_setup import plan_lab
    from spotlab.console.web.trials import TrialInfo, TrialStore

    if realtime is not None:  # as spotlab console --realtime: the main thread too
        from spotlab.acquisition.realtime import raise_thread

        raise_thread(realtime)
    acq = Acquisition(plan_lab(lab, False, data), TrialStore(data), realtime_priority=realtime)
    acq.start()
    try:
        deadline = time.monotonic() + 60
        while not (rows := acq.devices()) or not all(d["connected"] for d in rows):
            if time.monotonic() > deadline:
                raise RuntimeError(f"devices did not connect: {rows}")
            time.sleep(0.2)
        acq.start_trial(TrialInfo("bench", "load", "without"))
        c0, t0 = time.process_time(), time.monotonic()
        time.sleep(seconds)
        latency = acq.live_latency()
        share = (time.process_time() - c0) / (time.monotonic() - t0)
        info = acq.stop_trial(timeout=60)
    finally:
        acq.close()
    out = {"latency": latency, "trial": info.to_dict(), "host_cpu_share": round(share, 3)}
    print(json.dumps(out), flush=True)
    return 0


def _run_without(
    lab: Path, folder: Path, seconds: float, n: int, sims: dict[str, int], realtime: int | None
) -> dict[str, Any]:
    data = folder / f"data-without-{n}"
    load = Load(sims)
    args = [sys.executable, __file__, "--headless", str(lab), str(data), str(seconds),
            "-" if realtime is None else str(realtime)]  # fmt: skip
    done = subprocess.run(args, capture_output=True, text=True, timeout=seconds + 180)
    if done.returncode != 0:
        raise RuntimeError(f"the acquisition alone failed: {done.stderr[-2000:]}")
    got = json.loads(done.stdout.splitlines()[-1])
    return {"bench": "console_load", "run": "without", "round": n,
            **_trial(got["trial"], data), **_latency(got["latency"]), **load.result(),
            "host_cpu_share": got["host_cpu_share"]}  # fmt: skip


# ---- with the console and its page in Chromium -------------------------------------------
def _run_with(
    lab: Path,
    folder: Path,
    seconds: float,
    n: int,
    browser: Any,
    sims: dict[str, int],
    realtime: int | None,
) -> dict[str, Any]:
    data = folder / f"data-with-{n}"
    load = Load(sims)
    proc, url = _spawn(
        [*CLI, "console", "--lab", str(lab), "--port", "0", "--no-browser", "--data", str(data)]
        + ([] if realtime is None else ["--realtime", str(realtime)]),
        folder,
        f"console-{n}",
    )
    base = url.rstrip("/")
    page = browser.new_page(viewport={"width": 1280, "height": 900})
    try:
        page.goto(url)
        page.wait_for_function(
            "document.querySelectorAll('#devices td.ok').length === 2", timeout=60_000
        )
        _call(base, "/api/trials/start", {"subject": "bench", "session": "load", "trial": "with"})
        page.wait_for_function("window.spotlab.status.mode === 'recording'", timeout=30_000)
        t0, c0, w0 = time.monotonic(), _cpu_s(proc.pid), _browser_cpu_s()
        # the page's updates over the middle of the trial (after the session's start-up)
        time.sleep(min(2.0, seconds / 4))
        a = page.evaluate("[performance.now(), window.spotlab.frames3d, window.spotlab.messages]")
        time.sleep(max(0.0, seconds - (time.monotonic() - t0) - min(1.0, seconds / 8)))
        b = page.evaluate("[performance.now(), window.spotlab.frames3d, window.spotlab.messages]")
        time.sleep(max(0.0, seconds - (time.monotonic() - t0)))
        latency = _call(base, "/api/status")["live_latency"]
        wall = time.monotonic() - t0
        share, browser_share = (_cpu_s(proc.pid) - c0) / wall, (_browser_cpu_s() - w0) / wall
        info = _call(base, "/api/trials/stop", {})
    finally:
        page.close()
        _stop(proc)
    span_s = (b[0] - a[0]) / 1e3
    return {
        "bench": "console_load", "run": "with", "round": n, **_trial(info, data),
        **_latency(latency),
        "page_3d_fps": round((b[1] - a[1]) / span_s, 1),
        "page_messages_per_s": round((b[2] - a[2]) / span_s, 1), **load.result(),
        "host_cpu_share": round(share, 3), "browser_cpu_share": round(browser_share, 3),
    }  # fmt: skip


def _summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    def median(run: str, key: str) -> float | None:
        values = [r[key] for r in rows if r["run"] == run and r[key] is not None]
        return round(statistics.median(values), 3) if values else None

    without, with_ = median("without", "live_p50_us"), median("with", "live_p50_us")
    lost = sum(sum(r["lost"].values()) for r in rows)
    fps = median("with", "page_3d_fps")
    out: dict[str, Any] = {"bench": "console_load", "summary": True, "rounds": len(rows) // 2}
    for run in ("without", "with"):
        for key in ("live_p50_us", "live_p99_us", "live_mean_us"):
            out[f"{run}_{key}"] = median(run, key)
        out[f"{run}_hub_realtime"] = round(
            statistics.median(r["realtime"].get("hub") or 0 for r in rows if r["run"] == run), 3
        )
    out["lost_frames"] = lost
    out["p50_ratio"] = None if not without or not with_ else round(with_ / without, 3)
    p99w, p99 = out["without_live_p99_us"], out["with_live_p99_us"]
    out["p99_ratio"] = None if not p99w or not p99 else round(p99 / p99w, 3)
    out["page_3d_fps"] = fps
    for run in ("without", "with"):
        out[f"{run}_host_cpu_share"] = median(run, "host_cpu_share")
    out["with_browser_cpu_share"] = median("with", "browser_cpu_share")
    out["loadavg_1min"] = round(statistics.median(r["loadavg_1min"] for r in rows), 2)
    # a hub whose frames span less than 99 % of the trial fell behind: not conclusive
    out["hub_in_real_time"] = min(r["realtime"].get("hub") or 0.0 for r in rows) >= 0.99
    out["targets_met"] = {
        "no_frame_lost": lost == 0,
        "p50_within_10_percent": out["p50_ratio"] is not None and out["p50_ratio"] <= 1.10,
        "page_3d_at_least_30_fps": fps is not None and fps >= 30.0,
    }
    return out


def main() -> int:
    if len(sys.argv) == 6 and sys.argv[1] == "--headless":
        rt = None if sys.argv[5] == "-" else int(sys.argv[5])
        return _headless(Path(sys.argv[2]), Path(sys.argv[3]), float(sys.argv[4]), rt)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="trial length, s")
    parser.add_argument("--rounds", type=int, default=2, help="rounds of the two runs")
    parser.add_argument(
        "--realtime", type=int, default=None, metavar="PRIO",
        help="both runs' acquisition threads under SCHED_FIFO at PRIO (--realtime)",
    )  # fmt: skip
    args = parser.parse_args()
    # The simulators stand in for devices with processors of their own: their serving
    # threads at nice -10 where the system allows (simulators/priority.py), so that the
    # figures are the host's, not a starved simulator's.
    os.environ.setdefault("SPOTLAB_SIM_NICE", "-10")
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as pw:
        folder = Path(tmp)
        rig = folder / "rig.toml"
        sims = []
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
        try:
            hub, hub_port = _spawn(
                [*CLI, "sim", "centroid", "--pty", "--cameras", "8", "--markers", "40",
                 "--rate", str(int(HUB_HZ))],
                folder, "hub",
            )  # fmt: skip
            sims.append(hub)
            spx, spx_port = _spawn(
                [*CLI, "sim", "selspot", "--pty", "--cameras", "2", "--leds", "8", "--rate",
                 str(int(SPX_HZ)), "--motion", "gait", "--rig-out", str(rig)],
                folder, "selspot",
            )  # fmt: skip
            sims.append(spx)
            lab = folder / "lab.toml"
            lab.write_text(
                f'rig = "{rig}"\n\n'
                f'[[device]]\nfamily = "centroid"\nport = "{hub_port}"\nname = "hub"\n'
                f"rate = {HUB_HZ:g}\n\n"
                f'[[device]]\nfamily = "selspot"\nport = "{spx_port}"\ncameras = 2\nleds = 8\n'
                f"rate = {SPX_HZ:g}\n"
            )
            rows = []
            for n in range(args.rounds):
                for run in ("without", "with"):
                    pids = {"hub": hub.pid, "selspot": spx.pid}
                    if run == "without":
                        row = _run_without(lab, folder, args.seconds, n, pids, args.realtime)
                    else:
                        row = _run_with(lab, folder, args.seconds, n, browser, pids, args.realtime)
                    rows.append(row)
                    print(json.dumps(row), flush=True)
            print(json.dumps(_summary(rows)), flush=True)
        finally:
            browser.close()
            for proc in sims:
                _stop(proc)
    return 0


if __name__ == "__main__":
    sys.exit(main())
