"""``spotlab export``: a recording or a trial file to exchange files (C3D, TRC).

``FILE`` is a C3D or TRC file (converted), or observations that ``spotlab reconstruct``
reads (a ``.spj`` recording, npz, CSV) with ``--calibration``: they are reconstructed on
the way (:mod:`spotlab.processing.trajectories`).

A recording with a timer stream (or with ``--sync``) is reconstructed on session times:
every ``image2d`` stream resampled at common instants (``--rate``), the cameras of all
streams stacked in stream order (the calibration lists them so), see
:mod:`spotlab.processing.synchronised_export`.

A scanner (coda) recording needs no calibration: its trajectories come from its raw
angles and the geometry it stores (:mod:`spotlab.processing.scanner_trajectories`); the
units of a recording of several are carried into the first one's frame by the markers
they share (:mod:`spotlab.processing.scanner_session`).

A recording of labelled 3-D markers (QTM's, Motive's) is written as it is; its rigid
bodies go beside ``OUT`` as ``OUT``'s stem + ``.bodies.csv``
(:mod:`spotlab.processing.rigid_bodies`).

``--timestamps OUT.csv`` writes the session time of every frame of every stream of a
recording (``stream, seq, time_s, device_ticks, method``), ``--sync-report OUT.json``
the clock report (reference, drift, jitter and events per stream); see
:mod:`spotlab.processing.session_times` and docs/synchronisation.md "From a recording".
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from spotlab.console.errors import CommandError
from spotlab.console.options import parse_wiring
from spotlab.console.progress import Progress
from spotlab.console.summaries import print_summary
from spotlab.io import TRIAL_READERS, Trial
from spotlab.kinematics import smooth_trial
from spotlab.processing import (
    OBSERVATION_SUFFIXES,
    calibration_for,
    check_output_paths,
    check_outputs,
    input_suffix,
    reconstruct_file,
    reconstruct_recording,
    recording_timebase,
    write_timestamps,
    write_trial,
)
from spotlab.processing.labelled_points import labelled_trial
from spotlab.processing.rigid_bodies import bodies_path, recording_bodies, write_bodies_csv
from spotlab.processing.scanner_session import is_scanner_session, session_scanner_trial


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "export",
        help="write a recording or a trial file as C3D or TRC",
        description="Convert a C3D or TRC file, or reconstruct a recording (.spj, with "
        "--calibration) and write its marker trajectories.",
    )
    p.add_argument("file", type=Path, help="RECORDING.spj, TRIAL.c3d or TRIAL.trc")
    p.add_argument("--c3d", type=Path, metavar="OUT", help="write marker trajectories as C3D")
    p.add_argument("--trc", type=Path, metavar="OUT", help="write marker trajectories as TRC")
    p.add_argument(
        "--calibration",
        type=Path,
        help="rig (TOML) to reconstruct a recording (default for a recording made with "
        "--lab: the lab file's rig)",
    )
    p.add_argument(
        "--drop-group",
        action="append",
        default=[],
        metavar="GROUP",
        help="leave this C3D parameter group out of --c3d OUT (e.g. FORCE_PLATFORM; every "
        "group the input C3D file has is kept otherwise); repeat",
    )
    p.add_argument(
        "--timestamps",
        type=Path,
        metavar="OUT.csv",
        help="write the session time of every frame of every stream (stream, seq, time_s, "
        "device_ticks, method) of a recording",
    )
    p.add_argument(
        "--sync-report",
        type=Path,
        metavar="OUT.json",
        help="write the clock report (reference, drift, jitter, steps per stream) as JSON",
    )
    p.add_argument(
        "--wiring",
        action="append",
        default=[],
        metavar="STREAM=INPUT",
        help="timer input that captured STREAM's frame pulses (default: found from the "
        "recording); repeat",
    )
    p.add_argument(
        "--sync",
        action="store_true",
        help="reconstruct a recording on session times even without a timer stream (host "
        "arrival stamps; with a timer this is the default)",
    )
    p.add_argument(
        "--rate",
        type=float,
        metavar="HZ",
        help="rate of the common instants of a synchronised export (default: the fastest stream's)",
    )
    p.add_argument(
        "--no-slot-correction",
        action="store_true",
        help="take every marker at its frame's time, not its LED slot's (diagnosis only: "
        "biases moving markers)",
    )
    p.add_argument(
        "--smooth",
        action="store_true",
        help="smooth every marker coordinate with its own quintic GCV spline before writing "
        "(spotlab.kinematics.smooth_trial; gaps stay gaps)",
    )
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(run=run)


def _outputs(args: argparse.Namespace) -> list[Path]:
    outputs = [path for path in (args.c3d, args.trc) if path is not None]
    if not outputs and args.timestamps is None and args.sync_report is None:
        raise CommandError(
            "nothing to export: give --c3d OUT and/or --trc OUT, or --timestamps OUT.csv "
            "and/or --sync-report OUT.json for a recording"
        )
    for flag, path in (("--c3d", args.c3d), ("--trc", args.trc)):
        if path is not None and path.suffix.lower() != "." + flag[2:]:
            raise CommandError(f"{flag} {path}: the file name must end in .{flag[2:]}")
    check_output_paths(
        [
            ("--c3d", args.c3d),
            ("--trc", args.trc),
            ("--timestamps", args.timestamps),
            ("--sync-report", args.sync_report),
        ]
    )
    check_outputs(outputs)
    return outputs


def _session_times(args: argparse.Namespace) -> dict[str, Any]:
    """--timestamps / --sync-report: the recording's time base; notes go to stderr."""
    path: Path = args.file
    if input_suffix(path) != ".spj":
        raise CommandError(f"{path}: --timestamps and --sync-report need a recording (.spj)")
    timebase = recording_timebase(path, parse_wiring(args.wiring))
    report = timebase.report()
    for note in timebase.notes:
        print(f"spotlab: warning: {note}", file=sys.stderr)
    for s in report["streams"]:
        for note in s["notes"]:
            print(f"spotlab: {s['stream']}: {note}", file=sys.stderr)
    out: dict[str, Any] = {"sync": report}
    if args.timestamps is not None:
        out["timestamps"] = str(args.timestamps)
        out["timestamp_rows"] = write_timestamps(args.timestamps, timebase)
    if args.sync_report is not None:
        args.sync_report.write_text(json.dumps(report, indent=1) + "\n")
        out["sync_report"] = str(args.sync_report)
    return out


