"""Marker identification: labels, ghosts, 3-D error and speed for 8 cameras x 40 markers.

Prints one JSON object. Scene (issue 6): the reference ring rig (8 cameras 1280x1024,
distortion) watching :class:`spotlab.testing.synthetic_body.WalkingBody` (40 markers on
13 rigid segments) at 300 Hz, with self-occlusion, occlusion events of one camera and of
all cameras, merged blobs, floor reflections and specks, 0.2 px centroid noise
(:func:`spotlab.testing.synthetic_blobs.synthetic_blobs`). The marker model is learnt
from the first 10 frames of the truth.

Figures:

* ``right_label_fraction``: marker-frames reported with their own label within
  ``--tolerance`` mm of the truth, over the marker-frames that correctly matched blobs
  can reconstruct (two or more unmerged blobs of the marker);
* ``ghost_fraction``: reported marker-frames farther than the tolerance from their
  labelled marker (a ghost, a reflection or a wrong label), over all reported;
* ``rms_mm`` vs ``oracle_rms_mm``: 3-D RMS error of the reported markers, and of
  triangulating each marker's own unmerged blobs (the oracle association) on the same
  marker-frames;
* ``fps``: frames identified per second of wall time in one thread (blob generation
  not counted).

Usage: ``python benchmarks/identification.py [--seconds 60] [--rate 300] [--seed 0]``
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from spotlab.reconstruction import triangulate
from spotlab.reconstruction.identification import Identifier, MarkerModel
from spotlab.simulators.rigs import ring_rig
from spotlab.testing.synthetic_blobs import synthetic_blobs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--rate", type=float, default=300.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--tolerance", type=float, default=10.0, help="mm")
    args = parser.parse_args()
    rig = ring_rig(8)
    start = time.perf_counter()
    scene = synthetic_blobs(rig, args.seconds, args.rate, seed=args.seed)
    generated = time.perf_counter() - start
    model = MarkerModel.from_trajectories(scene.labels, scene.markers_mm[:10], scene.segments)
    identify = Identifier(rig, model)
    F, M = scene.markers_mm.shape[:2]
    points = np.full((F, M, 3), np.nan)
    ghosts = unlabelled = 0
    start = time.perf_counter()
    for f in range(F):
        result = identify(scene.frame(f))
        points[f] = result.points
        ghosts += result.ghosts
        unlabelled += result.unlabelled
    seconds = time.perf_counter() - start
    truth = scene.markers_mm
    err = np.linalg.norm(points - truth, axis=-1)
    reported = np.isfinite(err)
    right = reported & (err < args.tolerance)
    possible = np.isfinite(scene.clean_uv[..., 0]).sum(axis=0) >= 2
    oracle = triangulate(rig, scene.clean_uv)
    oracle_err = np.linalg.norm(oracle - truth, axis=-1)
    both = right & np.isfinite(oracle_err)
    blobs = scene.source.size
    row = {
        "benchmark": "identification",
        "cameras": len(rig),
        "markers": M,
        "rate_hz": args.rate,
        "seconds": args.seconds,
        "frames": F,
        "blobs_per_frame": round(blobs / F, 1),
        "merged_blob_fraction": round(float(scene.merged.mean()), 5),
        "reflection_blob_fraction": round(float((scene.source >= M).mean()), 5),
        "speck_blob_fraction": round(float((scene.source < 0).mean()), 5),
        "reconstructible_fraction": round(float(possible.mean()), 5),
        "right_label_fraction": round(float(right[possible].mean()), 6),
        "right_label_fraction_all": round(float(right.sum() / possible.sum()), 6),
        "ghost_fraction": round(float((reported & ~right).sum() / max(1, reported.sum())), 6),
        "reflections_rejected_per_frame": round(ghosts / F, 2),
        "unlabelled_per_frame": round(unlabelled / F, 3),
        "rms_mm": round(float(np.sqrt(np.mean(err[both] ** 2))), 4),
        "oracle_rms_mm": round(float(np.sqrt(np.mean(oracle_err[both] ** 2))), 4),
        "fps": round(F / seconds, 1),
        "ms_per_frame": round(1000 * seconds / F, 3),
        "generation_s": round(generated, 1),
    }
    print(json.dumps(row))


if __name__ == "__main__":
    main()
