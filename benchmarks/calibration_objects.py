"""Accuracy of the calibration objects: triad intrinsics (IAC), cage rotation check, PSD map.

Prints one JSON object per line; no timing. Figures quoted in docs/calibration-objects.md.

* ``iac``: K from orthogonal vanishing points of a triad (3 markers per 600 mm arm at 0,
  200, 600 mm) at F random attitudes in a 1.6 x 1.6 x 1.3 m volume, seen by the cameras of
  ``ring_rig(distortion=False)``; relative error of fx, fy (%), principal point error (px),
  skew (px); median and worst over cameras and repetitions.
* ``cage``: a 400 x 400 mm lower grid (5 x 5) and a 300 x 300 mm upper grid (4 x 4) 300 mm
  above, 2 cameras 2.5 m away, 70 degrees apart, f = 1500 px; rotation-check discrepancy
  with an exact cage and with a 2 mm shift of the upper plane, per image noise level.
* ``psd``: the simulator's pincushion (simulators/psd.py, k = 0.02) on a 17 x 17 grid of
  the 4096-count detector with 0.3 counts noise; fit and held-out residuals per order.

Usage: ``python benchmarks/calibration_objects.py [--repeats 5]``
"""

from __future__ import annotations

import argparse
import json

import numpy as np
from scipy.spatial.transform import Rotation

from spotlab.calibration import (
    fit_linearisation,
    intrinsics_from_orthogonal_vanishing_points,
    rotation_check,
    vanishing_point,
)
from spotlab.core.errors import CalibrationError
from spotlab.geometry import Camera
from spotlab.simulators.psd import HALF_RANGE, PsdModel
from spotlab.simulators.rigs import look_at, ring_rig
from spotlab.simulators.scene import DETECTOR_CENTRE

ARM_MM = np.array([0.0, 200.0, 600.0])


