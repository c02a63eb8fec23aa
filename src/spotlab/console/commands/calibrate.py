"""``spotlab calibrate``: wand self-calibration of a rig from observations.

Reads observations (npz arrays, CSV tables, or a wand-dance recording with a static
recording of the reference object; see :mod:`spotlab.processing.calibration_inputs` for
SELSPOT recordings and :mod:`spotlab.processing.blob_calibration_inputs` for video-centroid
ones, whose wand and reference markers are found among the blobs), runs
:func:`spotlab.calibration.wand_calibrate` from a cold start, writes the calibration
(TOML in the anipose / Pose2Sim layout), the quality report (JSON) and its figure (PNG).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from spotlab.console.errors import CommandError
from spotlab.processing.blob_calibration_inputs import BlobCalibrationInputs, load_blob_recordings
from spotlab.processing.blob_trajectories import is_blob_recording
from spotlab.processing.calibration_inputs import (
    WandObservations,
    load_csv,
    load_npz,
    load_recordings,
)
from spotlab.processing.decoding import input_suffix
from spotlab.processing.paths import check_output_paths
from spotlab.processing.recording_calibration import calibrate_observations, write_calibration


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
    p.add_argument(
        "--wand-length",
        type=float,
        help="wand length in mm, between its end markers (or in the npz)",
    )
    p.add_argument(
        "--wand-middle",
        type=float,
        metavar="MM",
        help="video-centroid recordings: a 3-marker wand's middle marker, MM from end A "
        "(default: as the recording shows)",
    )
    p.add_argument("--frame", type=Path, help="reference-object CSV table (CSV input)")
    p.add_argument("--image-size", type=int, nargs=2, metavar=("W", "H"), help="pixels")
    p.add_argument(
        "--wand-markers",
        type=int,
        nargs=2,
        metavar=("A", "B"),
        help="marker numbers of the wand's two ends in the recording (SELSPOT .spj input)",
    )
    p.add_argument(
        "--frame-recording",
        type=Path,
        metavar="STATIC.spj",
        help="static recording of the reference object (L-frame) (.spj input: SELSPOT or "
        "video-centroid)",
    )
    p.add_argument(
        "--frame-markers",
        type=int,
        nargs="+",
        metavar="N",
        help="marker numbers of the reference object, in the order of --frame-points "
        "(SELSPOT .spj input)",
    )
    p.add_argument("--frame-points", type=Path, help="CSV with X, Y, Z (mm) per frame marker")
    p.add_argument("--report", type=Path, help="quality report (JSON); default OUT.report.json")
    p.add_argument("--figure", type=Path, help="quality figure (PNG); default OUT.report.png")
    p.add_argument(
        "--distortion",
        choices=("auto", "none", "radial", "full"),
        default="auto",
        help="lens terms to fit: auto (default; per camera what the wand's coverage of the "
        "image determines), none, radial (k1, k2) or full (k1, k2, p1, p2, k3)",
    )
    p.add_argument(
        "--no-distortion",
        dest="distortion",
        action="store_const",
        const="none",
        help="fit no lens distortion (same as --distortion none)",
    )
    p.add_argument("--json", action="store_true", help="print the report as one JSON object")
    p.set_defaults(run=run)


def _load_blobs(args: argparse.Namespace) -> BlobCalibrationInputs:
    """A video-centroid wand dance and static recording (see the module docstring)."""
    given = [
        f"--{n.replace('_', '-')}"
        for n in ("wand_markers", "frame_markers")
        if getattr(args, n) is not None
    ]
    if given:
        raise CommandError(
            f"{', '.join(given)} name SELSPOT markers; in a video-centroid recording the wand "
            "and the reference object are found by their geometry (see --wand-middle)"
        )
    missing = [
        f"--{n.replace('_', '-')}"
        for n in ("frame_recording", "frame_points", "wand_length")
        if getattr(args, n) is None
    ]
    if missing:
        raise CommandError(f"video-centroid recording input needs {', '.join(missing)}")
    if not args.frame_recording.exists():
        raise CommandError(f"{args.frame_recording}: no such file")
    return load_blob_recordings(
        args.observations, args.frame_recording, args.frame_points,
        wand_length=args.wand_length, wand_middle=args.wand_middle, image_size=args.image_size,
    )  # fmt: skip


def _load(args: argparse.Namespace) -> WandObservations:
    path: Path = args.observations
    if not path.exists():
        raise CommandError(f"{path}: no such file")
    if args.wand_middle is not None:
        raise CommandError("--wand-middle is for video-centroid (blobs2d) recordings")
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


def _print_finder(found: BlobCalibrationInputs) -> None:
    summary = found.summary()
    wand = f"{found.markers} markers"
    if found.relabelled:
        wand += ", ends named by a first calibration"
    if found.middle_ratio is not None:
        wand += f", middle marker at {found.middle_ratio:.3f} of the length"
    w, h = summary["image_size"]
    print(f"  wand: {wand}; image size {w} x {h} px ({found.image_size_source})")
    for cam in summary["cameras"]:
        print(
            f"  {cam['name']}: wand found in {cam['wand_used']} frames, dropped "
            f"{cam['wand_ambiguous']} ambiguous, {cam['wand_missing']} missing a marker, "
            f"{cam['wand_unusable']} camera offline or overflowing; reference object "
            f"{cam['frame']}"
        )


def run(args: argparse.Namespace) -> int:
    out: Path = args.out
    report_path = args.report or out.with_suffix(".report.json")
    figure_path = args.figure or out.with_suffix(".report.png")
    check_output_paths([("--out", out), ("--report", report_path), ("--figure", figure_path)])
    path: Path = args.observations
    found = _load_blobs(args) if is_blob_recording(path) else None
    obs = found.observations if found is not None else _load(args)
    length = args.wand_length if args.wand_length is not None else obs.wand_length
    if length is None:
        raise CommandError("the wand length is not known: give --wand-length MM")
    verbose = not args.json

    def progress(message: str) -> None:
        if verbose:
            print(f"calibrate: {message}", file=sys.stderr, flush=True)

    calibrated = calibrate_observations(
        obs, length, found, distortion=args.distortion, progress=progress
    )
    result, obs, found = calibrated.result, calibrated.observations, calibrated.found
    extra = {"finder": found.summary()} if found is not None else {}
    # The figure first: it is the output most likely to fail (matplotlib), and a rig
    # is written only with its report.
    write_calibration(calibrated, out, report_path, figure_path)
    if args.json:
        print(json.dumps({**result.report, **extra, "calibration": str(out)}))
        return 0
    if found is not None:
        _print_finder(found)
    rep = result.report
    units = rep["image_units"]
    for cam in rep["cameras"]:
        lens = cam["distortion"]
        print(
            f"  {cam['name']}: reprojection RMS {cam['reprojection_rms_px']:.3f} {units}, "
            f"{cam['observations']} points ({cam['rejected']} rejected), "
            f"image covered {100 * cam['image_coverage']:.0f} %, "
            f"lens terms {', '.join(lens['fitted']) or 'none'} ({lens['mode']})"
        )
        if lens["limited_by"] not in ("", "chosen"):
            print(f"      {lens['reason']}")
        if lens["advice"]:
            print(f"      to do: {lens['advice']}")
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