def run(args: argparse.Namespace) -> int:
    outputs = _outputs(args)
    path: Path = args.file
    suffix = input_suffix(path)
    if not path.is_file():
        raise CommandError(f"{path}: no such file")
    if args.timestamps is not None or args.sync_report is not None:
        sync = _session_times(args)
        if not outputs:
            if args.json:
                print(json.dumps(sync))
            else:
                _print_sync(sync)
            return 0
    summary: dict[str, Any]
    if suffix in TRIAL_READERS:
        trial: Trial = TRIAL_READERS[suffix](path)
        summary = {
            "input": str(path),
            "frames": trial.n_frames,
            "markers": trial.n_markers,
            "rate_hz": trial.point_rate,
        }
    elif suffix == ".spj" and args.calibration is None and (found := labelled_trial(path)):
        trial, summary = found  # labelled 3-D markers (QTM's, Motive's): written as they are
        if outputs and (bodies := recording_bodies(path)):  # their rigid bodies beside
            table = bodies_path(outputs[0])
            check_output_paths([("bodies", table)])
            summary["bodies"] = str(table)
            summary["body_rows"] = write_bodies_csv(table, bodies)
    elif suffix == ".spj" and args.calibration is None and is_scanner_session(path):
        trial, scanner = session_scanner_trial(path)  # 3-D from the angles, one frame
        summary = {"input": str(path), "frames": trial.n_frames, "markers": trial.n_markers,
                   "rate_hz": trial.point_rate, "scanner": scanner}  # fmt: skip
    elif suffix in OBSERVATION_SUFFIXES:
        if args.calibration is None and suffix != ".spj":
            raise CommandError(f"{path}: exporting observations needs --calibration RIG.toml")
        if suffix == ".spj":
            result = reconstruct_recording(
                path, calibration_for(path, args.calibration), sync=args.sync,
                wiring=parse_wiring(args.wiring),
                rate_hz=args.rate, slot_correction=not args.no_slot_correction,
                progress=Progress,
            )  # fmt: skip
            for note in result.notes:
                print(f"spotlab: {note}", file=sys.stderr)
        else:
            result = reconstruct_file(path, args.calibration, rate_hz=args.rate, progress=Progress)
        trial, summary = result.trial, result.summary
    else:
        known = ", ".join([*TRIAL_READERS, *OBSERVATION_SUFFIXES])
        raise CommandError(f"{path}: unknown input format {suffix!r} ({known})")
    if args.smooth:
        trial = smooth_trial(trial)
        summary["smoothed"] = "quintic GCV spline per marker coordinate"
    for out in outputs:
        write_trial(out, trial, drop_groups=args.drop_group)
    if args.json:
        print(json.dumps({**summary, "outputs": [str(p) for p in outputs]}))
    elif "method" in summary:
        print_summary(summary, outputs)
    else:
        print(
            f"converted {summary['frames']} frames x {summary['markers']} markers at "
            f"{summary['rate_hz']:g} Hz"
        )
        if "smoothed" in summary:
            print(f"  smoothed           {summary['smoothed']}")
        for out in outputs:
            print(f"  wrote              {out}")
        if "bodies" in summary:
            print(f"  wrote              {summary['bodies']} ({summary['body_rows']} body rows)")
    return 0


def _print_sync(sync: dict[str, Any]) -> None:
    report = sync["sync"]
    print(f"session time from {report['reference']}")
    for s in report["streams"]:
        line = f"  {s['stream']}: {s['frames']} frames, {s.get('method') or 'none'}"
        if "drift_ppm" in s:
            line += (
                f", drift {s['drift_ppm']:+.2f} ppm, jitter {s['jitter_us']:.2f} us, "
                f"{len(s['events'])} events"
            )
        print(line)
    if "timestamps" in sync:
        print(f"  wrote              {sync['timestamps']} ({sync['timestamp_rows']} rows)")
    if "sync_report" in sync:
        print(f"  wrote              {sync['sync_report']}")
