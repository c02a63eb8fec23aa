"""``spotlab console``: the lab acquisition console, a web page (docs/console.md)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from spotlab.console.errors import CommandError
from spotlab.console.options import add_realtime_argument


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "console",
        help="serve the lab acquisition console, a live web page (devices, views, trials)",
        description=(
            "Serve the lab acquisition console on a web page: devices, live 2-D and 3-D "
            "views, trials recorded into DATA/SUBJECT/SESSION/TRIAL.spj and exported to "
            "C3D/TRC. Prints its URL on the first line; runs until Ctrl-C or SIGTERM."
        ),
    )
    lab = p.add_mutually_exclusive_group()
    lab.add_argument("--lab", type=Path, metavar="LAB.toml", help="the lab file's devices")
    lab.add_argument(
        "--sim", action="store_true", help="a simulated lab: SELSPOT system, centroid hub, timer"
    )
    p.add_argument("--host", default="127.0.0.1", help="address to serve on (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=8765, help="TCP port (default 8765; 0: a free one)")
    p.add_argument("--no-browser", action="store_true", help="do not open a web browser")
    p.add_argument(
        "--data",
        type=Path,
        default=Path("spotlab-data"),
        metavar="DIR",
        help="where trials go (default ./spotlab-data)",
    )
    p.add_argument(
        "--token",
        default=None,
        metavar="T",
        help="a token the page and API require (needed with a --host other than loopback)",
    )
    add_realtime_argument(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    if not 0 <= args.port <= 65535:
        raise CommandError(f"--port must be 0-65535, got {args.port}")
    if args.lab is None and not args.sim:
        raise CommandError("give --lab LAB.toml (the devices to acquire from) or --sim")
    from spotlab.console.web.security import check_access

    check_access(args.host, args.token)  # before the web server's imports (seconds)
    from spotlab.console.web.server import serve  # its imports: starlette, uvicorn

    return serve(
        lab=args.lab,
        sim=args.sim,
        host=args.host,
        port=args.port,
        data=args.data,
        token=args.token,
        open_browser=not args.no_browser,
        realtime=args.realtime,
    )
