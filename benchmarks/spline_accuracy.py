"""Acceleration from displacement: quintic GCV splines against accelerometer truth.

Prints one JSON object per signal. Signals (shared/data, SOURCES.md §3): Dowling (1985),
512 Hz, and Pezzack et al. (1977), each a measured angle with an independently measured
angular acceleration. Each is fitted by spotlab's ``SmoothingSpline(degree=5)`` (GCV) and,
when installed (``make bench-gcvspline``), by gcvspline's ``gcvspl`` (Woltring's Fortran
GCVSPL, quintic, mode 2) with its second derivative from ``splder``; the figure is the RMS
difference between the spline's second derivative and the accelerometer, rad/s^2.
Published: GCVSPL quintic on Dowling's data, 23.6 rad/s^2 (Davis & Challis 2020).

Usage: ``python benchmarks/spline_accuracy.py [--data ../shared/data]``
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from spotlab.kinematics import SmoothingSpline

DEFAULT_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def _signals(data: Path) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    dowling = np.genfromtxt(data / "dowling1985/dowling1985.csv", delimiter=",", names=True)
    pezzack = np.loadtxt(data / "bmc/Pezzack.txt", skiprows=6)
    return {
        "dowling1985": (dowling["time_s"], dowling["disp_rad"], dowling["acc_rad_per_s2"]),
        "pezzack1977": (pezzack[:, 0], pezzack[:, 1], pezzack[:, 3]),
    }


def _gcvspline_acceleration(t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, float] | None:
    try:
        from gcvspline import gcvspl  # type: ignore[import-not-found]
    except ImportError:
        return None
    n = t.size
    coef, wk, ier = gcvspl.gcvspl(
        t, np.asfortranarray(y[:, None]), np.ones(n), np.ones(1), 3, 2, 0, n
    )
    if ier != 0:
        raise RuntimeError(f"gcvspl failed with ier = {ier}")
    c = np.ascontiguousarray(coef[:, 0])
    # splder's interval hint l: the knot interval holding each t (1-based, Fortran)
    acc = np.array([gcvspl.splder(2, 3, ti, t, c, min(i + 1, n - 1)) for i, ti in enumerate(t)])
    return acc, float(wk[3])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    args = parser.parse_args(argv)
    for name, (t, y, acc) in _signals(args.data).items():
        spline = SmoothingSpline(t, y, degree=5)
        row: dict[str, object] = {
            "bench": "spline_accuracy",
            "signal": name,
            "samples": int(t.size),
            "spotlab_acc_rmse": float(np.sqrt(np.mean((spline(t, nu=2) - acc) ** 2))),
            "spotlab_p": float(spline.p),
        }
        theirs = _gcvspline_acceleration(t, y)
        if theirs is None:
            row["gcvspline_skipped"] = "not installed"
        else:
            row["gcvspline_acc_rmse"] = float(np.sqrt(np.mean((theirs[0] - acc) ** 2)))
            row["gcvspline_p"] = theirs[1]
        if name == "dowling1985":
            row["published_gcvspl_quintic_acc_rmse"] = 23.6
        print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
