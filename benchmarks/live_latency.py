"""Live pipeline host latency: 128 markers x 8 cameras at 300 Hz, last byte in to 3-D out.

Target (TARGETS.md): p99 <= 1 ms host processing. A SELSPOT-style system cannot do it
(128 LEDs in 100 us slots take 12.8 ms: at most 78 Hz, 4 cameras), so the frames come
from :class:`spotlab.testing.synthetic_image2d.SyntheticImage2d`: the reference rig of
TARGETS.md (8 cameras 1280x1024 on a 4 m ring, distortion), 128 markers moving on
known paths, 0.2 px noise, paced by the clock at 300 Hz, arrival stamped when the
reader wakes for a due frame (as a link's read returns with its last byte; the frames'
image coordinates are computed before the run). Each frame goes through a real
:class:`Session` into a :class:`LivePipeline` holding the rig loaded from TOML;
latency = the instant the 3-D points are handed to the consumers minus the arrival
stamp.

Configurations (``--configs``):

* ``inline``: one device of 8 cameras, the pipeline in the reader thread;
* ``dispatcher``: the same with the pipeline behind the session's queue and its own
  dispatcher thread (the hand-off issue 2 measured at 1.2-9 ms outliers);
* ``matched``: two devices of 4 cameras each on one frame clock (two synchronised
  systems), their frames matched by time, inline.

Figures per configuration (one JSON line each): p50 / p99 / max / mean latency (us),
frames over 1 ms, frames in and out, incomplete groups, how far the readers fell
behind the devices' schedule (``reader_behind_us``: stamp minus due instant; a real
link's kernel buffer hides this from the latency), the 3-D error against the true
paths (RMS, mm), and the machine's load before and after (other programs share the
cores). The first ``--warmup`` seconds are not measured.

Decoding is not in these figures (no wire bytes); the SPX decoder takes 30-49 us per
4x32 frame (``benchmarks/decode_selspot.py``).

Usage: ``python benchmarks/live_latency.py [--seconds 60] [--configs inline dispatcher
matched] [--warmup 1]``
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from spotlab.acquisition.live import LatencyStats, LiveFrame, LivePipeline
from spotlab.acquisition.session import Session
from spotlab.geometry import Rig
from spotlab.simulators.rigs import ring_rig
from spotlab.testing.synthetic_image2d import SyntheticImage2d

CAMERAS, MARKERS, RATE = 8, 128, 300.0
CONFIGS = ("inline", "dispatcher", "matched")


class ErrorMeter:
    """Consumer: 3-D error against the device's true paths, after the warm-up."""

    def __init__(self, device: SyntheticImage2d, warmup_frames: int) -> None:
        self.device = device
        self.warmup = warmup_frames
        self.sq = 0.0
        self.points = 0
        self.unseen = 0
        self.frames = 0

    def __call__(self, frame: LiveFrame) -> None:
        self.frames += 1
        if frame.seq < self.warmup:
            return
        err = frame.points - self.device.truth(frame.seq)
        ok = np.isfinite(err[:, 0])
        self.sq += float(np.sum(err[ok] ** 2))
        self.points += int(ok.sum())
        self.unseen += int((~ok).sum())


def _run(config: str, seconds: float, warmup_s: float, rig: Rig) -> dict[str, Any]:
    if config == "matched":
        t0 = time.monotonic_ns() + 200_000_000
        halves = [Rig(rig.cameras[:4]), Rig(rig.cameras[4:])]
        centre = SyntheticImage2d(rig, MARKERS, RATE).centre  # one volume for both
        devices = [
            SyntheticImage2d(
                h, MARKERS, RATE, name=f"sys{i}", seed=i, paths_seed=0, t0_ns=t0, centre=centre
            )
            for i, h in enumerate(halves)
        ]
    else:
        devices = [SyntheticImage2d(rig, MARKERS, RATE, name="cams", seed=0)]
    warm = int(warmup_s * RATE)
    meter = ErrorMeter(devices[0], warm)
    pipeline = LivePipeline(rig, [meter], inline=config != "dispatcher")
    load0 = os.getloadavg()[0]
    gc.collect()
    session = Session(devices, [pipeline])
    session.start()
    # Latency of the warm-up frames is not counted: reset once they are through.
    time.sleep(warmup_s)
    pipeline.reset_latency()
    for device in devices:
        device.behind = LatencyStats()
    status = session.run_for(seconds)
    stats = pipeline.stats()
    lat = stats.latency
    return {
        "config": config,
        "cameras": CAMERAS,
        "markers": MARKERS,
        "rate_hz": RATE,
        "seconds": seconds,
        "frames_in": stats.frames_in,
        "frames_out": stats.frames_out,
        "measured": lat.frames,
        "p50_us": lat.p50_us,
        "p99_us": lat.p99_us,
        "max_us": round(lat.max_us, 1),
        "mean_us": round(lat.mean_us, 1),
        "over_1ms": lat.over_1ms,
        "incomplete": stats.incomplete,
        "reader_behind_us_p99": max(d.behind.summary().p99_us for d in devices),
        "reader_behind_us_max": round(max(d.behind.max_ns for d in devices) / 1e3, 1),
        "failed": stats.failed,
        "overflows": sum(status.overflows.values()),
        "rms_error_mm": round(float(np.sqrt(meter.sq / max(meter.points, 1))), 4),
        "unseen_points": meter.unseen,
        "loadavg_1min": [round(load0, 2), round(os.getloadavg()[0], 2)],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--warmup", type=float, default=1.0)
    parser.add_argument("--configs", nargs="+", choices=CONFIGS, default=list(CONFIGS))
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "rig.toml"
        ring_rig(CAMERAS).save(path)
        rig = Rig.load(path)
    for config in args.configs:
        print(json.dumps(_run(config, args.seconds, args.warmup, rig)), flush=True)


if __name__ == "__main__":
    main()
