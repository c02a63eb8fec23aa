"""The lab console under load: does an open page cost the acquisition anything?

A simulated lab of separate processes on real pseudo-terminals (``spotlab sim ... --pty``):
a video-centroid hub of 8 cameras x 40 markers at 300 Hz and a SELSPOT-style system of
2 cameras x 8 LEDs at 200 Hz (its true rig for the live 3-D). ``spotlab console --lab``
records one trial of ``--seconds`` through the API twice: with no client, and with a
WebSocket client on ``/api/live`` reading every message (what the page receives). Each
run prints one JSON line: frames and lost frames per stream (the trial's sidecar, from
the journal), the live pipeline's host latency (p50, p99 µs) just before the stop, and
with the client the messages a second it received.

Usage: ``python benchmarks/console_load.py [--seconds 10]``. A shared 2-core machine is
noisy: compare the two lines of one run.
"""

from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

from websockets.sync.client import connect

CLI = (sys.executable, "-m", "spotlab.console.cli")


def _first_line(proc: subprocess.Popen[bytes], out: Path, timeout: float = 60.0) -> str:
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


def _run(lab: Path, folder: Path, seconds: float, client: bool) -> dict[str, Any]:
    data = folder / ("data-client" if client else "data-alone")
    proc, url = _spawn(
        [*CLI, "console", "--lab", str(lab), "--port", "0", "--no-browser", "--data", str(data)],
        folder,
        f"console-{client}",
    )
    base = url.rstrip("/")
    received = {"messages": 0, "bytes": 0}
    done = threading.Event()

    def read() -> None:
        with connect(base.replace("http://", "ws://") + "/api/live") as ws:
            while not done.is_set():
                text = ws.recv(timeout=5)
                received["messages"] += 1
                received["bytes"] += len(text)

    reader = threading.Thread(target=read, daemon=True) if client else None
    try:
        deadline = time.monotonic() + 30
        while not all(d["connected"] for d in _call(base, "/api/devices")["devices"]):
            if time.monotonic() > deadline:
                raise RuntimeError("devices did not connect")
            time.sleep(0.2)
        if reader is not None:
            reader.start()
        trial = {"subject": "bench", "session": "load", "trial": f"client{int(client)}"}
        _call(base, "/api/trials/start", trial)
        t0 = time.monotonic()
        time.sleep(seconds)
        latency = _call(base, "/api/status")["live_latency"]
        info = _call(base, "/api/trials/stop", {})
        elapsed = time.monotonic() - t0
        done.set()
        if reader is not None:
            reader.join(10)
    finally:
        _stop(proc)
    return {
        "bench": "console_load",
        "client": client,
        "seconds": info["duration_s"],
        "frames": info["frames"],
        "lost": info["lost"],
        "messages": info["messages"],
        "live_p50_us": None if latency is None else round(latency["p50_us"], 1),
        "live_p99_us": None if latency is None else round(latency["p99_us"], 1),
        "ws_messages_per_s": round(received["messages"] / elapsed, 1) if client else None,
        "ws_kbytes_per_s": round(received["bytes"] / elapsed / 1e3, 1) if client else None,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="trial length, s")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        rig = folder / "rig.toml"
        sims = []
        try:
            hub, hub_port = _spawn(
                [*CLI, "sim", "centroid", "--pty", "--cameras", "8", "--markers", "40",
                 "--rate", "300"],
                folder, "hub",
            )  # fmt: skip
            sims.append(hub)
            spx, spx_port = _spawn(
                [*CLI, "sim", "selspot", "--pty", "--cameras", "2", "--leds", "8", "--rate",
                 "200", "--motion", "gait", "--rig-out", str(rig)],
                folder, "selspot",
            )  # fmt: skip
            sims.append(spx)
            lab = folder / "lab.toml"
            lab.write_text(
                f'rig = "{rig}"\n\n'
                f'[[device]]\nfamily = "centroid"\nport = "{hub_port}"\nname = "hub"\n\n'
                f'[[device]]\nfamily = "selspot"\nport = "{spx_port}"\ncameras = 2\nleds = 8\n'
            )
            for client in (False, True):
                print(json.dumps(_run(lab, folder, args.seconds, client)), flush=True)
        finally:
            for proc in sims:
                _stop(proc)
    return 0


if __name__ == "__main__":
    sys.exit(main())
