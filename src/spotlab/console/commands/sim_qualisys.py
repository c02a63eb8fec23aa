"""``spotlab sim qualisys``: a simulated Qualisys QTM real-time server on 127.0.0.1.

Its first stdout line is ``127.0.0.1:PORT``, the address a client (the
``qtm-rt`` package, ``spotlab record --device qualisys=127.0.0.1:PORT``)
connects to. It serves until stopped (Ctrl-C, SIGTERM) or ``--seconds``.
"""

from __future__ import annotations

import argparse
from typing import Any

from spotlab.console.commands.sim_serve import serve_until_stopped
from spotlab.console.errors import CommandError
from spotlab.processing.paths import check_output_paths
from spotlab.simulators.qualisys import QualisysServer, QualisysSimOptions


def add_qualisys_arguments(p: Any) -> None:
    """The options only ``spotlab sim qualisys`` takes."""
    g = p.add_argument_group("qualisys (QTM real-time server; also --cameras, --markers, "
                             "--rate, --seed, --faults drop@T[:N],disconnect@T[:S],late@T[:N],"
                             "restart@T,slow@T[:N], "
                             "--clock-drift-ppm PPM (QTM's timestamps run fast), "
                             "--lab DIR --lab-name NAME (frame pulses of QTM's sync output), "
                             "--truth T.npz, --seconds)")  # fmt: skip
    g.add_argument("--password", help="password TakeControl must give (default: none)")


def qualisys_options(args: argparse.Namespace) -> QualisysSimOptions:
    """Simulator options from parsed arguments."""
    if args.tcp is not None:
        raise CommandError("the qualisys simulator serves TCP only: give --port N, not --tcp")
    options = QualisysSimOptions(
        cameras=8 if args.cameras is None else args.cameras,
        markers=40 if args.markers is None else args.markers,
        rate_hz=args.rate,
        seed=args.seed,
        port=args.port,
        truth=args.truth,
        faults=args.faults,
        password=args.password,
        clock_drift_ppm=args.clock_drift_ppm,
        lab=args.lab,
        lab_name=args.lab_name or "",
    )
    try:
        options.validate()
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    return options


def run_qualisys(args: argparse.Namespace) -> int:
    """Serve until stopped; print the address first."""
    check_output_paths([("--truth", args.truth)])
    options = qualisys_options(args)
    try:
        server = QualisysServer(options).start()
    except OSError as exc:
        raise CommandError(f"cannot listen on 127.0.0.1:{options.port}: {exc}") from None
    return serve_until_stopped(server, args.seconds)
