"""``spotlab calibrate``: wand self-calibration of a rig from observations.

Reads observations (npz arrays, CSV tables, or a wand-dance recording with a static
recording of the reference object; see :mod:`spotlab.console.calibration_inputs`), runs
:func:`spotlab.calibration.wand_calibrate` from a cold start, writes the calibration
(TOML in the anipose / Pose2Sim layout), the quality report (JSON) and its figure (PNG).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from spotlab.calibration import wand_calibrate, write_report_figure
from spotlab.console.calibration_inputs import (
    WandObservations,
    load_csv,
    load_npz,
    load_recordings,
)
from spotlab.console.decoding import input_suffix
from spotlab.console.errors import CommandError
from spotlab.console.paths import check_output_paths


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "calibrate",
        help="calibrate a camera rig from a wand dance and a reference object",
        description="Wand self-calibration from a cold start: no initial guess needed. "
        "Writes the rig (TOML), a quality report (JSON) and its figure (PNG).",
    )
    p.add_argument(
        "observations",
        type=Path,
        help="npz arrays, a wand CSV table (with --frame), or a wand-dance recording "
        "(.spj, with --wand-markers, --frame-recording, --frame-markers, --frame-points)",
    )
    p.add_argument("--out", type=Path, required=True, help="calibration file to write (.toml)")
    p.add_argument("--wand-length", type=float, help="wand length in mm (or in the npz)")
    p.add_argument("--frame", type=Path, help="reference-object CSV table (CSV input)")
    p.add_argument("--image-size", type=int, nargs=2, metavar=("W", "H"), help="pixels")
    p.add_argument(
        "--wand-markers",
        type=int,
        nargs=2,
        metavar=("A", "B"),
        help="marker numbers of the wand's two ends in the recording (.spj input)",
    )
    p.add_argument(
        "--frame-recording",
        type=Path,
        metavar="STATIC.spj",
        help="static recording of the reference object (L-frame) (.spj input)",
    )
    p.add_argument(
        "--frame-markers",
        type=int,
        nargs="+",
        metavar="N",
        help="marker numbers of the reference object, in the order of --frame-points",
    )
    p.add_argument("--frame-points", type=Path, help="CSV with X, Y, Z (mm) per frame marker")
    p.add_argument("--report", type=Path, help="quality report (JSON); default OUT.report.json")
    p.add_argument("--figure", type=Path, help="quality figure (PNG); default OUT.report.png")
    p.add_argument("--no-distortion", action="store_true", help="fit no lens distortion")
    p.add_argument("--json", action="store_true", help="print the report as one JSON object")
    p.set_defaults(run=run)


def _load(args: argparse.Namespace) -> WandObservations:
    path: Path = args.observations
    if not path.exists():
        raise CommandError(f"{path}: no such file")
    suffix = input_suffix(path)
    if suffix == ".npz":
        return load_npz(path)
    if suffix == ".csv":
        if args.frame is None or args.image_size is None:
            raise CommandError("CSV input needs --frame FRAME.csv and --image-size W H")
        return load_csv(path, args.frame, args.image_size)
    if suffix == ".spj":
        needed = ("wand_markers", "frame_recording", "frame_markers", "frame_points")
        missing = [f"--{n.replace('_', '-')}" for n in needed if getattr(args, n) is None]
        if missing:
            raise CommandError(f"recording input needs {', '.join(missing)}")
        return load_recordings(
            path, args.wand_markers, args.frame_recording, args.frame_markers, args.frame_points
        )
    raise CommandError(f"{path}: unknown observation format {suffix!r} (npz, csv or spj)")


def run(args: argparse.Namespace) -> int:
    out: Path = args.out
    report_path = args.report or out.with_suffix(".report.json")
    figure_path = args.figure or out.with_suffix(".report.png")
    check_output_paths([("--out", out), ("--report", report_path), ("--figure", figure_path)])
    obs = _load(args)
    length = args.wand_length if args.wand_length is not None else obs.wand_length
    if length is None:
        raise CommandError("the wand length is not known: give --wand-length MM")
    verbose = not args.json

    def progress(message: str) -> None:
        if verbose:
            print(f"calibrate: {message}", file=sys.stderr, flush=True)

    result = wand_calibrate(
        obs.wand,
        length,
        obs.frame,
        obs.frame_points,
        obs.image_size,
        names=obs.names,
        distortion=() if args.no_distortion else ("k1", "k2", "p1", "p2", "k3"),
        progress=progress,
    )
    result.rig.save(out)
    report_path.write_text(json.dumps(result.report, indent=2) + "\n")
    write_report_figure(
        result.rig, obs.wand, result.wand_residuals, result.inliers, result.report, figure_path
    )
    if args.json:
        print(json.dumps({**result.report, "calibration": str(out)}))
        return 0
    rep = result.report
    for cam in rep["cameras"]:
        print(
            f"  {cam['name']}: reprojection RMS {cam['reprojection_rms_px']:.3f} px, "
            f"{cam['observations']} points ({cam['rejected']} rejected), "
            f"image covered {100 * cam['image_coverage']:.0f} %"
        )
    w = rep["wand"]
    print(
        f"  wand: {w['frames']} frames, length {w['mean_mm']:.3f} mm (nominal "
        f"{w['nominal_mm']:g}), SD {w['sd_mm']:.3f} mm, max error {w['max_error_mm']:.3f} mm"
    )
    print(f"verdict: {rep['verdict']['grade']}")
    for reason in rep["verdict"]["reasons"]:
        print(f"  - {reason}")
    print(f"wrote {out}, {report_path}, {figure_path}")
    return 0
