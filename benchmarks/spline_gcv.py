"""Quintic GCV smoothing spline: fit time against N, side by side with SciPy.

Prints one JSON object per line. Target (TARGETS.md): quintic GCV on 1 000 000
samples faster than gcvspline (Woltring's Fortran GCVSPL; 7.3 s and 0.071 s at
10 000 samples on the reference machine), O(n) in time and memory. gcvspline is
not installed here, so the peer in the same run is SciPy's
``make_smoothing_spline`` (cubic, GCV); a size is skipped for SciPy when its
time, extrapolated linearly from the previous size, would exceed ``--limit`` s.

Signal: sin(2 pi 0.5 t) + 0.01 normal noise at 100 Hz.

Usage: ``python benchmarks/spline_gcv.py [--sizes 10000 100000 1000000] [--limit 60]``
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time

import numpy as np
from scipy.interpolate import make_smoothing_spline

from spotlab.kinematics import SmoothingSpline


def peak_rss_mb() -> float:
    """Peak resident set size of this process so far, MB."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    parser.add_argument("--limit", type=float, default=60.0)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(0)
    scipy_rate = None  # s per sample, from the last size SciPy ran
    for n in args.sizes:
        t = np.arange(n) * 0.01
        y = np.sin(2 * np.pi * 0.5 * t) + 0.01 * rng.standard_normal(n)
        start = time.perf_counter()
        spline = SmoothingSpline(t, y, degree=5)
        ours = time.perf_counter() - start
        rmse = float(np.sqrt(np.mean((spline(t) - np.sin(2 * np.pi * 0.5 * t)) ** 2)))
        row: dict[str, object] = {
            "bench": "spline_gcv",
            "n": n,
            "spotlab_quintic_gcv_s": round(ours, 4),
            "spotlab_p": spline.p,
            "spotlab_dof": round(float(spline.dof), 2),
            "spotlab_rmse_vs_truth": rmse,
            "peak_rss_mb": round(peak_rss_mb(), 1),
        }
        if scipy_rate is None or scipy_rate * n <= args.limit:
            start = time.perf_counter()
            make_smoothing_spline(t, y)
            theirs = time.perf_counter() - start
            scipy_rate = theirs / n
            row["scipy_cubic_gcv_s"] = round(theirs, 4)
            row["ratio_scipy_over_spotlab"] = round(theirs / ours, 2)
        else:
            row["scipy_cubic_gcv_s"] = None
            row["scipy_skipped"] = f"extrapolated {scipy_rate * n:.0f} s > {args.limit:g} s"
        print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
