"""Quintic GCV smoothing spline: fit time and peak memory against N, beside the peers.

Prints one JSON object per line. Target (TARGETS.md): a quintic GCV fit of
1 000 000 samples faster than gcvspline (the Python wrapper of Woltring's Fortran
GCVSPL) in the same run, O(n) in time and memory. Peers in the same run:

* gcvspline's ``gcvspl`` (quintic, GCV mode 2), when installed: ``make bench-gcvspline``
  builds it (it needs gfortran and an old setuptools, see docs/benchmarks.md);
* SciPy's ``make_smoothing_spline`` (cubic only, GCV); a size is skipped for SciPy when
  its time, extrapolated linearly from the previous size, would exceed ``--limit`` s.

Every fit runs in a fresh child process, so each tool starts from the same state
and its peak resident memory is its own (``peak_rss_mb`` includes the ~60 MB of an
interpreter with numpy and scipy loaded; ``data_mb`` is one float64 copy of the
samples, for scale).

Signal: sin(2 pi 0.5 t) + 0.01 normal noise at 100 Hz.

Usage: ``python benchmarks/spline_gcv.py [--sizes 1000 10000 100000 1000000] [--limit 60]
[--repeat 1] [--tools spotlab gcvspline scipy]``
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time

import numpy as np

TOOLS = ("spotlab", "gcvspline", "scipy")


def _signal(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    t = np.arange(n) * 0.01
    truth = np.sin(2 * np.pi * 0.5 * t)
    return t, truth + 0.01 * rng.standard_normal(n), truth


def _fit(tool: str, n: int) -> dict[str, object]:
    """Run one fit in this process; the figures of that fit."""
    t, y, truth = _signal(n)
    row: dict[str, object] = {"tool": tool, "n": n}
    if tool == "spotlab":
        from spotlab.kinematics import SmoothingSpline

        start = time.perf_counter()
        spline = SmoothingSpline(t, y, degree=5)
        row["seconds"] = time.perf_counter() - start
        row["p"] = spline.p
        row["dof"] = round(float(spline.dof), 3)
        fitted = spline(t)
        row["rmse_acc_vs_truth"] = float(
            np.sqrt(np.mean((spline(t, nu=2) + (np.pi**2) * truth) ** 2))
        )
    elif tool == "gcvspline":
        from gcvspline import gcvspl  # type: ignore[import-not-found]

        ys = np.asfortranarray(y[:, None])
        start = time.perf_counter()
        _coef, wk, ier = gcvspl.gcvspl(t, ys, np.ones(n), np.ones(1), 3, 2, 0.0, n)
        row["seconds"] = time.perf_counter() - start
        if ier != 0:
            raise RuntimeError(f"gcvspl failed with ier = {ier}")
        row["p"] = float(wk[3])
        row["dof"] = round(float(n - wk[2]), 3)
        fitted = None
    else:
        from scipy.interpolate import make_smoothing_spline

        start = time.perf_counter()
        cubic = make_smoothing_spline(t, y)
        row["seconds"] = time.perf_counter() - start
        fitted = cubic(t)
    if fitted is not None:
        row["rmse_vs_truth"] = float(np.sqrt(np.mean((fitted - truth) ** 2)))
    row["peak_rss_mb"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3, 1)
    return row


def _child(tool: str, n: int) -> dict[str, object] | None:
    out = subprocess.run(
        [sys.executable, __file__, "--child", tool, str(n)],
        capture_output=True,
        text=True,
        check=False,
    )
    if out.returncode != 0:
        if "No module named 'gcvspline'" in out.stderr:
            return None
        raise RuntimeError(f"{tool} at n = {n} failed:\n{out.stderr}")
    return dict(json.loads(out.stdout))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1_000, 10_000, 100_000, 1_000_000])
    parser.add_argument("--limit", type=float, default=60.0)
    parser.add_argument("--repeat", type=int, default=1, help="fits per tool and size (best)")
    parser.add_argument(
        "--tools", nargs="+", choices=TOOLS, default=list(TOOLS), help="tools to run (all)"
    )
    parser.add_argument("--child", nargs=2, metavar=("TOOL", "N"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(_fit(args.child[0], int(args.child[1]))))
        return 0
    scipy_rate = None  # s per sample, from the last size SciPy ran
    for n in args.sizes:
        row: dict[str, object] = {"bench": "spline_gcv", "n": n, "data_mb": n * 8 / 1e6}
        for tool in args.tools:
            if tool == "scipy" and scipy_rate is not None and scipy_rate * n > args.limit:
                row["scipy_skipped"] = f"extrapolated {scipy_rate * n:.0f} s > {args.limit:g} s"
                continue
            runs = [_child(tool, n) for _ in range(args.repeat)]
            if runs[0] is None:
                row[f"{tool}_skipped"] = "not installed"
                continue
            best = min((r for r in runs if r is not None), key=lambda r: float(r["seconds"]))
            for key, value in best.items():
                if key not in ("tool", "n"):
                    row[f"{tool}_{key}"] = value
            if tool == "scipy":
                scipy_rate = float(best["seconds"]) / n
        for peer in ("gcvspline", "scipy"):
            if f"{peer}_seconds" in row:
                ratio = float(row[f"{peer}_seconds"]) / float(row["spotlab_seconds"])  # type: ignore[arg-type]
                row[f"ratio_{peer}_over_spotlab"] = round(ratio, 2)
        if "gcvspline_p" in row:
            row["p_relative_difference"] = abs(
                float(row["spotlab_p"]) / float(row["gcvspline_p"]) - 1.0  # type: ignore[arg-type]
            )
        print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
