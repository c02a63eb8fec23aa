"""A whole trial smoothed in one call: quintic GCV splines of K channels x N samples.

Prints one JSON object per line. Target (issue 19): a trial of 120 channels x 3 000
samples (40 markers x 3 coordinates, 30 s at 100 Hz) smoothed by
``SmoothingSpline(t, Y)`` at least 5 times faster than a loop of gcvspline's
``gcvspl`` (Woltring's Fortran GCVSPL, quintic, GCV mode 2) over the channels, at
most 1.5 times its peak memory. In the same run:

* ``spotlab``: one ``SmoothingSpline(t, Y)`` call, Y of shape (N, K);
* ``spotlab_loop``: one ``SmoothingSpline(t, Y[:, k])`` per channel (the way to do it
  before the batched call; ``--no-loop`` leaves it out);
* ``gcvspline``: one ``gcvspl`` call per channel (``make bench-gcvspline`` builds it).

Each runs in a fresh child process, so its peak resident memory (``peak_rss_mb``,
including the interpreter with numpy and scipy, ~60-90 MB) is its own. The row
also gives the largest relative difference of the batched fit from the loop's
(``max_rel_diff_batch_vs_loop``, fitted values and p) and the median relative
difference of p from GCVSPL's.

Signal per channel: a sum of two sines (0.2-3 Hz, 10-500 mm) + 0.2-1 mm normal noise
at 100 Hz, seeded.

Usage: ``python benchmarks/spline_trial.py [--channels 120] [--samples 3000]
[--repeat 1] [--no-loop]``
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

TOOLS = ("spotlab", "spotlab_loop", "gcvspline")


def _trial(n: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    t = np.arange(n) * 0.01
    y = np.zeros((n, k))
    for _ in range(2):
        freq = rng.uniform(0.2, 3.0, k)
        amp = rng.uniform(10.0, 500.0, k)
        phase = rng.uniform(0.0, 2 * np.pi, k)
        y += amp * np.sin(2 * np.pi * freq * t[:, None] + phase)
    return t, y + rng.uniform(0.2, 1.0, k) * rng.standard_normal((n, k))


def _fit(tool: str, n: int, k: int, out: Path) -> dict[str, object]:
    """Run one tool in this process; its figures; fitted values and p saved to ``out``."""
    t, y = _trial(n, k)
    row: dict[str, object] = {}
    fitted = None
    if tool == "spotlab":
        from spotlab.kinematics import SmoothingSpline

        start = time.perf_counter()
        spline = SmoothingSpline(t, y, degree=5)
        fitted = spline(t)
        row["seconds"] = time.perf_counter() - start
        p = np.asarray(spline.p)
    elif tool == "spotlab_loop":
        from spotlab.kinematics import SmoothingSpline

        start = time.perf_counter()
        splines = [SmoothingSpline(t, y[:, j], degree=5) for j in range(k)]
        fitted = np.stack([s(t) for s in splines], axis=1)
        row["seconds"] = time.perf_counter() - start
        p = np.array([s.p for s in splines])
    else:
        from gcvspline import gcvspl  # type: ignore[import-not-found]

        ones, one = np.ones(n), np.ones(1)
        ps = []
        start = time.perf_counter()
        for j in range(k):
            _coef, wk, ier = gcvspl.gcvspl(
                t, np.asfortranarray(y[:, j : j + 1]), ones, one, 3, 2, 0.0, n
            )
            if ier != 0:
                raise RuntimeError(f"gcvspl failed with ier = {ier}")
            ps.append(float(wk[3]))
        row["seconds"] = time.perf_counter() - start
        p = np.array(ps)
    row["peak_rss_mb"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3, 1)
    np.savez(out, p=p, fitted=np.zeros(0) if fitted is None else fitted)
    return row


def _child(tool: str, n: int, k: int, out: Path) -> dict[str, object] | None:
    cmd = [sys.executable, __file__, "--child", tool, str(n), str(k), str(out)]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        if "No module named 'gcvspline'" in done.stderr:
            return None
        raise RuntimeError(f"{tool} failed:\n{done.stderr}")
    return dict(json.loads(done.stdout))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--channels", type=int, default=120)
    parser.add_argument("--samples", type=int, default=3000)
    parser.add_argument("--repeat", type=int, default=1, help="runs per tool (best)")
    parser.add_argument("--no-loop", action="store_true", help="leave out spotlab_loop")
    parser.add_argument("--child", nargs=4, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        tool, n, k, out = args.child
        print(json.dumps(_fit(tool, int(n), int(k), Path(out))))
        return 0
    n, k = args.samples, args.channels
    row: dict[str, object] = {"bench": "spline_trial", "channels": k, "samples": n}
    tools = [tool for tool in TOOLS if not (args.no_loop and tool == "spotlab_loop")]
    saved: dict[str, dict[str, np.ndarray]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for tool in tools:
            out = Path(tmp) / f"{tool}.npz"
            runs = [_child(tool, n, k, out) for _ in range(args.repeat)]
            if runs[0] is None:
                row[f"{tool}_skipped"] = "not installed"
                continue
            best = min((r for r in runs if r is not None), key=lambda r: float(r["seconds"]))  # type: ignore[arg-type]
            for key, value in best.items():
                row[f"{tool}_{key}"] = value
            with np.load(out) as data:
                saved[tool] = {"p": data["p"], "fitted": data["fitted"]}
    base = float(row["spotlab_seconds"])  # type: ignore[arg-type]
    for peer in ("gcvspline", "spotlab_loop"):
        if f"{peer}_seconds" in row:
            row[f"ratio_{peer}_over_spotlab"] = round(float(row[f"{peer}_seconds"]) / base, 2)  # type: ignore[arg-type]
            row[f"rss_spotlab_over_{peer}"] = round(
                float(row["spotlab_peak_rss_mb"]) / float(row[f"{peer}_peak_rss_mb"]),
                2,  # type: ignore[arg-type]
            )
    if "spotlab_loop" in saved:
        a, b = saved["spotlab"], saved["spotlab_loop"]
        scale = np.max(np.abs(b["fitted"]), axis=0)
        diff = max(
            float(np.max(np.max(np.abs(a["fitted"] - b["fitted"]), axis=0) / scale)),
            float(np.max(np.abs(a["p"] / b["p"] - 1.0))),
        )
        row["max_rel_diff_batch_vs_loop"] = diff
    if "gcvspline" in saved:
        rel = np.abs(saved["spotlab"]["p"] / saved["gcvspline"]["p"] - 1.0)
        row["p_median_rel_diff_vs_gcvspline"] = float(np.median(rel))
    print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
