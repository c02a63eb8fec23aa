"""``spotlab model``: marker models for identification, learnt from labelled trials.

* ``spotlab model learn TRIAL.c3d|TRIAL.trc [--markers L1 L2 ...] [--frames A:B]
  --out MODEL.json``: rigid clusters and distance links found in the trial
  (:meth:`MarkerModel.infer`), with the rigid tolerance chosen from the trial's own
  distance spreads (printed);
* ``spotlab model show MODEL.json``: its markers, segments, links and tolerances;
* ``spotlab model check MODEL.json TRIAL.c3d|TRIAL.trc [--frames A:B]``: how well the
  trial fits the model, marker by marker (:func:`model_fit`);
* ``spotlab model init STATIC.spj --template NAME|FILE --calibration RIG.toml --out
  M0.json`` and ``spotlab model learn ROM.spj --model M0.json --calibration RIG.toml
  --out MODEL.json``: a new subject's models (:mod:`.model_init`).

Reading is :mod:`spotlab.io.trial_files`, the methods are in
:mod:`spotlab.reconstruction.identification`; this module parses and prints.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from spotlab.console.commands.model_init import add_init_parser, run_learn_recording
from spotlab.console.errors import EXIT_USAGE, CommandError
from spotlab.core.errors import ReconstructionError
from spotlab.io import labelled_markers, read_trial
from spotlab.processing.paths import check_output_paths
from spotlab.reconstruction.identification import MarkerModel, model_fit


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "model",
        help="learn, show, check or init a marker model for identification",
        description="Marker models (rigid clusters and distance links) for labelling markers.",
    )
    actions = p.add_subparsers(dest="action", metavar="ACTION", help="learn, show, check or init")
    actions.required = True

    learn = actions.add_parser(
        "learn",
        help="learn a model from a labelled trial (C3D or TRC)",
        description="Find the rigid clusters and distance links of a labelled trial; the "
        "rigid tolerance is chosen from the trial's distance spreads.",
    )
    learn.add_argument(
        "trial", type=Path,
        help="TRIAL.c3d or TRIAL.trc (labelled), or ROM.spj (a video-centroid recording of "
        "a range-of-motion trial, labelled with --model M0.json and --calibration)",
    )  # fmt: skip
    _markers_and_frames(learn)
    learn.add_argument(
        "--model", type=Path, metavar="M0.json",
        help="with ROM.spj: the subject's first model (spotlab model init)",
    )  # fmt: skip
    learn.add_argument("--calibration", type=Path, metavar="RIG.toml", help="with ROM.spj: the rig")
    learn.add_argument("--out", type=Path, required=True, help="MODEL.json to write")
    learn.add_argument(
        "--tolerance",
        type=float,
        metavar="MM",
        help="rigid tolerance (default: chosen from the trial)",
    )
    learn.add_argument(
        "--link-spread",
        type=float,
        metavar="MM",
        help="largest distance spread of a link (default: 5 tolerances, at least 50 mm)",
    )
    learn.set_defaults(run=run_learn)
    add_init_parser(actions)

    show = actions.add_parser("show", help="print a model's markers, segments and links")
    show.add_argument("model", type=Path, help="MODEL.json")
    show.add_argument("--json", action="store_true", help="print the model file's JSON")
    show.set_defaults(run=run_show)

    check = actions.add_parser(
        "check",
        help="how well a labelled trial fits a model, marker by marker",
        description="Distance residuals of each marker of a labelled trial against its "
        "segment mates and links in the model (RMS and largest, mm).",
    )
    check.add_argument("model", type=Path, help="MODEL.json")
    check.add_argument("trial", type=Path, help="TRIAL.c3d or TRIAL.trc")
    check.add_argument("--frames", metavar="A:B", help="frames A to B-1 (from 0)")
    check.add_argument("--json", action="store_true", help="print one JSON object")
    check.set_defaults(run=run_check)


def _markers_and_frames(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--markers",
        nargs="+",
        metavar="LABEL",
        help="markers to take (default: every named marker seen in half the frames)",
    )
    p.add_argument(
        "--frames", metavar="A:B", help="frames A to B-1, from 0 at the file's first frame"
    )


def parse_frames(text: str | None) -> tuple[int | None, int | None] | None:
    """``A:B``, ``A:`` or ``:B`` as (start, stop); None for no --frames."""
    if text is None:
        return None
    parts = text.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        start, stop = (int(x) if x.strip() else None for x in parts)
    except ValueError:
        raise CommandError(
            f"--frames {text}: expected A:B (frames A to B-1, from 0)", EXIT_USAGE
        ) from None
    return start, stop


def run_learn(args: argparse.Namespace) -> int:
    if args.model is not None or args.trial.suffix.lower() == ".spj":
        if args.model is None or args.calibration is None:
            raise CommandError(
                f"{args.trial}: a recording is learnt from with --model M0.json (spotlab "
                "model init) and --calibration RIG.toml",
                EXIT_USAGE,
            )
        args.input = args.trial
        return run_learn_recording(args)
    if args.out.suffix.lower() != ".json":
        raise CommandError(f"--out {args.out}: the model file name must end in .json", EXIT_USAGE)
    check_output_paths([("--out", args.out)])
    for flag, value in (("--tolerance", args.tolerance), ("--link-spread", args.link_spread)):
        if value is not None and not value > 0:
            raise CommandError(f"{flag} must be positive (mm), not {value:g}", EXIT_USAGE)
    frames = parse_frames(args.frames)
    trial = read_trial(args.trial)
    labels, positions = labelled_markers(trial, args.trial, markers=args.markers, frames=frames)
    try:
        model = MarkerModel.infer(
            labels, positions, tolerance_mm=args.tolerance, link_spread_mm=args.link_spread
        )
    except ReconstructionError as exc:
        raise CommandError(f"{args.trial}: {exc}") from None
    model.save(args.out)
    how = "given" if args.tolerance is not None else "chosen from the trial's distance spreads"
    print(f"{args.out}: {len(labels)} markers from {positions.shape[0]} frames of {args.trial}")
    print(f"rigid tolerance {model.tolerance_mm:.1f} mm ({how})")
    print(f"link spread {model.link_spread_mm:.1f} mm")
    _print_structure(model)
    return 0


def run_show(args: argparse.Namespace) -> int:
    model = MarkerModel.load(args.model)
    if args.json:
        print(json.dumps(model.to_json(), indent=1))
        return 0
    print(f"{args.model}: {len(model.labels)} markers")
    if model.tolerance_mm is not None:
        print(f"rigid tolerance {model.tolerance_mm:.1f} mm")
    if model.link_spread_mm is not None:
        print(f"link spread {model.link_spread_mm:.1f} mm")
    _print_structure(model)
    return 0


def _print_structure(model: MarkerModel) -> None:
    """Segments with their markers, then the markers labelled by their links alone."""
    print(f"{len(model.segments)} rigid segments, {len(model.links)} links")
    for seg in model.segments:
        print(f"  {seg.name}: {' '.join(model.labels[m] for m in seg.markers)}")
    links = np.zeros(len(model.labels), dtype=int)
    for link in model.links:
        links[[link.a, link.b]] += 1
    loose = [m for m in range(len(model.labels)) if model.segment_of[m] < 0]
    if loose:
        print("  by links alone: " + " ".join(f"{model.labels[m]}({links[m]})" for m in loose))


def run_check(args: argparse.Namespace) -> int:
    model = MarkerModel.load(args.model)
    frames = parse_frames(args.frames)
    trial = read_trial(args.trial)
    labels, positions = labelled_markers(
        trial, args.trial, markers=list(model.labels), frames=frames
    )
    fit = model_fit(model, labels, positions)
    worst = fit.worst
    first = frames[0] if frames is not None and frames[0] is not None else 0
    at = np.where(fit.worst_frame >= 0, fit.worst_frame + first, -1)  # file frames from 0
    if args.json:
        print(
            json.dumps(
                {
                    "model": str(args.model),
                    "trial": str(args.trial),
                    "frames": int(positions.shape[0]),
                    "markers": {
                        name: {
                            "rms_mm": _num(fit.rms_mm[m]),
                            "max_mm": _num(fit.max_mm[m]),
                            "worst_frame": int(at[m]),
                            "seen": round(float(fit.seen[m]), 4),
                        }
                        for m, name in enumerate(fit.labels)
                    },
                    "worst": fit.labels[worst] if worst >= 0 else None,
                }
            )
        )
        return 0
    print(f"{args.trial} against {args.model}: {positions.shape[0]} frames")
    print(f"{'marker':<20} {'seen':>6} {'rms mm':>8} {'max mm':>8} {'at frame':>8}")
    for m in np.argsort(-np.nan_to_num(fit.rms_mm, nan=-1.0)):
        print(
            f"{fit.labels[m]:<20} {100 * fit.seen[m]:5.1f}% {fit.rms_mm[m]:8.2f} "
            f"{fit.max_mm[m]:8.2f} {at[m]:8d}"
        )
    if worst >= 0:
        print(
            f"worst: {fit.labels[worst]} (RMS {fit.rms_mm[worst]:.2f} mm, "
            f"{fit.max_mm[worst]:.2f} mm at frame {at[worst]})"
        )
    return 0


def _num(x: float) -> float | None:
    return round(float(x), 3) if np.isfinite(x) else None
