"""Marker identification on the simulated CEN hub: labels, ghosts, 3-D error and speed.

Prints one JSON object per seed. Scene (issue 6): the video-centroid simulator
(:mod:`spotlab.simulators.centroid`: 8 cameras 1280x1024 of the reference ring rig, the
40-marker walking body with body-segment occlusion, merged blobs, floor-reflection
ghosts, noise blobs) run in process and decoded by the host driver
(:func:`spotlab.testing.centroid_scene.centroid_scene`), so the blobs are those a
recording holds. Each seed is a subject (size, speed, marker placement, soft tissue).
The marker model is learnt, with :meth:`MarkerModel.infer`'s defaults, from other
frames of the same subject: the ``--train`` seconds of its walk after the scored part
(out of sample in time; a new subject's model comes from a template, see
docs/identification.md).

Figures (marker-frames; "possible" = two or more of the marker's own unmerged blobs,
what correctly matched blobs can reconstruct):

* ``right_label_fraction``: reported with their own label within ``--tolerance`` mm of
  the truth, over the possible ones;
* ``wrong_label_fraction``: reported within the tolerance of another marker (a wrong
  label), over all reported;
* ``ghost_fraction``: reported farther than the tolerance from every marker (a ghost,
  reflection or noise point), over all reported;
* ``rms_mm`` vs ``oracle_rms_mm``: 3-D RMS error of the right reported markers, and of
  triangulating each marker's own unmerged blobs on the same marker-frames;
* ``fps``: frames identified per second of wall time in one thread (simulation and
  decoding not counted); ``cpu_fps``: the same per second of the process's CPU time,
  steadier than ``fps`` on a machine other work shares.

Harder variants: ``--ghost-rate 0.3`` (a reflection in 30 % of the (camera, marker)
pairs: ghost points seen by several cameras) and ``--dropouts 0.2`` (each marker hidden
from every camera 0.2 times a second for 10-90 frames, a hand over it: its label must
come back after the gap).

Usage: ``python benchmarks/identification.py [--seconds 60] [--rate 300] [--seeds 0 1 2]
[--ghost-rate 0.02] [--dropouts 0]``
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from spotlab.reconstruction import triangulate
from spotlab.reconstruction.identification import Identifier, MarkerModel
from spotlab.testing.centroid_scene import centroid_scene


def dropouts(shape: tuple[int, int], per_s: float, rate: float, seed: int) -> np.ndarray:
    """(F, M) True where a marker is hidden from every camera: ``per_s`` events per marker
    and second, each 10-90 frames long."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0xD809]))
    F, M = shape
    hidden = np.zeros(shape, dtype=bool)
    n = rng.poisson(per_s * F / rate * M)
    for f, length, m in zip(
        rng.integers(0, F, n), rng.integers(10, 91, n), rng.integers(0, M, n), strict=True
    ):
        hidden[f : f + length, m] = True
    return hidden


def run(args: argparse.Namespace, seed: int) -> dict:
    """Simulate, identify and score one seed."""
    seconds, rate, train_s, tolerance = args.seconds, args.rate, args.train, args.tolerance
    start = time.perf_counter()
    scene = centroid_scene(seconds, rate, seed=seed, ghost_rate=args.ghost_rate)
    if args.dropouts > 0:
        shape = scene.markers_mm.shape[:2]
        scene = scene.hidden(dropouts(shape, args.dropouts, rate, seed))
    generated = time.perf_counter() - start
    # The same subject (each seed is one), other frames: the walk after the scored part.
    training = centroid_scene(seconds + train_s, rate, seed=seed, ghost_rate=0.0)
    model = MarkerModel.infer(training.labels, training.markers_mm[round(seconds * rate) :])
    identify = Identifier(scene.rig, model)
    F, M = scene.markers_mm.shape[:2]
    points = np.full((F, M, 3), np.nan)
    ghosts = unlabelled = 0
    start, cpu_start = time.perf_counter(), time.process_time()
    for f in range(F):
        result = identify(scene.frame(f), scene.unusable(f))
        points[f] = result.points
        ghosts += result.ghosts
        unlabelled += result.unlabelled
    seconds_taken = time.perf_counter() - start
    cpu_taken = time.process_time() - cpu_start
    truth = scene.markers_mm
    err = np.linalg.norm(points - truth, axis=-1)
    reported = np.isfinite(err)
    right = reported & (err < tolerance)
    nearest = np.full((F, M), np.inf)
    for m in range(M):  # distance of each reported point to the nearest true marker
        d = np.linalg.norm(points[:, :, None] - truth[:, None, m : m + 1], axis=-1)[..., 0]
        nearest = np.fmin(nearest, np.where(np.isfinite(d), d, np.inf))
    wrong = reported & ~right & (nearest < tolerance)
    ghost = reported & ~right & ~wrong
    clean = scene.oracle_uv()
    possible = np.isfinite(clean[..., 0]).sum(axis=0) >= 2
    oracle = triangulate(scene.rig, clean)
    oracle_err = np.linalg.norm(oracle - truth, axis=-1)
    both = right & np.isfinite(oracle_err)
    kind = np.bincount(scene.blob_kind, minlength=5) / max(1, scene.blob_kind.size)
    n_reported = max(1, int(reported.sum()))
    per_marker = right.sum(axis=0) / np.maximum(possible.sum(axis=0), 1)
    worst = np.argsort(per_marker)[:3]
    return {
        "benchmark": "identification",
        "seed": seed,
        "cameras": scene.blobs.n_cameras,
        "markers": M,
        "rate_hz": rate,
        "seconds": seconds,
        "frames": F,
        "ghost_rate": args.ghost_rate,
        "dropouts_per_s": args.dropouts,
        "segments": len(model.segments),
        "links": len(model.links),
        "blobs_per_frame": round(scene.blob_kind.size / F, 1),
        "merged_blob_fraction": round(float(kind[1]), 5),
        "ghost_blob_fraction": round(float(kind[2]), 5),
        "noise_blob_fraction": round(float(kind[3] + kind[4]), 5),
        "possible_fraction": round(float(possible.mean()), 5),
        "right_label_fraction": round(float(right[possible].mean()), 6),
        "wrong_label_fraction": round(float(wrong.sum() / n_reported), 6),
        "ghost_fraction": round(float(ghost.sum() / n_reported), 6),
        "worst_markers": {scene.labels[m]: round(float(per_marker[m]), 4) for m in worst},
        "reflections_rejected_per_frame": round(ghosts / F, 2),
        "unlabelled_per_frame": round(unlabelled / F, 3),
        "rms_mm": round(float(np.sqrt(np.mean(err[both] ** 2))), 4),
        "oracle_rms_mm": round(float(np.sqrt(np.mean(oracle_err[both] ** 2))), 4),
        "fps": round(F / seconds_taken, 1),
        "cpu_fps": round(F / cpu_taken, 1),
        "ms_per_frame": round(1000 * seconds_taken / F, 3),
        "simulation_s": round(generated, 1),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--rate", type=float, default=300.0)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--train", type=float, default=2.5, help="training trial (s)")
    parser.add_argument("--tolerance", type=float, default=10.0, help="mm")
    parser.add_argument(
        "--ghost-rate", type=float, default=0.02, help="(camera, marker) pairs seeing a reflection"
    )
    parser.add_argument(
        "--dropouts", type=float, default=0.0, help="per marker and s: hidden from all cameras"
    )
    args = parser.parse_args()
    for seed in args.seeds:
        print(json.dumps(run(args, seed)))


if __name__ == "__main__":
    main()
