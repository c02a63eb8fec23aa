"""CPU cost of one live frame (8 cameras x 128 markers) in a tight loop: compiled kernel
against its numpy twin.

Per path (``compiled``: ``spotlab.reconstruction._c_frame``; ``numpy``: the twin, as
with ``SPOTLAB_NO_NATIVE=1``): the thread CPU time of ``FrameTriangulator.by_marker``
on one frame (undistortion, depth-weighted ODLE, residuals), and of
``LivePipeline.on_block`` on one-frame blocks of the reference rig (image coordinates,
frame times, triangulation, ``LiveFrame``, latency histogram, a no-op consumer): best
of ``--rounds`` rounds of ``--frames`` calls, us per frame. The loop runs on warm
caches; inside a session the same call costs more (``benchmarks/live_latency.py``
reports ``on_block_cpu_us_mean``). One JSON line per path, with the 1-minute load
average (other programs share the cores).

Usage: ``python benchmarks/live_frame_cost.py [--frames 3000] [--rounds 3]``
"""

from __future__ import annotations

import argparse
import json
import os
import time
from collections.abc import Callable

from spotlab.acquisition.live import LivePipeline
from spotlab.core import native
from spotlab.simulators.rigs import ring_rig
from spotlab.testing.synthetic_image2d import SyntheticImage2d

CAMERAS, MARKERS, RATE = 8, 128, 300.0


def _best_us(call: Callable[[int], object], frames: int, rounds: int) -> float:
    """Least thread CPU time per call over ``rounds`` rounds of ``frames`` calls, us."""
    best = float("inf")
    for _ in range(rounds):
        t0 = time.thread_time_ns()
        for k in range(frames):
            call(k)
        best = min(best, (time.thread_time_ns() - t0) / frames / 1e3)
    return best


def _measure(path: str, frames: int, rounds: int) -> dict[str, object]:
    if path == "numpy":
        os.environ[native.NO_NATIVE_ENV] = "1"
    else:
        os.environ.pop(native.NO_NATIVE_ENV, None)
    rig = ring_rig(CAMERAS)
    device = SyntheticImage2d(rig, MARKERS, RATE, name="cams", seed=0)
    device.paced = False
    device.start()
    blocks = [device.recv() for _ in range(300)]
    pipeline = LivePipeline(rig, [lambda frame: None])
    pipeline.configure([device.spec])
    tri = pipeline._triangulate
    assert tri is not None
    if (tri._kernel is not None) != (path == "compiled"):
        raise SystemExit(f"live_frame_cost: the {path} path is not available here")
    uv = [b.data[0] for b in blocks if b is not None]
    load = round(os.getloadavg()[0], 2)
    return {
        "path": path,
        "cameras": CAMERAS,
        "markers": MARKERS,
        "triangulate_us": round(_best_us(lambda k: tri.by_marker(uv[k % 300]), frames, rounds), 1),
        "on_block_us": round(
            _best_us(lambda k: pipeline.on_block("cams", blocks[k % 300]), frames, rounds), 1
        ),
        "frames": frames,
        "rounds": rounds,
        "loadavg_1min": {"start": load, "end": round(os.getloadavg()[0], 2)},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=3000)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    for path in ("compiled", "numpy"):
        print(json.dumps(_measure(path, args.frames, args.rounds)), flush=True)
    os.environ.pop(native.NO_NATIVE_ENV, None)


if __name__ == "__main__":
    main()
