"""``spotlab bench``: a device's conformance suite and timing figures, as a report."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from spotlab.console.device_arguments import add_device_arguments, add_setting_arguments
from spotlab.console.device_settings import (
    GLOBAL_OPTIONS,
    DeviceRequest,
    device_options,
    requests_from_options,
)
from spotlab.console.errors import EXIT_FAILURE, CommandError
from spotlab.drivers import Driver, load_driver

HELP = "run a device's conformance suite and measure its timing, with a report"


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "bench",
        help=HELP,
        description="Run the conformance suite of each device's family against its port, "
        "then stream and measure frame-arrival jitter, host latency per frame, throughput "
        "against the line's capacity and the device clock against the host's; with "
        "--disruptive also the recovery from a reset and a pulled cable. Writes "
        "report.json, report.html and PNG plots to --report; with --baseline names every "
        "figure worse beyond its tolerance. Exit 1 when a test fails or a figure regresses. "
        "PORT: a device path, a pyserial URL (sim://selspot?...), a pty of spotlab sim, or "
        "HOST[:PORT] for qualisys and natnet.",
    )
    add_device_arguments(p, "a device to bench, with its settings as for spotlab record; repeat")
    p.add_argument("--seconds", type=float, default=5.0, help="seconds measured (default 5)")
    p.add_argument(
        "--disruptive", action="store_true", help="also reset the device and pull its cable"
    )
    p.add_argument("--yes", action="store_true", help="do not ask before each disruptive step")
    p.add_argument("--baseline", type=Path, metavar="OLD.json", help="a previous report.json")
    p.add_argument(
        "--report", type=Path, default=Path("bench-report"), metavar="DIR",
        help="folder of the report (default bench-report)",
    )  # fmt: skip
    p.add_argument("-k", dest="select", metavar="EXPR", help="only the tests pytest -k selects")
    add_setting_arguments(p, "line rate or 'auto', for devices that do not say")
    p.set_defaults(run=run)


def _requests(args: argparse.Namespace) -> list[DeviceRequest]:
    defaults = {k: getattr(args, k) for k in GLOBAL_OPTIONS if getattr(args, k) is not None}
    requests: list[DeviceRequest] = []
    if args.port:
        if not args.driver:
            raise CommandError("give --driver FAMILY with PORT (or use --device FAMILY=PORT)")
        name, options = device_options(args.driver, {}, f"--driver {args.driver}", defaults)
        requests.append(DeviceRequest(args.driver, args.port, name, options))
    elif args.driver:
        raise CommandError("--driver needs a PORT")
    requests += requests_from_options(args.device, defaults)
    if not requests:
        raise CommandError("nothing to bench: give PORT --driver FAMILY or --device FAMILY=PORT")
    return requests


def _device(request: DeviceRequest, name: str) -> Any:
    from spotlab.bench.run import BenchDevice

    cls = load_driver(request.family)

    def make(port: str) -> Driver:
        return cls(port, name=name, **request.options)

    return BenchDevice(request.family, request.port, name, make)


def _ask(question: str) -> bool:
    print(f"spotlab bench: {question} [y/N] ", end="", file=sys.stderr, flush=True)
    answer = sys.stdin.readline()
    return answer.strip().lower() in ("y", "yes")


def run(args: argparse.Namespace) -> int:
    from spotlab.bench.conformance import SUITES
    from spotlab.bench.run import BenchOptions, run_bench

    if args.seconds <= 0:
        raise CommandError(f"--seconds must be positive, got {args.seconds:g}")
    if args.yes and not args.disruptive:
        raise CommandError("--yes goes with --disruptive")
    requests = _requests(args)
    counts: dict[str, int] = {}
    devices = []
    for r in requests:
        if r.family not in SUITES:
            raise CommandError(
                f"no conformance suite for {r.family} devices (bench knows {', '.join(SUITES)})"
            )
        n = counts.get(r.family, 0)
        counts[r.family] = n + 1
        devices.append(_device(r, r.name or (r.family if n == 0 else f"{r.family}{n}")))
    if args.report.exists() and not args.report.is_dir():
        raise CommandError(f"--report {args.report}: is a file, not a folder")
    if args.baseline is not None and not args.baseline.is_file():
        raise CommandError(f"--baseline {args.baseline}: no such file")
    options = BenchOptions(
        seconds=args.seconds,
        disruptive=args.disruptive,
        ask=None if args.yes else _ask,
        pull_cable=None if args.yes else _ask,
        report_dir=args.report,
        baseline=args.baseline,
        select=args.select,
    )
    report = run_bench(devices, options, lambda line: print(line, file=sys.stderr, flush=True))
    for device in report["devices"]:
        tests = device["conformance"]
        counts_of = {k: sum(t["outcome"] == k for t in tests) for k in ("passed", "failed")}
        print(f"{device['stream']}: conformance {counts_of['passed']} passed, "
              f"{counts_of['failed']} failed")  # fmt: skip
        f = device["figures"]
        if f:
            print(f"  rate {f['rate_hz']} Hz of {f['nominal_rate_hz']:g}, latency p50/p99/max "
                  f"{f['latency_p50_us']}/{f['latency_p99_us']}/{f['latency_max_us']} us, "
                  f"jitter rms {f['jitter_rms_us']} us, drift {f['clock_drift_ppm']} ppm, "
                  f"lost {f['lost_frames']}")  # fmt: skip
        for step in device.get("disruptive", []):
            print(f"  {step['step']}: {step['status']}"
                  + (f" in {step['recovery_s']} s" if step["recovery_s"] is not None else "")
                  + (f" ({step['reason']})" if step["reason"] else ""))  # fmt: skip
    for line in report["failures"]:
        print(f"FAILED {line}")
    print(f"report {args.report / 'report.html'}")
    print(f"verdict {report['verdict']}")
    return EXIT_FAILURE if report["failures"] else 0
