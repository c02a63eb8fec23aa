"""Blob centroiding: subpixel error on rendered blobs and time per 1280x800 frame.

Prints one JSON object per line. Targets (issue 6): <= 0.05 px RMS centroid error on
rendered blobs of 3-10 px diameter; a whole 1280x800 frame with ~40 blobs well under
the 3.3 ms frame period of 300 Hz on one core; a sunlit frame (thousands of blobs)
neither slow nor crashing.

* ``"case": "accuracy"`` rows: per profile (disc = retro-reflective marker blurred by
  the optics, sigma 0.5 px; gaussian = spot of that FWHM), diameter and read noise,
  the RMS and largest distance (px) between ``find_blobs`` centroids and the true
  centres of blobs at random subpixel positions, rendered with pixel-area integration
  (8x8 sub-samples), background 8, plateau 180 counts above it, uint8, threshold at
  20 % of the plateau.
* ``"case": "speed"`` rows: median and 90th percentile ms of ``find_blobs`` on one
  1280x800 uint8 frame (noise 2 counts) with 40 and with 5000 blobs of 3-10 px, and
  on a frame flooded with light; median over ``--repeat`` calls on one core.

Usage: ``python benchmarks/centroiding.py [--repeat 200] [--quick]``
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
from scipy.spatial import cKDTree

from spotlab.imaging import find_blobs, render_blobs

SIZE = (1280, 800)
BACKGROUND, PLATEAU = 8.0, 180.0
THRESHOLD = BACKGROUND + 0.2 * PLATEAU


def _grid(rng: np.random.Generator, step: int) -> np.ndarray:
    gx, gy = np.meshgrid(
        np.arange(step, SIZE[0] - step, step), np.arange(step, SIZE[1] - step, step)
    )
    grid = np.column_stack([gx.ravel(), gy.ravel()]).astype(float)
    return grid + rng.uniform(-0.5, 0.5, grid.shape)


def accuracy(profile: str, diameter: float, noise: float, seed: int) -> dict[str, object]:
    rng = np.random.default_rng(seed)
    truth = _grid(rng, 40)
    img = render_blobs(
        SIZE, truth, diameter, peak=PLATEAU, profile=profile, noise=noise,
        background=BACKGROUND, rng=rng,
    )  # fmt: skip
    blobs = find_blobs(img, THRESHOLD, min_area=2, max_blobs=len(truth) + 1)
    dist, _ = cKDTree(blobs.xy).query(truth)
    return {
        "case": "accuracy",
        "profile": profile,
        "diameter_px": diameter,
        "noise_counts": noise,
        "blobs": len(truth),
        "found": len(blobs),
        "rms_px": round(float(np.sqrt(np.mean(dist**2))), 4),
        "max_px": round(float(dist.max()), 4),
    }


def speed(label: str, img: np.ndarray, repeat: int) -> dict[str, object]:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        blobs = find_blobs(img, THRESHOLD, max_blobs=256)
        times.append(time.perf_counter() - start)
    ms = np.array(times) * 1e3
    return {
        "case": "speed",
        "frame": label,
        "size": list(SIZE),
        "components": blobs.n_components,
        "returned": len(blobs),
        "truncated": blobs.truncated,
        "flooded": blobs.flooded,
        "ms_median": round(float(np.median(ms)), 3),
        "ms_p90": round(float(np.percentile(ms, 90)), 3),
        "frame_period_ms_300hz": round(1e3 / 300, 3),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=200)
    parser.add_argument("--quick", action="store_true", help="fewer diameters and repeats")
    args = parser.parse_args()
    diameters = (3.0, 6.0, 10.0) if args.quick else (3.0, 4.0, 5.0, 6.0, 8.0, 10.0)
    repeat = min(args.repeat, 20) if args.quick else args.repeat
    seed = 0
    for profile in ("disc", "gaussian"):
        for diameter in diameters:
            for noise in (0.0, 2.0, 5.0):
                seed += 1
                print(json.dumps(accuracy(profile, diameter, noise, seed)), flush=True)
    rng = np.random.default_rng(100)
    for n in (40, 5000):
        xy = np.column_stack([rng.uniform(0, SIZE[0], n), rng.uniform(0, SIZE[1], n)])
        img = render_blobs(SIZE, xy, rng.uniform(3, 10, n), peak=PLATEAU, noise=2.0, rng=rng)
        print(json.dumps({"blobs_rendered": n, **speed(f"{n} blobs", img, repeat)}), flush=True)
    flooded = np.full((SIZE[1], SIZE[0]), 200, np.uint8)
    print(json.dumps(speed("flooded", flooded, repeat)), flush=True)


if __name__ == "__main__":
    main()
