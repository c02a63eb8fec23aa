"""Serve a simulated device on a local TCP port, for pyserial's ``socket://`` URLs.

One client at a time: a second connection is accepted and closed at once.
A client that goes away leaves the device running; the next one picks it up
where it is. TCP has no baud rate and no BREAK: the device's pacing still
holds, ``COMM:`` needs no switch on the host side, and hosts reset with
``RESET:``. On a disconnect fault the client's socket is closed and new
connections are refused (accepted and closed) until the device returns.
"""

from __future__ import annotations

import contextlib
import select
import socket
import threading
import time
from types import TracebackType

from spotlab.simulators.mcs1_device import Mcs1Device
from spotlab.simulators.priority import raise_serving_priority

MIN_WAIT_S = 0.002  # a USB-serial adapter delivers in ms chunks too (FTDI: 1-16 ms)
MAX_WAIT_S = 0.05
#: Bytes an adapter and the host's driver take in before flow control holds the device
#: back (what waits beyond this counts against the device's FIFO).
HOST_SLACK = 1 << 16


class TcpServer:
    """A simulated device on ``127.0.0.1:port``, served by one thread.

    Parameters
    ----------
    device : Mcs1Device
        The device to serve (closed by :meth:`stop`).
    port : int
        TCP port; 0 picks a free one.

    Attributes
    ----------
    url : str
        ``socket://127.0.0.1:PORT``, for ``serial.serial_for_url``.
    """

    def __init__(self, device: Mcs1Device, port: int = 0) -> None:
        self.device = device
        self._listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self._listener.bind(("127.0.0.1", port))
            self._listener.listen(4)
        except OSError:
            self._listener.close()
            raise
        self.port = int(self._listener.getsockname()[1])
        self.url = f"socket://127.0.0.1:{self.port}"
        self.stats = {"bytes_out": 0, "bytes_in": 0, "clients": 0, "refused": 0}
        self._client: socket.socket | None = None
        self._pending = bytearray()
        self._resets_seen = device.resets
        self._stop = threading.Event()
        self._wake_r, self._wake_w = socket.socketpair()
        self._thread: threading.Thread | None = None

    def start(self) -> TcpServer:
        """Start serving."""
        if self._thread is not None:
            raise RuntimeError("TcpServer already started")
        self.device.output(time.monotonic_ns())  # sent before the port existed: lost
        self._thread = threading.Thread(target=self._run, name="spotlab-sim-tcp", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop serving, close every socket, close the device."""
        self._stop.set()
        with contextlib.suppress(OSError):
            self._wake_w.send(b"x")
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        self._drop_client()
        for s in (self._listener, self._wake_r, self._wake_w):
            s.close()
        self.device.close()

    def __enter__(self) -> TcpServer:
        return self if self._thread is not None else self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()

    def _drop_client(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None
        self._pending.clear()

    def _accept(self, down: bool) -> None:
        conn, _ = self._listener.accept()
        if down or self._client is not None:
            self.stats["refused"] += 1
            conn.close()
            return
        conn.setblocking(False)
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._client = conn
        self.stats["clients"] += 1

    def _run(self) -> None:
        raise_serving_priority()
        while not self._stop.is_set():
            now = time.monotonic_ns()
            down = self.device.link_down(now)
            if down:
                self._drop_client()
            self.device.host_backlog = max(0, len(self._pending) - HOST_SLACK)
            segments = self.device.output_segments(now)
            if self.device.resets != self._resets_seen:
                # A reset empties what flow control held back (still in the device's FIFO).
                self._resets_seen = self.device.resets
                if len(self._pending) > HOST_SLACK:
                    self._pending.clear()
                    segments = [g for g in segments if g.end_ns >= self.device.last_reset_ns]
            if self._client is not None:
                for seg in segments:
                    self._pending += seg.data
                self._send_pending()
            self.device.host_backlog = max(0, len(self._pending) - HOST_SLACK)
            nxt = self.device.next_event_ns()
            wait = (
                MAX_WAIT_S if nxt is None else min(max((nxt - now) / 1e9, MIN_WAIT_S), MAX_WAIT_S)
            )
            readers: list[socket.socket] = [self._listener, self._wake_r]
            if self._client is not None:
                readers.append(self._client)
            writers = [self._client] if self._client is not None and self._pending else []
            readable, _, _ = select.select(readers, writers, [], wait)
            if self._client is not None and self._client in readable:
                self._receive()  # first: a client that left frees the place for the next
            if self._listener in readable:
                self._accept(down)
            if self._wake_r in readable:
                with contextlib.suppress(OSError):
                    self._wake_r.recv(64)

    def _receive(self) -> None:
        assert self._client is not None
        try:
            data = self._client.recv(4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            data = b""
        if not data:
            self._drop_client()
            return
        self.stats["bytes_in"] += len(data)
        self.device.receive(data, time.monotonic_ns(), line_baud=None)

    def _send_pending(self) -> None:
        assert self._client is not None
        while self._pending:
            try:
                n = self._client.send(self._pending)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                self._drop_client()
                return
            self.stats["bytes_out"] += n
            del self._pending[:n]
        del self._pending[self.device.fifo_bytes + 2 * HOST_SLACK :]
