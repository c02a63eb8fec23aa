"""``spotlab reconstruct``: observations + calibration -> marker trajectories (C3D or TRC).

Observations are npz arrays, a CSV table or a SELSPOT-style recording (see
:mod:`spotlab.processing.marker_observations`); the work is done by
:mod:`spotlab.processing.trajectories`, which ``spotlab export`` shares.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from spotlab.console.progress import Progress
from spotlab.console.summaries import print_summary
from spotlab.processing.errors import InputError
from spotlab.processing.linear_trajectories import (
    is_linear_recording,
    linear_trial,
    read_linear_recording,
)
from spotlab.processing.paths import check_output_paths
from spotlab.processing.scanner_session import is_scanner_session, session_scanner_trial
from spotlab.processing.scanner_trajectories import SOURCES
from spotlab.processing.session_times import calibration_for
from spotlab.processing.trajectories import check_outputs, reconstruct_file, write_trial
from spotlab.reconstruction import METHODS


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "reconstruct",
        help="triangulate marker trajectories from observations and a calibration",
        description="Triangulate every frame of the observations (npz, CSV or a .spj "
        "recording) with a calibrated rig and write the trajectories as C3D or TRC "
        "(by the suffix of --out). The blobs of a video-centroid recording are identified "
        "and named by a marker model (--model, or the one stored in the recording). A "
        "scanner (coda) recording needs no calibration: its 3-D comes from the unit's "
        "geometry stored in the recording (--scanner). So does a linear-sensor (wsx) recording: "
        "the hub's factory calibration travels in it.",
    )
    p.add_argument("input", type=Path, help="observations: OBS.npz, OBS.csv or RECORDING.spj")
    p.add_argument(
        "--calibration",
        type=Path,
        help="rig (TOML); default for a recording made with --lab: the lab file's rig",
    )
    p.add_argument("--out", type=Path, required=True, help="trajectories to write (.c3d, .trc)")
    p.add_argument("--method", choices=METHODS, default="odle", help="estimator (default odle)")
    p.add_argument("--rate", type=float, help="frame rate in Hz (needed for CSV input)")
    p.add_argument("--labels", nargs="+", metavar="LABEL", help="marker names, one per marker")
    p.add_argument(
        "--model",
        type=Path,
        metavar="MODEL.json",
        help="marker model naming the markers of a video-centroid recording (default: the "
        "one stored in the recording by spotlab record --model)",
    )
    p.add_argument(
        "--scanner",
        choices=SOURCES,
        default="angles",
        help="scanner recordings: 3-D from the raw angles, each at its own crossing instant "
        "(angles, default) or the unit's own 3-D (device)",
    )
    p.add_argument(
        "--raw",
        action="store_true",
        help="wsx recordings: each marker at its own firing instant, not interpolated to the "
        "frame's instant",
    )
    p.add_argument(
        "--align-markers",
        nargs="+",
        metavar="CODE",
        help="recordings of several scanners: the colour codes of the shared object's "
        "markers that carry every unit into the first one's frame (e.g. WR WO WY WG); "
        "default: every marker both units see",
    )
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    check_output_paths([("--out", args.out)])
    check_outputs([args.out])
    if is_scanner_session(args.input):
        return _run_scanner(args)
    if args.align_markers and args.input.is_file():
        raise InputError(f"{args.input}: --align-markers is for recordings of scanners")
    if is_linear_recording(args.input):
        return _run_linear(args)
    calibration = args.calibration
    if calibration is None:
        calibration = calibration_for(args.input, None)
    result = reconstruct_file(
        args.input,
        calibration,
        method=args.method,
        rate_hz=args.rate,
        labels=args.labels,
        model=args.model,
        progress=Progress,
    )
    write_trial(args.out, result.trial)
    if args.json:
        print(json.dumps({**result.summary, "outputs": [str(args.out)]}))
    else:
        print_summary(result.summary, [args.out])
    return 0


def _run_scanner(args: argparse.Namespace) -> int:
    """A scanner recording: trajectories from its angles (or the unit's 3-D), no calibration."""
    if args.calibration is not None or args.labels or args.model is not None:
        raise InputError(
            f"{args.input}: a scanner recording takes no --calibration, --labels or --model "
            "(its geometry and marker codes are in the recording)"
        )
    trial, summary = session_scanner_trial(args.input, args.scanner, args.align_markers)
    write_trial(args.out, trial)
    summary = {"input": str(args.input), **summary}
    if args.json:
        print(json.dumps({**summary, "outputs": [str(args.out)]}))
    else:
        _print_scanner(summary, args.out)
    return 0


def _print_scanner(summary: dict[str, Any], out: Path) -> None:
    """The text summary of a scanner reconstruction: frames, markers, precision model."""
    print(
        f"scanner {summary['stream']}: {summary['frames']} frames, 3-D from the "
        f"{summary['source']} (base {summary['base_mm']:g} mm)"
    )
    for unit in summary.get("units", [])[1:]:
        fit = unit["alignment"]
        print(
            f"  {unit['stream']}: {unit['frames']} frames, base {unit['base_mm']:g} mm, into "
            f"{summary['stream']}'s frame by {', '.join(fit['markers'])} ("
            + ("still, mean positions" if fit["method"] == "still" else f"{fit['pairs']} pairs")
            + f", RMS {fit['rms_mm']:.3f} mm), times from {summary['time_base']}"
        )
    for m in summary["markers"]:
        sd = " / ".join("-" if v is None else f"{v:.3f}" for v in m["precision_sd_mm"])
        print(f"  {m['label']:<4} {m['frames']:>7} frames   precision sd x / y / z {sd} mm")
    print(f"  wrote              {out}")


def _run_linear(args: argparse.Namespace) -> int:
    """A WSX recording: markers from its CCD planes and the factory calibration it carries."""
    if args.calibration is not None or args.labels or args.model is not None:
        raise InputError(
            f"{args.input}: a wsx recording takes no --calibration, --labels or --model "
            "(the hub's factory calibration is in the recording)"
        )
    trial, summary = linear_trial(read_linear_recording(args.input), raw=args.raw)
    write_trial(args.out, trial)
    summary = {"input": str(args.input), **summary}
    if args.json:
        print(json.dumps({**summary, "outputs": [str(args.out)]}))
        return 0
    how = "interpolated to each frame's start" if summary["interpolated"] else "at firing instants"
    print(f"wsx {summary['stream']}: {summary['frames']} frames, {summary['ccds']} CCDs, {how}")
    if summary["registration_rms_mm"] is not None:
        rms = ", ".join(f"{v:.3f}" for v in summary["registration_rms_mm"][1:])
        print(f"  sensors registered to sensor 0 by the markers they share (RMS {rms} mm)")
    for m in summary["markers"]:
        rms = "-" if m["plane_rms_mm"] is None else f"{m['plane_rms_mm']:.3f}"
        print(f"  {m['label']:<4} {m['frames']:>7} frames   plane RMS {rms} mm")
    print(f"  wrote              {args.out}")
    return 0