def triad_vanishing_pairs(
    camera: Camera, n: int, noise: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    axes = np.swapaxes(Rotation.random(n, random_state=rng).as_matrix(), 1, 2)
    base = rng.uniform([-800.0, -800.0, 300.0], [800.0, 800.0, 1600.0], (n, 3))
    markers = base[:, None, None] + ARM_MM[:, None] * axes[:, :, None, :]
    seen = camera.project(markers)
    vp = vanishing_point(seen + rng.normal(0.0, noise, seen.shape), ARM_MM)
    return vp[:, [0, 0, 1]].reshape(-1, 3), vp[:, [1, 2, 2]].reshape(-1, 3)


def bench_iac(repeats: int) -> None:
    rig = ring_rig(8, distortion=False, seed=0)
    for assume in ("none", "zero_skew"):
        for noise in (0.0, 0.1, 0.2, 0.5):
            for frames in (5, 20, 100, 300, 1000):
                f_err, pp_err, skew, fails = [], [], [], 0
                rng = np.random.default_rng(frames)
                for _ in range(repeats):
                    for camera in rig:
                        v1, v2 = triad_vanishing_pairs(camera, frames, noise, rng)
                        try:
                            K = intrinsics_from_orthogonal_vanishing_points(
                                v1, v2, assume=assume, image_size=camera.size
                            ).K
                        except CalibrationError:  # counted in "failed", not hidden
                            fails += 1
                            continue
                        f_err += list(100.0 * np.abs(np.diag(K)[:2] / np.diag(camera.K)[:2] - 1))
                        pp_err.append(float(np.hypot(*(K[:2, 2] - camera.K[:2, 2]))))
                        skew.append(abs(float(K[0, 1])))
                row = {
                    "bench": "iac",
                    "assume": assume,
                    "noise_px": noise,
                    "attitudes": frames,
                    "pairs": 3 * frames,
                    "runs": repeats * len(rig),
                    "failed": fails,
                }
                if f_err:
                    row |= {
                        "f_err_pct_median": round(float(np.median(f_err)), 4),
                        "f_err_pct_max": round(float(np.max(f_err)), 4),
                        "pp_err_px_median": round(float(np.median(pp_err)), 3),
                        "pp_err_px_max": round(float(np.max(pp_err)), 3),
                        "skew_px_max": round(float(np.max(skew)), 3),
                    }
                print(json.dumps(row), flush=True)


def bench_cage(repeats: int) -> None:
    grid = np.linspace(-200.0, 200.0, 5)
    top = np.linspace(-150.0, 150.0, 4)
    cage = np.array(
        [[x, y, 0.0] for x in grid for y in grid] + [[x, y, 300.0] for x in top for y in top]
    )
    upper = cage[:, 2] > 150.0
    cameras = []
    for angle in np.radians([-35.0, 35.0]):
        R, t = look_at([2500.0 * np.sin(angle), -2500.0 * np.cos(angle), 900.0], [0, 0, 150.0])
        K = [[1500.0, 0.0, 640.0], [0.0, 1500.0, 512.0], [0.0, 0.0, 1.0]]
        cameras.append(Camera(K, None, R, t, (1280, 1024)))
    half_turn = Rotation.from_euler("z", 180.5, degrees=True).as_matrix()
    for noise in (0.05, 0.1, 0.2):
        for shift in (0.0, 2.0):
            true = cage.copy()
            true[upper, 0] += shift
            rng = np.random.default_rng(7)
            rms, worst, est = [], [], []
            for _ in range(repeats * 4):
                views = [true, true @ half_turn.T + [25.0, -10.0, 0.0]]
                uv = [np.stack([c.project(Y) for c in cameras]) for Y in views]
                uv = [u + rng.normal(0.0, noise, u.shape) for u in uv]
                check = rotation_check(cage, uv[0], uv[1], tolerance_mm=1.0)
                rms.append(check.rms_mm)
                worst.append(check.max_mm)
                est.append(float(check.upper_plane_shift_mm[0]))
            print(
                json.dumps(
                    {
                        "bench": "cage",
                        "noise_px": noise,
                        "shift_mm": shift,
                        "runs": len(rms),
                        "rms_mm_median": round(float(np.median(rms)), 3),
                        "max_mm_median": round(float(np.median(worst)), 3),
                        "max_mm_max": round(float(np.max(worst)), 3),
                        "shift_estimate_mm_mean": round(float(np.mean(est)), 3),
                        "shift_estimate_mm_sd": round(float(np.std(est)), 3),
                    }
                ),
                flush=True,
            )


def bench_psd() -> None:
    k = PsdModel().pincushion
    g = np.linspace(150.0, 2.0 * DETECTOR_CENTRE - 150.0, 17)
    true = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)

    def bend(xy: np.ndarray) -> np.ndarray:
        pq = (xy - DETECTOR_CENTRE) / HALF_RANGE
        return DETECTOR_CENTRE + HALF_RANGE * pq * (1.0 + k * np.sum(pq**2, axis=1))[:, None]

    rng = np.random.default_rng(0)
    noise = 0.3
    measured = bend(true) + rng.normal(0.0, noise, true.shape)
    held_true = rng.uniform(300.0, 3800.0, (5000, 2))
    held = bend(held_true)
    for order in (1, 3, 5, 7, 9):
        lin = fit_linearisation(measured, true, order=order)
        err = np.hypot(*(lin(held) - held_true).T)
        print(
            json.dumps(
                {
                    "bench": "psd",
                    "order": order,
                    "noise_counts": noise,
                    "noise_rms_2d": round(noise * np.sqrt(2.0), 3),
                    "raw_rms": round(lin.raw_rms, 3),
                    "fit_rms": round(lin.residual_rms, 3),
                    "held_out_rms": round(float(np.sqrt(np.mean(err**2))), 3),
                    "held_out_max": round(float(err.max()), 3),
                }
            ),
            flush=True,
        )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    bench_psd()
    bench_cage(args.repeats)
    bench_iac(args.repeats)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
