"""``spotlab replay FILE``: decode a recording again, as if live, and put it on session time.

Every stream is fed through its driver's decoder in recording order (as
:func:`spotlab.acquisition.replay.replay` does); the command prints what ``spotlab
info`` prints per stream and, for each, where its frames lie on the session time base
(:mod:`spotlab.processing.session_times`): first and last frame, method, drift, jitter and
clock events. ``--timestamps OUT.csv`` writes the frame times as ``spotlab export``
does. Feeding a live pipeline (reconstruction, LSL outlets) from a recording belongs to
:mod:`spotlab.acquisition.live` (``replay_live``); this command only decodes and times.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from spotlab.acquisition.replay import summarize
from spotlab.console.errors import CommandError
from spotlab.console.options import parse_wiring
from spotlab.processing.decoding import decoder_for
from spotlab.processing.paths import check_output_paths
from spotlab.processing.session_times import recording_timebase, write_timestamps


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "replay",
        help="decode a recording again and put every stream on session time",
        description="Replay a recording through the drivers' decoders: per stream, frames, "
        "losses and rate (as spotlab info), and the session time of its frames from the "
        "timer (or from arrival stamps when there is none): span, drift, jitter, clock "
        "steps.",
    )
    p.add_argument("file", type=Path, help="recording journal (.spj)")
    p.add_argument(
        "--timestamps", type=Path, metavar="OUT.csv", help="also write every frame's session time"
    )
    p.add_argument(
        "--wiring",
        action="append",
        default=[],
        metavar="STREAM=INPUT",
        help="timer input of STREAM's frame pulses (default: found from the recording)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    path: Path = args.file
    if not path.is_file():
        raise CommandError(f"{path}: no such file")
    check_output_paths([("--timestamps", args.timestamps)])
    summary = summarize(path, decoder_for).to_dict()
    timebase = recording_timebase(path, parse_wiring(args.wiring))
    report = timebase.report()
    spans: dict[str, dict[str, Any]] = {}
    for name, s in timebase.streams.items():
        ok = np.isfinite(s.time_s)
        spans[name] = {
            "first_s": float(s.time_s[ok][0]) if ok.any() else None,
            "last_s": float(s.time_s[ok][-1]) if ok.any() else None,
        }
    out: dict[str, Any] = {**summary, "sync": report, "session_span": spans}
    if args.timestamps is not None:
        out["timestamp_rows"] = write_timestamps(args.timestamps, timebase)
    if args.json:
        print(json.dumps(out))
    else:
        _print(path, out)
    for note in timebase.notes:
        print(f"spotlab: warning: {note}", file=sys.stderr)
    return 0


def _print(path: Path, out: dict[str, Any]) -> None:
    sync = {s["stream"]: s for s in out["sync"]["streams"]}
    print(f"{path}: session time from {out['sync']['reference']}")
    for s in out["streams"]:
        name = s["name"]
        if s.get("undecodable"):
            print(f"  {name}: not decoded: {s['undecodable']}")
            continue
        print(
            f"  {name}: {s['frames']} frames ({s['rate_hz']:.2f} Hz), lost {s['lost_frames']}, "
            f"CRC errors {s['crc_errors']}, gaps {s['gaps']}"
        )
        t = sync.get(name)
        span = out["session_span"].get(name)
        if t is None or span is None or span["first_s"] is None:
            continue
        line = f"      session {span['first_s']:.6f} .. {span['last_s']:.6f} s, {t['method']}"
        if "drift_ppm" in t:
            line += f", drift {t['drift_ppm']:+.2f} ppm, jitter {t['jitter_us']:.2f} us"
        print(line)
        for note in t["notes"]:
            print(f"      note: {note}")
    if "timestamp_rows" in out:
        print(f"  wrote {out['timestamp_rows']} frame times")
