"""Planar-grid calibration: Zhang's reference set and SMAC on a synthetic rig (JSON lines).

1. ``zhang``: :func:`spotlab.calibration.calibrate_intrinsics` on Zhang's five images
   (shared/data/zhang1998), with and without skew, beside OpenCV's ``calibrateCamera``
   on the same points (k1, k2 only, as Zhang's model) when cv2 is installed (bench
   extra). Times are the median of ``--repeat`` runs.
2. ``smac``: :func:`spotlab.calibration.smac_calibrate` with 4 cameras of 1280 x 1024 px
   (``ring_rig``, radius 3 m), a 10 x 10 grid of 80 mm pitch at 20 poses, 0.2 px noise,
   all five distortion terms; reprojection RMS per camera and the 3-D RMS error of a
   held-out 21st grid pose triangulated with the calibrated rig and with the true one.

Usage: ``python benchmarks/planar_calibration.py [--repeat 5] [--data ../shared/data]``
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from spotlab.calibration import calibrate_intrinsics, smac_calibrate
from spotlab.geometry import Camera, Rig
from spotlab.simulators.rigs import ring_rig

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def timed(fn: Callable[[], Any], repeat: int) -> tuple[Any, float]:
    """Result of ``fn`` and the median wall time of ``repeat`` calls (s)."""
    times, out = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - start)
    return out, float(np.median(times))


def intrinsics_row(K: np.ndarray, dist: np.ndarray) -> dict[str, float]:
    return {
        "fx": round(float(K[0, 0]), 4),
        "fy": round(float(K[1, 1]), 4),
        "gamma": round(float(K[0, 1]), 6),
        "cx": round(float(K[0, 2]), 4),
        "cy": round(float(K[1, 2]), 4),
        "k1": round(float(dist[0]), 6),
        "k2": round(float(dist[1]), 6),
    }


def zhang(data: Path, repeat: int) -> None:
    folder = data / "zhang1998"
    model = np.loadtxt(folder / "Model.txt").reshape(-1, 2)
    uv = np.array([np.loadtxt(folder / f"data{i}.txt").reshape(-1, 2) for i in range(1, 6)])
    published = {"fx": 832.5, "fy": 832.53, "gamma": 0.204494, "cx": 303.959, "cy": 206.585}
    print(
        json.dumps(
            {"bench": "zhang", "tool": "published", **published, "k1": -0.228601, "k2": 0.190353}
        )
    )
    for skew in (False, True):
        res, sec = timed(lambda s=skew: calibrate_intrinsics(model, uv, (640, 480), skew=s), repeat)
        row = {"bench": "zhang", "tool": "spotlab", "skew": skew, "seconds": round(sec, 4)}
        row |= intrinsics_row(res.camera.K, res.camera.dist)
        row |= {"rms_px": round(res.rms_px, 4), "iterations": res.iterations}
        print(json.dumps(row))
    try:
        import cv2
    except ImportError:
        print(json.dumps({"bench": "zhang", "tool": "opencv", "skipped": "cv2 not installed"}))
        return
    obj = [np.column_stack([model, np.zeros(len(model))]).astype(np.float32)] * 5
    img = [v.astype(np.float32) for v in uv]
    flags = cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K3
    (rms, K, dist, _, _), sec = timed(
        lambda: cv2.calibrateCamera(obj, img, (640, 480), None, None, flags=flags), repeat
    )
    # OpenCV's rms is sqrt(sum |r|^2 / N): the same distance RMS as ours.
    row = {"bench": "zhang", "tool": f"opencv {cv2.__version__}", "skew": False}
    row |= {"seconds": round(sec, 4), **intrinsics_row(K, dist.ravel())}
    print(json.dumps(row | {"rms_px": round(float(rms), 4)}))


def triangulate(rig: Rig, uv: np.ndarray) -> np.ndarray:
    """Least-squares intersection of the viewing rays, (N, 3) from uv (C, N, 2)."""
    normal = np.zeros((uv.shape[1], 3, 3))
    rhs = np.zeros((uv.shape[1], 3))
    for cam, pts in zip(rig, uv, strict=True):
        valid = np.isfinite(pts[:, 0])
        rays = np.column_stack([cam.normalize(np.nan_to_num(pts)), np.ones(len(pts))]) @ cam.R
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        proj = np.where(valid[:, None, None], np.eye(3) - np.einsum("ni,nj->nij", rays, rays), 0)
        normal += proj
        rhs += np.einsum("nij,j->ni", proj, cam.center)
    return np.linalg.solve(normal, rhs[..., None])[..., 0]


def smac(repeat: int, n_views: int = 20, noise: float = 0.2, seed: int = 3) -> None:
    rig = ring_rig(4, radius_mm=3000.0, height_mm=2400.0, seed=seed)
    rng = np.random.default_rng(seed)
    pitch = (np.arange(10) - 4.5) * 80.0
    grid = np.stack(np.meshgrid(pitch, pitch), -1).reshape(-1, 2)
    grid3 = np.column_stack([grid, np.zeros(len(grid))])
    uv = np.full((4, n_views + 1, len(grid), 2), np.nan)
    poses = []
    for v in range(n_views + 1):
        R = Rotation.from_rotvec([*rng.uniform(-0.8, 0.8, 2), rng.uniform(-np.pi, np.pi)])
        t = np.array([0.0, 0.0, 900.0]) + rng.uniform(-400.0, 400.0, 3)
        poses.append((R.as_matrix(), t))
        X = R.apply(grid3) + t
        for c, cam in enumerate(rig):
            sight = (cam.center - t) / np.linalg.norm(cam.center - t)
            if abs(sight @ R.as_matrix()[:, 2]) < np.cos(np.radians(75.0)):
                continue  # grid too edge-on for this camera
            pix = cam.project(X)
            keep = np.all((pix >= 0) & (pix < cam.size), axis=1)
            uv[c, v, keep] = pix[keep] + noise * rng.standard_normal((int(keep.sum()), 2))
    res, sec = timed(
        lambda: smac_calibrate(grid, uv[:, :n_views], (1280, 1024), distortion=True), repeat
    )
    R0, t0 = poses[0]
    truth = Rig(Camera(c.K, c.dist, c.R @ R0, c.R @ t0 + c.t, c.size, c.name) for c in rig)
    R, t = poses[n_views]
    X_true = (grid3 @ R.T + t - t0) @ R0
    held = uv[:, n_views]
    errors = {
        name: float(np.sqrt(np.mean(np.sum((triangulate(r, held) - X_true) ** 2, axis=1))))
        for name, r in (("calibrated", res.rig), ("true", truth))
    }
    row = {
        "bench": "smac",
        "cameras": 4,
        "views": n_views,
        "points": len(grid),
        "noise_px": noise,
        "seconds": round(sec, 4),
        "iterations": res.report["iterations"],
        "rms_px": [round(float(x), 4) for x in res.rms_px],
        "held_out_3d_rms_mm": round(errors["calibrated"], 4),
        "held_out_3d_rms_true_rig_mm": round(errors["true"], 4),
        "principal_distance_error_px": [
            round(float(abs(a.K[0, 0] - b.K[0, 0])), 3) for a, b in zip(res.rig, truth, strict=True)
        ],
        "center_error_mm": [
            round(float(np.linalg.norm(a.center - b.center)), 3)
            for a, b in zip(res.rig, truth, strict=True)
        ],
    }
    print(json.dumps(row))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--data", type=Path, default=DATA)
    args = parser.parse_args(argv)
    zhang(args.data, args.repeat)
    smac(args.repeat)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
