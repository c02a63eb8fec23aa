"""``spotlab record``: record one or several devices into one crash-safe journal."""

from __future__ import annotations

import argparse
import inspect
import json
from pathlib import Path
from typing import Any

from spotlab.acquisition.recorder import Recorder
from spotlab.acquisition.session import Session, SessionStatus
from spotlab.console.blob_trajectories import MODEL_KEY, model_metadata
from spotlab.console.errors import CommandError
from spotlab.console.paths import check_output_paths
from spotlab.console.progress import Progress
from spotlab.core.wire import LinkEventKind
from spotlab.drivers import Driver, available_families, load_driver

# Command-line flag -> driver keyword argument.
DEVICE_OPTIONS = {"cameras": "cameras", "leds": "leds", "rate": "rate_hz", "baud": "baud"}


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "record",
        help="record devices into a journal (raw wire bytes, crash-safe)",
        description="Record the raw bytes of one or several devices, with arrival stamps and "
        "metadata, into an append-only journal that survives a kill at any moment. PORT is a "
        "device path or a pyserial URL (socket://, sim://selspot?...).",
    )
    p.add_argument("port", nargs="?", help="device path or URL (with --driver)")
    p.add_argument("--driver", help=f"device family of PORT ({', '.join(available_families())})")
    p.add_argument(
        "--device",
        action="append",
        default=[],
        metavar="FAMILY=PORT",
        help="a device to record; repeat for several devices",
    )
    p.add_argument("--seconds", type=float, required=True, help="how long to record")
    p.add_argument("--out", type=Path, required=True, help="journal file to write (.spj)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    p.add_argument("--cameras", type=int, help="cameras to configure")
    p.add_argument("--leds", type=int, help="LEDs (markers) to configure")
    p.add_argument("--rate", type=float, help="frame rate in Hz")
    p.add_argument("--baud", help="line rate after negotiation, or 'auto'")
    p.add_argument(
        "--model",
        type=Path,
        metavar="MODEL.json",
        help="marker model (names, rigid clusters) of the subject, kept in the recording for "
        "spotlab reconstruct of video-centroid recordings",
    )
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
    p.set_defaults(run=run)


def _device_list(args: argparse.Namespace) -> list[tuple[str, str]]:
    pairs: list[tuple[str, str]] = []
    if args.port:
        if not args.driver:
            raise CommandError("give --driver FAMILY with PORT (or use --device FAMILY=PORT)")
        pairs.append((args.driver, args.port))
    elif args.driver:
        raise CommandError("--driver needs a PORT")
    for item in args.device:
        family, sep, port = item.partition("=")
        if not sep or not family or not port:
            raise CommandError(f"--device takes FAMILY=PORT, got {item!r}")
        pairs.append((family, port))
    if not pairs:
        raise CommandError("nothing to record: give PORT --driver FAMILY or --device FAMILY=PORT")
    return pairs


def _driver_options(
    args: argparse.Namespace, cls: type[Driver], mixed: bool = False
) -> dict[str, Any]:
    """Keyword arguments of ``cls`` from the flags; with ``mixed`` families, flags that do
    not apply to this one (``--cameras`` for a timer) are left to the others."""
    accepted = inspect.signature(cls.__init__).parameters
    options: dict[str, Any] = {}
    for flag, keyword in DEVICE_OPTIONS.items():
        value = getattr(args, flag)
        if value is None:
            continue
        if keyword not in accepted:
            if mixed:
                continue
            raise CommandError(f"--{flag} does not apply to {cls.family} devices")
        if keyword == "baud" and value != "auto":
            try:
                value = int(value)
            except ValueError:
                raise CommandError(f"--baud takes a number or 'auto', got {value!r}") from None
        options[keyword] = value
    return options


def build_drivers(args: argparse.Namespace) -> list[Driver]:
    """Driver objects for every device named on the command line (not yet started)."""
    pairs = _device_list(args)
    drivers: list[Driver] = []
    counts: dict[str, int] = {}
    mixed = len({family for family, _ in pairs}) > 1
    for family, port in pairs:
        cls = load_driver(family)
        n = counts.get(family, 0)
        counts[family] = n + 1
        name = family if n == 0 else f"{family}{n}"
        drivers.append(cls(port, name=name, **_driver_options(args, cls, mixed)))
    if len(pairs) > 1:
        # Name every stream by family and index when a family appears more than once.
        for d in drivers:
            if counts[d.family] > 1 and d.name == d.family:
                d.name = f"{d.family}0"
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


def run(args: argparse.Namespace) -> int:
    if not args.seconds > 0:
        raise CommandError(f"--seconds must be positive, got {args.seconds}")
    check_output_paths([("--out", args.out)])
    if args.out.exists() and not args.overwrite:
        raise CommandError(f"{args.out} exists; choose another --out or add --overwrite")
    drivers = build_drivers(args)
    session_meta: dict[str, Any] = {"command": "record"}
    if args.model is not None:
        session_meta[MODEL_KEY] = model_metadata(args.model)
    recorder = Recorder(args.out, session_meta, overwrite=args.overwrite)
    progress = Progress("recording", total=args.seconds)

    def show(status: SessionStatus) -> None:
        progress.update(status.elapsed_s, f"{sum(status.frames.values())} frames")

    watch = OutageWatch()
    for driver in drivers:
        driver.add_tap(watch)
    session = Session(drivers, [recorder], close_devices=True)
    try:
        status = session.run_for(args.seconds, progress=show)
    except BaseException:
        if not any(session.frames.values()):
            # Nothing but a failed start-up dialogue: leave no file that blocks a retry.
            args.out.unlink(missing_ok=True)
        raise
    finally:
        progress.close()
    result: dict[str, Any] = {
        "out": str(args.out),
        "seconds": round(status.elapsed_s, 3),
        "streams": [
            {"name": d.name, "family": d.family, "port": d.port, **d.stats.as_dict()}
            for d in drivers
        ],
        "overflows": status.overflows,
        "errors": [str(e) for e in session.errors],
    }
    result["away_at_end"] = dict(watch.away)
    if args.json:
        print(json.dumps(result))
    else:
        for s in result["streams"]:
            print(
                f"{s['name']}: {s['frames']} frames, lost {s['lost_frames']}, "
                f"CRC errors {s['crc_errors']}, resyncs {s['resyncs']}, "
                f"reconnects {s['reconnects']} -> {args.out}"
            )
    if watch.away:
        lost = ", ".join(f"{name} ({why})" for name, why in watch.away.items())
        raise CommandError(
            f"device gone when the recording ended: {lost}; what arrived before is in {args.out}"
        )
    return 0
