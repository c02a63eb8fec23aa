"""``spotlab sim natnet``: a simulated OptiTrack Motive NatNet server on 127.0.0.1."""

from __future__ import annotations

import argparse
from typing import Any

from spotlab.console.commands.sim_serve import serve_until_stopped
from spotlab.console.errors import CommandError
from spotlab.processing.paths import check_output_paths
from spotlab.simulators.natnet import NatNetServer, parse_faults
from spotlab.simulators.natnet_scene import NatNetScene


def add_arguments(p: Any) -> None:
    """The options only ``spotlab sim natnet`` takes."""
    g = p.add_argument_group("natnet (OptiTrack Motive's NatNet stream, UDP on 127.0.0.1)")
    g.add_argument(
        "--natnet-version", default="4.1", choices=["3.1", "4.1"],
        help="natnet: NatNet version served (default 4.1)",
    )  # fmt: skip


def run(args: argparse.Namespace) -> int:
    """Serve until stopped (SIGTERM, Ctrl-C) or ``--seconds``; print ``host:port`` first."""
    if args.truth is not None and args.truth.suffix != ".npz":
        raise CommandError(f"--truth {args.truth}: the natnet truth is an .npz file")
    check_output_paths([("--truth", args.truth)])
    if not 0 <= args.port <= 65535:
        raise CommandError(f"--port must be 0 to 65535, got {args.port}")
    try:
        parse_faults(args.faults)
        scene = NatNetScene(
            markers=40 if args.markers is None else args.markers,
            cameras=8 if args.cameras is None else args.cameras,
            rate_hz=args.rate,
            seed=args.seed,
        )
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    major, minor = (int(x) for x in args.natnet_version.split("."))
    try:
        server = NatNetServer(
            scene, version=(major, minor), port=args.port, truth=args.truth, faults=args.faults,
            clock_drift_ppm=args.clock_drift_ppm, clock_offset_s=args.clock_offset,
        )  # fmt: skip
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    except OSError as exc:
        raise CommandError(f"cannot bind 127.0.0.1:{args.port}: {exc.strerror}") from None
    server.start()
    return serve_until_stopped(server, args.seconds)
