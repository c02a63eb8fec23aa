"""Serving a network simulator from the command line (``spotlab sim qualisys|natnet``)."""

from __future__ import annotations

import signal
import sys
import threading
from typing import Protocol


class NetworkSimulator(Protocol):
    """A simulator serving on 127.0.0.1 (started already)."""

    @property
    def address(self) -> str: ...

    def stop(self) -> None: ...


def serve_until_stopped(server: NetworkSimulator, seconds: float | None) -> int:
    """Print the address a client connects to first, then serve until SIGTERM, Ctrl-C or
    ``seconds``; the server is stopped (its truth written) in every case."""
    stop = threading.Event()

    def _stop(signum: int, frame: object) -> None:
        stop.set()

    signal.signal(signal.SIGTERM, _stop)
    signal.signal(signal.SIGINT, _stop)
    try:
        print(server.address, flush=True)
        stop.wait(seconds)
    finally:
        server.stop()
    sys.stdout.flush()
    return 0
