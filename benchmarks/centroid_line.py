"""CEN video-centroid hub: what its line carries (12 or 24 Mbaud), whatever the CPU.

Runs a clean simulated hub (seed 3, as ``centroid_link.py``) in virtual time, so the
simulator's speed plays no part: ``--seconds`` of frames at each rate, then ``STOP:``
and the line drained. Prints one JSON object per line and rate: frames taken, sent
whole, dropped whole by the hub's FIFO (the line full), and the mean frame size. A
frame the line cannot carry in time is dropped by the device whatever the host and
the simulator do (docs/protocols/mcs1.md §4).

Usage: ``python benchmarks/centroid_line.py [--seconds 20] [--rates 300 480 600]
[--bauds 12000000 24000000]``
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from spotlab.simulators import wire
from spotlab.simulators.centroid_service import CentroidSimOptions, build_centroid_device

#: ``COMM`` codes of the line rates (docs/protocols/centroid.md §2).
COMM_CODES = {6_000_000: 10, 12_000_000: 11, 24_000_000: 12}
STEP_NS = 1_000_000


def run(rate: float, seconds: float, cameras: int, markers: int, baud: int) -> dict[str, object]:
    """One clean stream of ``seconds`` at ``rate`` Hz, the line drained after it."""
    with tempfile.TemporaryDirectory() as tmp:
        truth = Path(tmp) / "truth.npz"
        options = CentroidSimOptions(
            cameras=cameras, markers=markers, rate_hz=rate, seed=3, truth=truth
        )
        dev = build_centroid_device(options, now_ns=0)
        t = 1_000_000_000
        dev.receive(wire.command(f"COMM:{COMM_CODES[baud]}"), t)
        t += 50_000_000
        dev.output(t)
        dev.receive(wire.command("START:"), t, line_baud=baud)
        n_bytes = 0
        stop = t + round(seconds * 1e9)
        while t < stop:
            t += STEP_NS
            n_bytes += len(dev.output(t))
        dev.receive(wire.command("STOP:"), t, line_baud=baud)
        for _ in range(3000):  # 3 s: the FIFO (1 MB) drains
            t += STEP_NS
            n_bytes += len(dev.output(t))
        dev.close(t)
        with np.load(truth) as z:
            sent = z["sent"]
    return {
        "bench": "centroid_line", "baud": baud, "cameras": cameras, "markers": markers,
        "rate_hz": rate,
        "seconds": seconds, "frames_taken": int(sent.size), "sent_whole": int(sent.sum()),
        "dropped_whole": int((~sent).sum()),
        "frame_bytes": round(n_bytes / max(int(sent.sum()), 1)),
        "line_bytes_per_s": baud // 10,
    }  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--rates", type=float, nargs="+", default=[300.0, 480.0, 600.0])
    ap.add_argument("--cameras", type=int, default=8)
    ap.add_argument("--markers", type=int, default=40)
    ap.add_argument("--bauds", type=int, nargs="+", default=[12_000_000, 24_000_000],
                    choices=sorted(COMM_CODES))  # fmt: skip
    args = ap.parse_args()
    for baud in args.bauds:
        for rate in args.rates:
            row = run(rate, args.seconds, args.cameras, args.markers, baud)
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
