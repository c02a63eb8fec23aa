"""A new subject's first labels from a generic template, scored on the subject's walk.

Prints one JSON object per seed (each seed of the simulated hub is another subject).
Pipeline, in process (:func:`spotlab.testing.centroid_scene.centroid_scene`: the blobs
a recording of ``spotlab sim centroid`` holds, decoded by the host driver):

1. the static trial (``--motion static``, ``--static`` s): blobs matched into points
   and clustered over the frames (``static_cloud``), the ``spotlab-body`` template fitted
   (``fit_template``), the subject's first model M0 (``first_model``);
2. the same subject's ROM trial (``--motion rom``, ``--rom`` s), its first frame
   labelled by fitting the subject's static pose, then identified with M0
   (``label_trial``); the final model learnt from it (``learn_model``);
3. the same subject's walk (``--walk`` s) identified with the final model, cold:
   forward only, as live labelling does (``walk_*``), and forward and backward joined,
   as ``spotlab reconstruct`` does (``walk_both_ways_*``, with ``filled_backward`` and
   ``label_conflicts``: :mod:`spotlab.processing.identification_passes`).

The simulator's truth is read only at the end, to score: ``static_wrong`` (static points
labelled farther than 10 mm from their marker), ``rom_right``/``walk_right`` (marker-
frames reported with their own label within 10 mm, over all marker-frames: coverage),
``rom_wrong``/``walk_wrong`` (reported farther than 10 mm from their own marker, over
the reported ones), and the walk's least covered markers.

    .venv/bin/python benchmarks/new_subject.py --seeds 5 6 7
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Iterator
from typing import Any

import numpy as np

from spotlab.processing.identification_passes import identify_both_ways
from spotlab.reconstruction.identification import BlobFrame, RigGeometry
from spotlab.reconstruction.identification.static_cloud import static_cloud
from spotlab.reconstruction.identification.subject_model import (
    first_model,
    label_trial,
    learn_model,
    subject_template,
)
from spotlab.reconstruction.identification.template import fit_template, load_template
from spotlab.testing.centroid_scene import CentroidScene, centroid_scene


def _frames(scene: CentroidScene) -> Iterator[tuple[BlobFrame, Any]]:
    return ((scene.frame(f), scene.unusable(f)) for f in range(len(scene)))


def _score(
    points: np.ndarray, scene: CentroidScene, labels: tuple[str, ...]
) -> tuple[float, float]:
    truth = scene.markers_mm[:, [scene.labels.index(x) for x in labels]]
    reported = np.isfinite(points[..., 0])
    near = np.linalg.norm(points - truth, axis=2) < 10.0
    return float((reported & near).mean()), float((reported & ~near).sum() / max(reported.sum(), 1))


def run(seed: int, static_s: float, rom_s: float, walk_s: float, rate: float) -> dict[str, Any]:
    t0 = time.perf_counter()
    body = load_template("spotlab-body")
    static = centroid_scene(static_s, rate, seed=seed, motion="static")
    cloud = static_cloud([static.frame(f) for f in range(len(static))], RigGeometry(static.rig))
    fit = fit_template(cloud.points, body)
    m0 = first_model(cloud.points, fit, body)
    rom = centroid_scene(rom_s, rate, seed=seed, motion="rom")
    labelled, start = label_trial(
        rom.rig, _frames(rom), m0, subject_template(cloud.points, fit, body, m0)
    )
    final = learn_model(m0, labelled)
    walk = centroid_scene(walk_s, rate, seed=seed)
    walked, _ = label_trial(walk.rig, _frames(walk), final)
    # offline, as spotlab reconstruct labels: forward and backward, joined
    frames = list(_frames(walk))
    usable = np.ones(len(frames), dtype=bool)
    numbers = np.arange(len(frames))
    joined, counts = identify_both_ways(walk.rig, final, frames, usable, numbers)
    # scoring, with the simulator's truth, only now
    truth = np.nanmedian(static.markers_mm, axis=0)
    marker = np.array([static.labels.index(x) for x in body.labels])
    ok = fit.marker_of >= 0
    static_wrong = int(
        (np.linalg.norm(truth[marker[fit.marker_of[ok]]] - cloud.points[ok], axis=1) > 10).sum()
    )
    rom_right, rom_wrong = _score(labelled, rom, m0.labels)
    walk_right, walk_wrong = _score(walked, walk, final.labels)
    both_right, both_wrong = _score(joined.points, walk, final.labels)
    cover = np.isfinite(walked[..., 0]).mean(axis=0)
    least = {final.labels[m]: round(float(cover[m]), 2) for m in np.argsort(cover)[:6]}
    return {
        "seed": seed, "static_points": int(cloud.points.shape[0]), "scale": round(fit.scale, 3),
        "yaw_deg": round(fit.yaw_deg, 1), "fit_rms_mm": round(fit.rms_mm, 1),
        "matched": fit.matched, "static_wrong": static_wrong,
        "rom_start_rms_mm": None if start is None else round(start.rms_mm, 1),
        "rom_right": round(rom_right, 4), "rom_wrong": round(rom_wrong, 5),
        "walk_right": round(walk_right, 4), "walk_wrong": round(walk_wrong, 5),
        "walk_both_ways_right": round(both_right, 4),
        "walk_both_ways_wrong": round(both_wrong, 5), **counts,
        "walk_least_covered": least,
        "seconds": round(time.perf_counter() - t0, 1),
    }  # fmt: skip


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[5])
    p.add_argument("--static", type=float, default=1.0, help="static trial, s")
    p.add_argument("--rom", type=float, default=6.0, help="ROM trial, s")
    p.add_argument("--walk", type=float, default=3.0, help="walk labelled, s")
    p.add_argument("--rate", type=float, default=100.0, help="frame rate, Hz")
    args = p.parse_args()
    for seed in args.seeds:
        print(json.dumps(run(seed, args.static, args.rom, args.walk, args.rate)), flush=True)


if __name__ == "__main__":
    main()
