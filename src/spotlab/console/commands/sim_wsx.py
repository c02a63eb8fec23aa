"""``spotlab sim wsx``: a simulated WSX hub (docs/protocols/wsx.md), USB over a local socket."""

from __future__ import annotations

import argparse
from typing import Any

from spotlab.console.commands.sim_serve import serve_until_stopped
from spotlab.console.errors import CommandError
from spotlab.processing.paths import check_output_paths


def add_arguments(p: Any) -> None:
    """The options only ``spotlab sim wsx`` takes."""
    g = p.add_argument_group("wsx (LED-multiplexed linear sensors over USB, on 127.0.0.1)")
    g.add_argument(
        "--sensors", type=int, default=3,
        help="wsx: position sensors of three linear CCDs each, 1-8 (default 3)",
    )  # fmt: skip
    g.add_argument(
        "--marker-rate", type=float, default=2500.0, metavar="HZ",
        help="wsx: marker rate after power-up, 1500-4600 Hz (default 2500)",
    )  # fmt: skip
    g.add_argument(
        "--unregistered", action="store_true",
        help="wsx: the factory calibration gives each position sensor's CCDs in the sensor's "
        "own frame; spotlab reconstruct registers the sensors with the markers they share",
    )  # fmt: skip


def run(args: argparse.Namespace) -> int:
    """Serve until stopped or ``--seconds``; print ``wsxsim://127.0.0.1:PORT/SERIAL`` first."""
    from spotlab.simulators.wsx_service import WsxSimOptions, serve_wsx

    if args.truth is not None and args.truth.suffix != ".npz":
        raise CommandError(f"--truth {args.truth}: the wsx truth is an .npz file")
    check_output_paths([("--truth", args.truth)])
    if not 0 <= args.port <= 65535:
        raise CommandError(f"--port must be 0 to 65535, got {args.port}")
    options = WsxSimOptions(
        sensors=args.sensors,
        markers=8 if args.markers is None else args.markers,
        marker_rate_hz=args.marker_rate,
        rate_hz=args.rate if getattr(args, "rate_given", False) else None,
        seed=args.seed,
        faults=args.faults,
        registered=not args.unregistered,
    )
    try:
        options.validate()
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    try:
        server = serve_wsx(options, port=args.port, truth=args.truth)
    except OSError as exc:
        raise CommandError(f"cannot bind 127.0.0.1:{args.port}: {exc.strerror}") from None
    return serve_until_stopped(server, args.seconds)
