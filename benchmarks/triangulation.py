"""Triangulation: points per second and 3-D error, spotlab beside aniposelib and OpenCV.

Prints one JSON object per line. Scene (TARGETS.md): ``ring_rig()`` (8 cameras of
1280 x 1024 px on a 4 m ring, distortion), 100 000 points uniform in the capture
cylinder (radius 1.6 m, height 0.1-2.2 m), each seen by a random 2..8 of the cameras
that see it, 0.2 px Gaussian noise per coordinate. The noise floor is the
maximum-likelihood point (Gauss-Newton on the pixel error until it stops moving,
``triangulate(..., refine=3)``); ``ratio_to_floor`` is a method's RMS 3-D error over it.

Peers, on the same observations: a plain normalised DLT in numpy (every view of a
point, undistorted by OpenCV, one batched SVD of the stacked 2k x 4 systems; the
``x_numpy_dlt`` of each spotlab row is its speed over this one's, same run, same
repeats), aniposelib ``CameraGroup.triangulate`` (all views,
undistorted by OpenCV inside), and OpenCV ``cv2.triangulatePoints`` on the first two
views of each point after ``cv2.undistortPoints`` (it takes exactly two cameras). A
missing peer is reported as skipped. Times are the best of ``--repeats`` runs. The default
estimator (ODLE with depth weights) is timed on one thread (``workers=1``) and on two
(``workers=2``); the other spotlab rows use the default (one thread). Where the
compiled kernel is built, ``triangulate`` uses it; ``SPOTLAB_NO_NATIVE=1`` times the
numpy twin.

Usage: ``python benchmarks/triangulation.py [--points 100000] [--repeats 5] [--seed 0]``
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from spotlab.geometry import Rig
from spotlab.reconstruction import triangulate
from spotlab.simulators.rigs import ring_rig


def scene(rig: Rig, n: int, seed: int, noise_px: float) -> tuple[np.ndarray, np.ndarray]:
    """True points (n, 3) and their noisy observations (C, n, 2), NaN where unseen."""
    rng = np.random.default_rng(seed)
    radius = 1600.0 * np.sqrt(rng.uniform(0.0, 1.0, n))
    angle = rng.uniform(0.0, 2.0 * np.pi, n)
    X = np.stack([radius * np.cos(angle), radius * np.sin(angle), rng.uniform(100, 2200, n)], 1)
    uv = rig.project(X)
    visible = np.all(np.isfinite(uv), axis=-1)
    for c, cam in enumerate(rig):
        w, h = cam.size
        visible[c] &= (uv[c, :, 0] > 0) & (uv[c, :, 0] < w) & (uv[c, :, 1] > 0) & (uv[c, :, 1] < h)
    n_visible = visible.sum(axis=0)
    X, uv, visible, n_visible = X[n_visible >= 2], uv[:, n_visible >= 2], visible, n_visible
    visible = visible[:, n_visible >= 2]
    wanted = rng.integers(2, visible.sum(axis=0) + 1)
    score = np.where(visible, rng.uniform(size=visible.shape), np.inf)
    rank = np.argsort(np.argsort(score, axis=0), axis=0)
    uv = uv + rng.normal(0.0, noise_px, uv.shape)
    uv[~(visible & (rank < wanted))] = np.nan
    return X, uv


def best_time(fn: Callable[[], Any], repeats: int) -> tuple[float, Any]:
    """Shortest wall time of ``repeats`` calls (s) and the last result."""
    best, out = np.inf, None
    for _ in range(repeats):
        start = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - start)
    return best, out


def rms_mm(estimate: np.ndarray, truth: np.ndarray) -> float:
    ok = np.all(np.isfinite(estimate), axis=-1)
    return float(np.sqrt(np.mean(np.sum((estimate[ok] - truth[ok]) ** 2, axis=-1))))


def aniposelib_peer(rig: Rig) -> Callable[[np.ndarray], np.ndarray] | str:
    try:
        from aniposelib.cameras import Camera as AniCamera
        from aniposelib.cameras import CameraGroup
    except ImportError as exc:
        return f"aniposelib not installed ({exc})"
    import cv2

    cams = [
        AniCamera(
            matrix=cam.K,
            dist=cam.dist,
            size=cam.size,
            rvec=cv2.Rodrigues(cam.R)[0].ravel(),
            tvec=cam.t,
            name=cam.name,
        )
        for cam in rig
    ]
    group = CameraGroup(cams)
    return lambda uv: np.asarray(group.triangulate(uv, undistort=True, progress=False))


def opencv_peer(rig: Rig) -> Callable[[np.ndarray], np.ndarray] | str:
    try:
        import cv2
    except ImportError as exc:
        return f"OpenCV not installed ({exc})"
    Rt = [np.column_stack([cam.R, cam.t]) for cam in rig]

    def run(uv: np.ndarray) -> np.ndarray:
        seen = np.all(np.isfinite(uv), axis=-1)
        first = np.argmax(seen, axis=0)
        second = np.argmax(seen & (np.arange(len(rig))[:, None] > first), axis=0)
        normalized = np.full(uv.shape, np.nan)
        for c, cam in enumerate(rig):
            pts = uv[c, seen[c]].reshape(-1, 1, 2)
            normalized[c, seen[c]] = cv2.undistortPoints(pts, cam.K, cam.dist).reshape(-1, 2)
        out = np.full((uv.shape[1], 3), np.nan)
        pair = first * len(rig) + second
        for key in np.unique(pair):
            idx = np.flatnonzero(pair == key)
            a, b = divmod(int(key), len(rig))
            h = cv2.triangulatePoints(Rt[a], Rt[b], normalized[a, idx].T, normalized[b, idx].T)
            out[idx] = (h[:3] / h[3]).T
        return out

    return run


def numpy_dlt_peer(rig: Rig) -> Callable[[np.ndarray], np.ndarray] | str:
    try:
        import cv2
    except ImportError as exc:
        return f"OpenCV not installed ({exc})"
    Rt = np.stack([np.column_stack([cam.R, cam.t]) for cam in rig])  # (C, 3, 4)

    def run(uv: np.ndarray) -> np.ndarray:
        seen = np.all(np.isfinite(uv), axis=-1)  # (C, N)
        xy = np.zeros(uv.shape)
        for c, cam in enumerate(rig):
            pts = uv[c, seen[c]].reshape(-1, 1, 2)
            xy[c, seen[c]] = cv2.undistortPoints(pts, cam.K, cam.dist).reshape(-1, 2)
        # rows x P3 - P1 and y P3 - P2 of each view; an unseen view's rows are zero
        w = seen[..., None].astype(np.float64)
        rows_x = (xy[..., 0:1] * Rt[:, None, 2] - Rt[:, None, 0]) * w  # (C, N, 4)
        rows_y = (xy[..., 1:2] * Rt[:, None, 2] - Rt[:, None, 1]) * w
        A = np.concatenate([rows_x, rows_y]).transpose(1, 0, 2)  # (N, 2C, 4)
        h = np.linalg.svd(A)[2][:, -1]  # (N, 4)
        return h[:, :3] / h[:, 3:]

    return run


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=100_000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    rig = ring_rig()
    X, uv = scene(rig, args.points, args.seed, 0.2)
    n = X.shape[0]
    views = np.all(np.isfinite(uv), axis=-1).sum(axis=0)
    _, ml = best_time(lambda: triangulate(rig, uv, refine=3), 1)
    floor = rms_mm(ml, X)
    head = {"bench": "triangulation", "points": n, "cameras": len(rig), "noise_px": 0.2}
    print(json.dumps({**head, "views_min": int(views.min()), "views_max": int(views.max()),
                      "views_mean": round(float(views.mean()), 3), "floor_rms_mm": floor}),
          flush=True)  # fmt: skip
    runs: list[tuple[str, str, Callable[[np.ndarray], np.ndarray] | str]] = [
        ("spotlab", "odle_1_worker", lambda a: triangulate(rig, a, workers=1)),
        ("spotlab", "odle_2_workers", lambda a: triangulate(rig, a, workers=2)),
        ("spotlab", "odle_unweighted", lambda a: triangulate(rig, a, iterations=0)),
        ("spotlab", "dlt", lambda a: triangulate(rig, a, "dlt")),
        ("spotlab", "dlt_plain", lambda a: triangulate(rig, a, "dlt", iterations=0)),
        ("spotlab", "odle_refine2", lambda a: triangulate(rig, a, refine=2)),
        ("numpy", "dlt_normalised_all_views", numpy_dlt_peer(rig)),
        ("aniposelib", "triangulate_all_views", aniposelib_peer(rig)),
        ("opencv", "triangulatePoints_2_views", opencv_peer(rig)),
    ]
    rows: list[dict[str, Any]] = []
    for tool, method, fn in runs:
        row: dict[str, Any] = {**head, "tool": tool, "method": method}
        rows.append(row)
        if isinstance(fn, str):
            row["skipped"] = fn
        else:
            slow_peer = tool not in ("spotlab", "numpy")
            repeats = max(1, min(args.repeats, 2)) if slow_peer else args.repeats
            seconds, estimate = best_time(lambda fn=fn: fn(uv), repeats)
            err = rms_mm(estimate, X)
            row.update(
                seconds=round(seconds, 4),
                points_per_s=round(n / seconds),
                rms_mm=round(err, 5),
                ratio_to_floor=round(err / floor, 4),
                reconstructed=int(np.all(np.isfinite(estimate), axis=-1).sum()),
            )
    peer = next((r for r in rows if r["tool"] == "numpy" and "seconds" in r), None)
    for row in rows:
        if peer is not None and row["tool"] == "spotlab" and "seconds" in row:
            row["x_numpy_dlt"] = round(peer["seconds"] / row["seconds"], 2)
        print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
