"""``spotlab console``: bind, print the URL, serve until SIGINT or SIGTERM.

The socket is bound here, before anything starts, so that a busy port is one error
line (and ``--port 0`` takes a free port whose number the URL gives).
"""

from __future__ import annotations

import signal
import socket
import threading
import webbrowser
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import uvicorn

from spotlab.acquisition.realtime import raise_thread
from spotlab.console.web.acquisition import Acquisition
from spotlab.console.web.app import make_app
from spotlab.console.web.lab_setup import plan_lab
from spotlab.console.web.security import check_access
from spotlab.console.web.trials import TrialStore
from spotlab.processing.errors import InputError

__all__ = ["bind", "serve"]


def bind(host: str, port: int) -> socket.socket:
    """A listening TCP socket on ``host:port`` (InputError if it cannot be had)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    try:
        sock.bind((host, port))
        sock.listen(64)
    except OSError as exc:
        sock.close()
        why = "it is in use (another console?)" if exc.errno == 98 else (exc.strerror or exc)
        raise InputError(f"cannot listen on {host}:{port}: {why}") from None
    return sock


class _Server(uvicorn.Server):
    """uvicorn's server, stopped by SIGINT/SIGTERM without re-raising them afterwards
    (a deliberate stop ends ``spotlab console`` with exit code 0)."""

    @contextmanager
    def capture_signals(self) -> Iterator[None]:
        if threading.current_thread() is not threading.main_thread():
            yield
            return

        def stop(signum: int, frame: object) -> None:
            self.should_exit = True

        old = {sig: signal.signal(sig, stop) for sig in (signal.SIGINT, signal.SIGTERM)}
        try:
            yield
        finally:
            for sig, handler in old.items():
                signal.signal(sig, handler)


def serve(
    *,
    lab: Path | None,
    sim: bool,
    host: str,
    port: int,
    data: Path,
    token: str | None,
    open_browser: bool,
    realtime: int | None = None,
) -> int:
    """Run the console; returns the exit code (0 after SIGINT or SIGTERM)."""
    check_access(host, token)
    sock = bind(host, port)
    try:
        plan = plan_lab(lab, sim, data)
        acq = Acquisition(plan, TrialStore(data), realtime_priority=realtime)
    except BaseException:
        sock.close()
        raise
    bound = sock.getsockname()[1]
    shown = f"[{host}]" if ":" in host else host
    url = f"http://{shown}:{bound}/" + (f"?token={token}" if token else "")
    print(url, flush=True)
    if realtime is not None:
        # This thread, where the web server runs, under SCHED_FIFO too: a normal thread
        # holding the interpreter lock while other programs (the page's browser) run
        # would hold up the sessions' raised threads. Threads started from here do not
        # inherit it (SCHED_RESET_ON_FORK resets every new thread); the sessions raise
        # their own, and tell a refusal (Acquisition's note).
        raise_thread(realtime)
    acq.start()
    app = make_app(acq, token)
    # no per-message deflate: the live messages (a few kB at 33 Hz) to a page on this
    # machine or the lab's network are not worth compressing in the acquiring process
    config = uvicorn.Config(
        app, log_level="warning", access_log=False, lifespan="off", ws_per_message_deflate=False
    )
    server = _Server(config)
    if open_browser:
        threading.Timer(0.5, webbrowser.open, (url,)).start()
    try:
        server.run(sockets=[sock])
    finally:
        for close in app.state.closers:
            close()
        acq.close()
        sock.close()
    return 0
