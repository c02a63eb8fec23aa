"""A loopback TCP relay that can cut its connections: a server dropping its clients, on demand.

:class:`CuttableRelay` listens on 127.0.0.1 (a free port) and relays every
connection to a target ``host:port`` in both directions; :meth:`CuttableRelay.cut`
closes every relayed connection at once, both sides, as a server that drops its
clients does (a QTM restarting, a network cable pulled and put back). New
connections are relayed again at once, or after ``refuse_s`` seconds. It works
in front of a simulator and of a real device alike, so a conformance suite can
test a driver's reconnection without any help from the server.
"""

from __future__ import annotations

import contextlib
import selectors
import socket
import threading
import time


class CuttableRelay:
    """Relay 127.0.0.1:``port`` to ``target``; ``cut()`` drops every connection.

    Parameters
    ----------
    host, port : str, int
        The server relayed to.

    Attributes
    ----------
    port : int
        The relay's own port on 127.0.0.1 (after ``start``).
    accepted : int
        Connections relayed so far.
    """

    def __init__(self, host: str, port: int) -> None:
        self.target = (host, port)
        self.port = 0
        self.accepted = 0
        self._listener: socket.socket | None = None
        self._pairs: list[tuple[socket.socket, socket.socket]] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._refuse_until = 0.0
        self._thread: threading.Thread | None = None

    @property
    def address(self) -> str:
        """``127.0.0.1:PORT``, what a client connects to."""
        return f"127.0.0.1:{self.port}"

    def start(self) -> CuttableRelay:
        """Listen and relay in a thread of its own."""
        listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listener.bind(("127.0.0.1", 0))
        listener.listen(8)
        listener.setblocking(False)
        self._listener = listener
        self.port = int(listener.getsockname()[1])
        self._thread = threading.Thread(target=self._run, name="tcp-relay", daemon=True)
        self._thread.start()
        return self

    def cut(self, refuse_s: float = 0.0) -> None:
        """Close every relayed connection, both sides; refuse new ones for ``refuse_s`` s."""
        with self._lock:
            self._refuse_until = time.monotonic() + refuse_s
            pairs, self._pairs = self._pairs, []
        for a, b in pairs:
            for s in (a, b):
                with contextlib.suppress(OSError):
                    s.shutdown(socket.SHUT_RDWR)
                s.close()

    def stop(self) -> None:
        """Cut everything and stop listening."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
            self._thread = None
        self.cut()
        if self._listener is not None:
            self._listener.close()
            self._listener = None

    def __enter__(self) -> CuttableRelay:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _accept(self) -> None:
        assert self._listener is not None
        try:
            client, _ = self._listener.accept()
        except (BlockingIOError, OSError):
            return
        if time.monotonic() < self._refuse_until:
            client.close()
            return
        try:
            server = socket.create_connection(self.target, timeout=3.0)
        except OSError:
            client.close()
            return
        for s in (client, server):
            s.setblocking(False)
            s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        with self._lock:
            self._pairs.append((client, server))
        self.accepted += 1

    def _run(self) -> None:
        assert self._listener is not None
        while not self._stop.is_set():
            with self._lock:
                pairs = list(self._pairs)
            sel = selectors.DefaultSelector()
            sel.register(self._listener, selectors.EVENT_READ, None)
            for a, b in pairs:
                with contextlib.suppress(ValueError, OSError):
                    sel.register(a, selectors.EVENT_READ, (a, b))
                    sel.register(b, selectors.EVENT_READ, (b, a))
            try:
                ready = sel.select(0.02)
            except (OSError, ValueError):
                ready = []
            finally:
                sel.close()
            for key, _ in ready:
                if key.data is None:
                    self._accept()
                    continue
                src, dst = key.data
                self._pump(src, dst)

    def _pump(self, src: socket.socket, dst: socket.socket) -> None:
        try:
            data = src.recv(1 << 16)
        except BlockingIOError:
            return
        except OSError:
            data = b""
        if data:
            try:
                dst.setblocking(True)
                dst.sendall(data)
                dst.setblocking(False)
                return
            except OSError:
                pass
        with self._lock:
            self._pairs = [p for p in self._pairs if src not in p]
        for s in (src, dst):
            with contextlib.suppress(OSError):
                s.shutdown(socket.SHUT_RDWR)
            s.close()
