"""CEN video-centroid hub: simulator render time and host decode time per frame.

Prints one JSON object per line. The simulator must render a frame (every
camera's blobs, the wire frame) well within a frame period to serve 300 Hz in
real time on a pseudo-terminal; the host must decode a frame in a fraction of it.
Simulated frames are taken on the device's own time axis (no pacing): ``ms_per_frame``
is the wall time per frame on one core, ``cpu_ms_per_frame`` the process's CPU time
(less sensitive to other processes sharing the machine).

Usage: ``python benchmarks/centroid_sim.py [--cameras 8] [--markers 40] [--frames 600]``
"""

from __future__ import annotations

import argparse
import json
import time

from spotlab.drivers.centroid import CentroidConfig, CentroidDecoder
from spotlab.simulators import wire
from spotlab.simulators.centroid_service import CentroidSimOptions, build_centroid_device


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--cameras", type=int, default=8)
    ap.add_argument("--markers", type=int, default=40)
    ap.add_argument("--frames", type=int, default=600)
    ap.add_argument("--rate", type=float, default=300.0)
    args = ap.parse_args()
    options = CentroidSimOptions(cameras=args.cameras, markers=args.markers, rate_hz=args.rate)
    dev = build_centroid_device(options, now_ns=0)
    t = 1_000_000_000
    dev.receive(wire.command("COMM:11"), t)
    t += 50_000_000
    dev.output(t)
    dev.receive(wire.command("START:"), t, line_baud=12_000_000)
    period = round(1e9 / args.rate)
    chunks = []
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(args.frames):
        t += period
        chunks.append(dev.output(t))
    render = (time.perf_counter() - t0) / args.frames
    render_cpu = (time.process_time() - c0) / args.frames
    config = CentroidConfig.create(cameras=args.cameras, rate_hz=args.rate)
    decoder = CentroidDecoder(config)
    t0 = time.perf_counter()
    frames = sum(len(decoder.feed(c, 0)) for c in chunks)
    decode = (time.perf_counter() - t0) / max(frames, 1)
    size = sum(len(c) for c in chunks) / max(frames, 1)
    common = {"cameras": args.cameras, "markers": args.markers, "frames": frames}
    print(json.dumps({"what": "sim_render", **common, "ms_per_frame": round(render * 1e3, 3),
                      "cpu_ms_per_frame": round(render_cpu * 1e3, 3),
                      "period_ms": round(1e3 / args.rate, 3)}))  # fmt: skip
    print(json.dumps({"what": "host_decode", **common, "ms_per_frame": round(decode * 1e3, 3),
                      "bytes_per_frame": round(size), "blobs": decoder.blobs}))  # fmt: skip


if __name__ == "__main__":
    main()
