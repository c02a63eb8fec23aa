"""C3D export: time of ``write_c3d`` for 100 markers x 100 000 frames.

Prints one JSON object per line. Target (TARGETS.md, "recording" row): C3D export of
100 markers x 100 000 frames in at most 1 s. The trial has 5 % of its marker samples
missing (NaN) and, with ``--channels``, analog channels at ``--per-frame`` samples per
frame. The first call in the process is reported apart (``first_s``): it pays for
page faults on fresh memory and a new file, which is what a user exporting once sees.
``best_s`` is the best of the following ``--repeats`` calls. ``mb_per_s`` is the file
size over ``first_s``. ``peak_rss_mb`` is the process's peak resident set size after
the writes; ``trial_rss_mb`` the same before the first write (the trial itself, 240 MB
of float64 points at the default size), so the difference is the writer's own memory.

Usage: ``python benchmarks/c3d_export.py [--markers 100] [--frames 100000]
[--channels 0] [--per-frame 10] [--repeats 3] [--dir DIR]``
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from spotlab.io import Trial, write_c3d


def peak_rss_mb() -> float:
    """Peak resident set size of this process so far, MB."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3


def make_trial(markers: int, frames: int, channels: int, per_frame: int) -> Trial:
    """A synthetic trial: points in mm with 5 % NaN samples, optional analog channels."""
    rng = np.random.default_rng(0)
    points = rng.normal(0.0, 800.0, (frames, markers, 3))
    points[rng.random((frames, markers)) < 0.05] = np.nan
    analog = rng.normal(0.0, 2.0, (frames * per_frame, channels)) if channels else None
    return Trial(
        points=points,
        labels=[f"M{i}" for i in range(markers)],
        point_rate=100.0,
        analog=analog if analog is not None else np.zeros((0, 0)),
        analog_labels=[f"A{i}" for i in range(channels)],
        analog_rate=100.0 * per_frame if channels else 0.0,
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--markers", type=int, default=100)
    parser.add_argument("--frames", type=int, default=100_000)
    parser.add_argument("--channels", type=int, default=0)
    parser.add_argument("--per-frame", type=int, default=10)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--dir", default=None, help="where the file goes (default: temp dir)")
    args = parser.parse_args(argv)
    trial = make_trial(args.markers, args.frames, args.channels, args.per_frame)
    trial_rss = peak_rss_mb()
    with tempfile.TemporaryDirectory(dir=args.dir) as tmp:
        path = Path(tmp) / "export.c3d"
        times = []
        for _ in range(1 + args.repeats):
            start = time.perf_counter()
            write_c3d(path, trial)
            times.append(time.perf_counter() - start)
        size_mb = path.stat().st_size / 1e6
    row = {
        "bench": "c3d_export",
        "markers": args.markers,
        "frames": args.frames,
        "analog_channels": args.channels,
        "analog_per_frame": args.per_frame if args.channels else 0,
        "file_mb": round(size_mb, 1),
        "first_s": round(times[0], 3),
        "best_s": round(min(times[1:]), 3) if args.repeats else None,
        "mb_per_s": round(size_mb / times[0], 1),
        "target_s": 1.0,
        "trial_rss_mb": round(trial_rss, 1),
        "peak_rss_mb": round(peak_rss_mb(), 1),
    }
    print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
