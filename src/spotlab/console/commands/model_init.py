"""``spotlab model init`` and ``spotlab model learn ROM.spj``: a new subject's marker model.

``init`` fits a marker template to the subject's static trial (a video-centroid
recording): the trial's blobs are matched into unlabelled points and clustered over the
frames (:func:`~spotlab.reconstruction.identification.static_cloud.static_cloud`), the
template is fitted to them (scale, yaw, translation, labels:
:func:`~spotlab.reconstruction.identification.template.fit_template`) and the subject's
first model M0 is written: the template's structure with the subject's own static
coordinates (:func:`~spotlab.reconstruction.identification.subject_model.first_model`),
plus the subject's static pose, which ``learn`` fits to the first frame of the ROM trial.

``learn`` labels a range-of-motion (ROM) trial with M0 and writes the final model learnt
from it (:func:`~spotlab.reconstruction.identification.subject_model.learn_model`).

The lead wires these into ``spotlab model`` (:func:`add_init_parser`, :func:`run_init`,
:func:`run_learn_recording`).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from spotlab.console.errors import CommandError
from spotlab.core.errors import CalibrationError, ReconstructionError
from spotlab.processing.blob_trajectories import _frames, read_blob_recording
from spotlab.processing.trajectories import load_rig
from spotlab.reconstruction.identification import MarkerModel, RigGeometry
from spotlab.reconstruction.identification.static_cloud import static_cloud
from spotlab.reconstruction.identification.subject_model import (
    first_model,
    label_trial,
    learn_model,
    subject_template,
)
from spotlab.reconstruction.identification.template import (
    Template,
    fit_template,
    load_template,
    shipped_templates,
)

__all__ = ["STATIC_KEY", "add_init_parser", "run_init", "run_learn_recording"]

#: Key of the subject's static pose (a template JSON) in M0's JSON.
STATIC_KEY = "static_pose"


def add_init_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``init`` to the subparsers of ``spotlab model``."""
    p: argparse.ArgumentParser = subparsers.add_parser(
        "init",
        help="a new subject's first marker model from a static trial and a template",
        description="Fit a marker template to the subject standing still (a video-centroid "
        "recording) and write the subject's first model M0: the template's clusters and "
        "links with the subject's own static coordinates. Label a range-of-motion trial "
        "with it next: spotlab model learn ROM.spj --model M0.json.",
    )
    p.add_argument("input", type=Path, metavar="STATIC.spj", help="the static trial")
    p.add_argument(
        "--template", required=True, metavar="NAME|FILE",
        help=f"marker template: {', '.join(shipped_templates())}, or a template JSON file",
    )  # fmt: skip
    p.add_argument("--calibration", type=Path, required=True, help="rig (TOML)")
    p.add_argument("--out", type=Path, required=True, metavar="M0.json", help="model to write")
    p.set_defaults(run=run_init)
    return p


def _template(text: str) -> Template:
    try:
        return load_template(text)
    except ReconstructionError as exc:
        raise CommandError(f"--template: {exc}") from None


def _check_out(path: Path) -> None:
    if not path.parent.is_dir():
        raise CommandError(f"{path}: the folder {path.parent} does not exist")


def run_init(args: argparse.Namespace) -> int:
    """``spotlab model init``: fit the template, write M0, print the fit."""
    _check_out(args.out)
    template = _template(args.template)
    rig = load_rig(args.calibration)
    recording = read_blob_recording(args.input)
    if len(rig) != recording.blobs.n_cameras:
        raise CommandError(
            f"the recording has {recording.blobs.n_cameras} cameras but the calibration has "
            f"{len(rig)}"
        )
    frames = [frame for frame, _ in _frames(recording.blobs)]
    try:
        cloud = static_cloud(frames, RigGeometry(rig))
        fit = fit_template(cloud.points, template)
        m0 = first_model(cloud.points, fit, template)
        start = subject_template(cloud.points, fit, template, m0)
    except ReconstructionError as exc:
        raise CommandError(f"{args.input}: {exc}") from None
    data = m0.to_json()
    data[STATIC_KEY] = start.to_json()
    data["template_fit"] = {
        "template": template.name, "scale": round(fit.scale, 4),
        "yaw_deg": round(fit.yaw_deg, 2), "rms_mm": round(fit.rms_mm, 2),
        "matched": round(fit.matched, 4),
    }  # fmt: skip
    args.out.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    print(
        f"{args.input}: {cloud.points.shape[0]} points standing still in {cloud.frames} "
        f"frames ({cloud.dropped} left out: seen in too few frames)"
    )
    print(
        f"template {template.name}: scale {fit.scale:.3f}, yaw {fit.yaw_deg:.1f} deg, "
        f"RMS {fit.rms_mm:.1f} mm, {round(fit.matched * len(template.labels))} of "
        f"{len(template.labels)} markers matched"
    )
    order = np.argsort(-np.nan_to_num(fit.residual_mm, nan=np.inf))
    print("residuals (mm), worst first: " + ", ".join(
        f"{template.labels[m]} {fit.residual_mm[m]:.1f}" if np.isfinite(fit.residual_mm[m])
        else f"{template.labels[m]} missing" for m in order
    ))  # fmt: skip
    print(f"wrote {args.out} (M0: {len(m0.segments)} segments, {len(m0.links)} links)")
    return 0


def _load_m0(path: Path) -> tuple[MarkerModel, Template | None]:
    if not path.is_file():
        raise CommandError(f"{path}: no such marker model file")
    try:
        model = MarkerModel.load(path)
        data = json.loads(path.read_text(encoding="utf-8"))
        start = Template.from_json(data[STATIC_KEY], str(path)) if STATIC_KEY in data else None
    except (ReconstructionError, ValueError) as exc:
        raise CommandError(str(exc)) from None
    if start is not None and start.labels != model.labels:
        raise CommandError(f"{path}: its static pose names other markers than its model")
    return model, start


def run_learn_recording(args: argparse.Namespace) -> int:
    """``spotlab model learn ROM.spj --model M0.json``: label the ROM trial, learn, write.

    ``args``: ``input`` (the ROM recording), ``model`` (M0), ``calibration``, ``out``.
    """
    _check_out(args.out)
    m0, start = _load_m0(args.model)
    rig = load_rig(args.calibration)
    recording = read_blob_recording(args.input)
    if len(rig) != recording.blobs.n_cameras:
        raise CommandError(
            f"the recording has {recording.blobs.n_cameras} cameras but the calibration has "
            f"{len(rig)}"
        )
    try:
        X, fit = label_trial(rig, _frames(recording.blobs), m0, start)
        final = learn_model(m0, X)
    except (ReconstructionError, CalibrationError) as exc:
        raise CommandError(f"{args.input}: {exc}") from None
    final.save(args.out)
    seen = np.isfinite(X[..., 0]).mean(axis=0)
    if fit is not None:
        print(f"static pose: fits frame {fit.frame} best, RMS {fit.rms_mm:.1f} mm")
    print(
        f"{args.input}: {X.shape[0]} frames, {seen.mean():.1%} of the marker-frames labelled "
        "with M0; least labelled: "
        + ", ".join(f"{m0.labels[m]} {seen[m]:.0%}" for m in np.argsort(seen)[:5])
    )
    print(f"wrote {args.out} ({len(final.segments)} segments, {len(final.links)} links)")
    return 0
