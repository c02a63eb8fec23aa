"""``spotlab record``: record one or several devices into one crash-safe journal."""

from __future__ import annotations

import argparse
import json
import signal
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from spotlab.acquisition.recorder import Recorder
from spotlab.acquisition.session import Session, SessionStatus
from spotlab.acquisition.summary import summarize
from spotlab.console.device_arguments import add_device_arguments, add_setting_arguments
from spotlab.console.device_settings import (
    FAMILY_SETTINGS,
    GLOBAL_OPTIONS,
    DeviceRequest,
    device_options,
    requests_from_lab,
    requests_from_options,
)
from spotlab.console.errors import CommandError
from spotlab.console.link_faults import fault_line
from spotlab.console.options import add_realtime_argument, parse_wiring
from spotlab.console.progress import Progress
from spotlab.core.wire import LinkEventKind
from spotlab.drivers import Driver, load_driver
from spotlab.io.lab_file import Lab, load_lab
from spotlab.processing.blob_trajectories import MODEL_KEY, model_metadata
from spotlab.processing.decoding import decoder_for
from spotlab.processing.paths import check_output_paths
from spotlab.processing.session_times import WIRING_KEY


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "record",
        help="record devices into a journal (raw wire bytes, crash-safe)",
        description="Record the raw bytes of one or several devices, with arrival stamps and "
        "metadata, into an append-only journal that survives a kill at any moment. PORT is a "
        "device path or a pyserial URL (socket://, sim://selspot?...). A setting a device is "
        "not given keeps what the device reports it has. Without --seconds the recording "
        "runs until Ctrl-C or SIGTERM.",
    )
    add_device_arguments(
        p,
        "a device to record, with its own settings (selspot: rate, cameras, leds, slot, "
        "bgnd, agc, baud; timer: rate, slots, baud; centroid: rate, cameras, exposure, "
        "threshold, blobs, baud; qualisys: password, udp; any: name); repeat for several devices",
    )
    p.add_argument(
        "--lab",
        type=Path,
        metavar="LAB.toml",
        help="lab file: devices and settings, timer wiring, rig and model (docs/lab.md)",
    )
    p.add_argument(
        "--seconds", type=float, help="how long to record (default: until Ctrl-C or SIGTERM)"
    )
    p.add_argument("--out", type=Path, required=True, help="journal file to write (.spj)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    add_setting_arguments(p, "line rate after negotiation, or 'auto', for devices that do not say")
    p.add_argument(
        "--wiring",
        action="append",
        default=[],
        metavar="STREAM=INPUT",
        help="timer input that captures STREAM's frame pulses, kept in the recording for "
        "spotlab export (adds to the lab file's [wiring]); repeat",
    )
    p.add_argument(
        "--model",
        type=Path,
        metavar="MODEL.json",
        help="marker model (names, rigid clusters) of the subject, kept in the recording for "
        "spotlab reconstruct of video-centroid recordings (default: the lab file's)",
    )
    add_realtime_argument(p)
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
    p.set_defaults(run=run)


def _defaults(args: argparse.Namespace) -> dict[str, Any]:
    """The global options given, as settings for devices that do not say."""
    out: dict[str, Any] = {}
    for key in GLOBAL_OPTIONS:
        value = getattr(args, key)
        if value is not None:
            out[key] = value
    return out


def _requests(args: argparse.Namespace, lab: Lab | None) -> list[DeviceRequest]:
    defaults = _defaults(args)
    requests: list[DeviceRequest] = []
    if lab is not None:
        requests += requests_from_lab(lab.devices, defaults)
    if args.port:
        if not args.driver:
            raise CommandError("give --driver FAMILY with PORT (or use --device FAMILY=PORT)")
        name, options = device_options(args.driver, {}, f"--driver {args.driver}", defaults)
        requests.append(DeviceRequest(args.driver, args.port, name, options))
    elif args.driver:
        raise CommandError("--driver needs a PORT")
    requests += requests_from_options(args.device, defaults)
    if not requests:
        raise CommandError(
            "nothing to record: give PORT --driver FAMILY, --device FAMILY=PORT or --lab LAB.toml"
        )
    families = {r.family for r in requests}
    for key, value in defaults.items():
        if not any(key in FAMILY_SETTINGS.get(f, {}) for f in families):
            raise CommandError(
                f"--{key} {value} does not apply to {', '.join(sorted(families))} devices"
            )
    return requests


def build_drivers(args: argparse.Namespace, lab: Lab | None = None) -> list[Driver]:
    """Driver objects for every device named on the command line or in the lab file
    (not yet started)."""
    requests = _requests(args, lab)
    drivers: list[Driver] = []
    counts: dict[str, int] = {}
    for r in requests:
        cls = load_driver(r.family)
        n = counts.get(r.family, 0)
        counts[r.family] = n + 1
        name = r.name or (r.family if n == 0 else f"{r.family}{n}")
        drivers.append(cls(r.port, name=name, **r.options))
    if len(requests) > 1:
        # Name every stream by family and index when a family appears more than once.
        for d in drivers:
            if counts[d.family] > 1 and d.name == d.family:
                d.name = f"{d.family}0"
    names = [d.name for d in drivers]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise CommandError(f"stream name {twice[0]!r} is given to several devices")
    return drivers


class OutageWatch:
    """A wire tap that remembers which streams are away (lost, not yet reconnected)."""

    def __init__(self) -> None:
        self.away: dict[str, str] = {}

    def on_rx(self, stream: str, data: bytes, arrival_ns: int) -> None:
        """Bytes are not its business."""

    def on_tx(self, stream: str, data: bytes, sent_ns: int) -> None:
        """Bytes are not its business."""

    def on_event(
        self, stream: str, kind: LinkEventKind, detail: dict[str, object], t_ns: int
    ) -> None:
        if kind in ("disconnected", "device_reset"):
            self.away[stream] = str(detail.get("reason", kind))
        elif kind in ("reconnected", "started"):
            self.away.pop(stream, None)


@contextmanager
def _stop_on_signals(session: Session) -> Iterator[list[int]]:
    """While recording, SIGINT (Ctrl-C) and SIGTERM end it as a deliberate stop; yields
    the list of signals received."""
    received: list[int] = []

    def handler(signum: int, frame: object) -> None:
        received.append(signum)
        session.request_stop()

    previous = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield received
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


def _session_metadata(args: argparse.Namespace, lab: Lab | None) -> dict[str, Any]:
    meta: dict[str, Any] = {"command": "record"}
    wiring = dict(lab.wiring) if lab is not None else {}
    wiring.update(parse_wiring(args.wiring))
    if wiring:
        meta[WIRING_KEY] = wiring
    model = args.model if args.model is not None else (lab.model if lab else None)
    if model is not None:
        meta[MODEL_KEY] = model_metadata(model)
    if lab is not None:
        meta["lab"] = {
            "path": str(lab.path),
            "rig": None if lab.rig is None else str(lab.rig),
            "model": None if lab.model is None else str(lab.model),
        }
    return meta


def _summary_lines(result: dict[str, Any]) -> list[str]:
    lines = []
    for s in result["streams"]:
        if s.get("undecodable"):
            lines.append(f"{s['name']}: not decoded: {s['undecodable']} -> {result['out']}")
            continue
        lines.append(
            f"{s['name']}: {s['frames']} frames, lost {s['lost_frames']}, "
            f"CRC errors {s['crc_errors']}, resyncs {s['resyncs']}, "
            f"reconnects {s['reconnects']} -> {result['out']}"
        )
        faults = fault_line(s)
        if faults:
            lines.append(f"{s['name']}: {faults}")
    return lines


def run(args: argparse.Namespace) -> int:
    if args.seconds is not None and not args.seconds > 0:
        raise CommandError(f"--seconds must be positive, got {args.seconds}")
    check_output_paths([("--out", args.out)])
    if args.out.exists() and not args.overwrite:
        raise CommandError(f"{args.out} exists; choose another --out or add --overwrite")
    lab = load_lab(args.lab) if args.lab is not None else None
    drivers = build_drivers(args, lab)
    session_meta = _session_metadata(args, lab)
    recorder = Recorder(args.out, session_meta, overwrite=args.overwrite)
    progress = Progress("recording", total=args.seconds)

    def show(status: SessionStatus) -> None:
        progress.update(status.elapsed_s, f"{sum(status.frames.values())} frames")

    watch = OutageWatch()
    for driver in drivers:
        driver.add_tap(watch)
    session = Session(drivers, [recorder], close_devices=True, realtime_priority=args.realtime)
    seconds = float("inf") if args.seconds is None else args.seconds
    try:
        with _stop_on_signals(session) as received:
            status = session.run_for(seconds, progress=show)
    except BaseException:
        if not any(session.frames.values()):
            # Nothing but a failed start-up dialogue: leave no file that blocks a retry.
            args.out.unlink(missing_ok=True)
        raise
    finally:
        progress.close()
    # The figures are those of the written file, decoded as `spotlab info` decodes it.
    recorded = summarize(args.out, decoder_for).to_dict()
    live = {d.name: {"family": d.family, "port": d.port, **d.stats.as_dict()} for d in drivers}
    result: dict[str, Any] = {
        "out": str(args.out),
        "seconds": round(status.elapsed_s, 3),
        "stopped_by": [signal.Signals(s).name for s in received],
        "streams": [
            {**s, "port": live.get(s["name"], {}).get("port")} for s in recorded["streams"]
        ],
        "live": live,
        "overflows": status.overflows,
        "errors": [str(e) for e in session.errors],
        "away_at_end": dict(watch.away),
    }
    result["realtime"] = {"priority": args.realtime, "refused": session.realtime_refused}
    if session.realtime_refused is not None:
        print(f"spotlab: warning: --realtime: {session.realtime_refused}", file=sys.stderr)
    if args.json:
        print(json.dumps(result))
    else:
        for line in _summary_lines(result):
            print(line)
    if watch.away:
        lost = ", ".join(f"{name} ({why})" for name, why in watch.away.items())
        raise CommandError(
            f"device gone when the recording ended: {lost}; what arrived before is in {args.out}"
        )
    return 0
