"""``spotlab info FILE``: what a recording holds, per stream."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from spotlab.acquisition.replay import summarize
from spotlab.console.link_faults import fault_line
from spotlab.processing.decoding import decoder_for


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "info",
        help="summarise a recording: frames, losses, checksum errors, gaps, rate",
        description="Decode a recording again and report, per stream, frames, lost frames, "
        "checksum errors, resyncs, gaps, duration and measured rate (and a WSX hub's USB "
        "faults: stalls, timeouts, short packets, babble, unplugs and returns).",
    )
    p.add_argument("file", type=Path, help="recording journal (.spj)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    summary = summarize(args.file, decoder_for)
    data = summary.to_dict()
    if args.json:
        print(json.dumps(data))
        return 0
    print(
        f"{args.file}: {'complete' if data.get('complete') else 'incomplete (recording was cut)'}"
    )
    if data.get("truncated_bytes"):
        print(f"  cut short: last {data['truncated_bytes']} bytes were a partial record")
    if data.get("corrupt_records"):
        print(f"  damaged records skipped: {data['corrupt_records']}")
    for s in data["streams"]:
        if s.get("undecodable"):
            print(f"  {s['name']}: not decoded: {s['undecodable']}")
            continue
        print(
            f"  {s['name']}: {s['frames']} frames in {s['duration_s']:.3f} s "
            f"({s['rate_hz']:.2f} Hz), lost {s['lost_frames']}, CRC errors {s['crc_errors']}, "
            f"resyncs {s['resyncs']}, gaps {s['gaps']}"
        )
        if s.get("reconnects") or s.get("device_dropped"):
            print(
                f"      device FIFO drops {s.get('device_dropped', 0)}, "
                f"reconnects {s['reconnects']}, device resets {s.get('device_resets', 0)}"
            )
        faults = fault_line(s)
        if faults:
            print(f"      {faults}")
        extra = s.get("device_summary") or {}
        if "labels" in extra:  # labelled 3-D markers (NatNet)
            print(f"      {len(extra['labels'])} labelled 3-D markers: {' '.join(extra['labels'])}")
        if "blobs_per_frame" in extra:
            print(
                f"      blobs {extra['blobs']} ({extra['blobs_per_frame']:.1f} per frame), "
                f"overflow frames per camera {extra['overflow_frames']}, "
                f"camera gaps {extra['camera_gaps']} ({extra['offline_frames']} frames offline)"
            )
    return 0
