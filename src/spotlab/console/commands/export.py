"""``spotlab export``: a recording or a trial file to exchange files (C3D, TRC).

``FILE`` is a C3D or TRC file (converted), or observations that ``spotlab reconstruct``
reads (a ``.spj`` recording, npz, CSV) with ``--calibration``: they are reconstructed on
the way (:mod:`spotlab.console.trajectories`).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from spotlab.console.errors import CommandError
from spotlab.console.marker_observations import OBSERVATION_SUFFIXES
from spotlab.console.trajectories import (
    check_outputs,
    print_summary,
    reconstruct_file,
    write_trial,
)
from spotlab.io import Trial, read_c3d, read_trc

TRIAL_READERS = {".c3d": read_c3d, ".trc": read_trc}


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
    p.add_argument("--calibration", type=Path, help="rig (TOML) to reconstruct a recording")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(run=run)


def _outputs(args: argparse.Namespace) -> list[Path]:
    outputs = [path for path in (args.c3d, args.trc) if path is not None]
    if not outputs:
        raise CommandError("nothing to export: give --c3d OUT and/or --trc OUT")
    for flag, path in (("--c3d", args.c3d), ("--trc", args.trc)):
        if path is not None and path.suffix.lower() != "." + flag[2:]:
            raise CommandError(f"{flag} {path}: the file name must end in .{flag[2:]}")
    check_outputs(outputs)
    return outputs


def run(args: argparse.Namespace) -> int:
    outputs = _outputs(args)
    path: Path = args.file
    suffix = path.suffix.lower()
    if not path.is_file():
        raise CommandError(f"{path}: no such file")
    summary: dict[str, Any]
    if suffix in TRIAL_READERS:
        trial: Trial = TRIAL_READERS[suffix](path)
        summary = {
            "input": str(path),
            "frames": trial.n_frames,
            "markers": trial.n_markers,
            "rate_hz": trial.point_rate,
        }
    elif suffix in OBSERVATION_SUFFIXES:
        if args.calibration is None:
            raise CommandError(f"{path}: exporting observations needs --calibration RIG.toml")
        result = reconstruct_file(path, args.calibration)
        trial, summary = result.trial, result.summary
    else:
        known = ", ".join([*TRIAL_READERS, *OBSERVATION_SUFFIXES])
        raise CommandError(f"{path}: unknown input format {suffix!r} ({known})")
    for out in outputs:
        write_trial(out, trial)
    if args.json:
        print(json.dumps({**summary, "outputs": [str(p) for p in outputs]}))
    elif "method" in summary:
        print_summary(summary, outputs)
    else:
        print(
            f"converted {summary['frames']} frames x {summary['markers']} markers at "
            f"{summary['rate_hz']:g} Hz"
        )
        for out in outputs:
            print(f"  wrote              {out}")
    return 0
