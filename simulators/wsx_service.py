"""A WSX hub served to other processes: USB over a TCP socket (docs/protocols/wsx.md §8).

``WsxServer`` listens on 127.0.0.1; each connection is one host, its requests
answered in order by the :class:`~spotlab.simulators.wsx_device.WsxDevice`. The
address a driver opens is ``wsxsim://127.0.0.1:PORT/SERIAL``. On stop the truth
(true positions at every frame's start and the true CCD calibration) is written
as an npz file when asked for.
"""

from __future__ import annotations

import socket
import struct
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spotlab.simulators import wsx_wire as w
from spotlab.simulators.priority import raise_serving_priority
from spotlab.simulators.wsx_device import NO_DEVICE, WsxDevice, parse_faults
from spotlab.simulators.wsx_scene import WsxScene


@dataclass
class WsxSimOptions:
    """What ``spotlab sim wsx`` builds: scene, power-up set-up, faults."""

    sensors: int = 3
    markers: int = 8
    marker_rate_hz: float = 2500.0
    rate_hz: float | None = None
    seed: int = 0
    serial: str = "WSX00042"
    faults: str = ""
    registered: bool = True

    def validate(self) -> None:
        """Raise ValueError for what the device could not be built with."""
        if not 1 <= self.sensors <= 8:
            raise ValueError(f"--sensors must be 1 to 8, got {self.sensors}")
        if not 1 <= self.markers <= 512:
            raise ValueError(f"--markers must be 1 to 512, got {self.markers}")
        if not 1500.0 <= self.marker_rate_hz <= 4600.0:
            raise ValueError(f"--marker-rate must be 1500 to 4600 Hz, got {self.marker_rate_hz:g}")
        bound = self.marker_rate_hz / (self.markers + 2)
        if self.rate_hz is not None and not 0.001 <= self.rate_hz <= bound * (1 + 1e-9):
            raise ValueError(
                f"--rate must be at most marker rate / (markers + 2) = {bound:.3f} Hz, "
                f"got {self.rate_hz:g}"
            )
        parse_faults(self.faults)

    def setup(self) -> w.Setup:
        """The device's set-up after power-up (wsx.md §4.1 defaults, with these options)."""
        mrate = round(self.marker_rate_hz * 1000)
        bound = mrate // (self.markers + 2)
        frate = bound if self.rate_hz is None and bound < 100_000 else 100_000
        if self.rate_hz is not None:
            frate = min(round(self.rate_hz * 1000), bound)
        return w.Setup(
            self.markers, (self.markers, 0, 0, 0), 350, mrate, frate, 80, 30, 160, w.FLAG_FULL_RAW
        )


def build_device(options: WsxSimOptions) -> WsxDevice:
    """The simulated hub of ``options``."""
    options.validate()
    scene = WsxScene(options.sensors, options.markers, options.seed)
    return WsxDevice(
        scene, options.serial, options.setup(), parse_faults(options.faults),
        registered=options.registered,
    )  # fmt: skip


def write_truth(device: WsxDevice, path: Path) -> None:
    """Frames' true positions (F, M, 3) mm at their starts, and the true calibration."""
    t, g = device.truth, device.scene.geometry
    m = device.scene.n_markers
    pts = [p for p in t.points if p.shape[0] == m]
    keep = [i for i, p in enumerate(t.points) if p.shape[0] == m]
    np.savez_compressed(
        path,
        frame_no=np.asarray(t.frame_no, dtype=np.int64)[keep],
        collection=np.asarray(t.collection, dtype=np.int64)[keep],
        start_ns=np.asarray(t.start_ns, dtype=np.int64)[keep],
        points=np.asarray(pts).reshape(-1, m, 3),
        R=g.R, t=g.t, focal=g.focal, principal=g.principal, axis=g.axis,
    )  # fmt: skip


class WsxServer:
    """The hub on a TCP port of 127.0.0.1 (0: any free port)."""

    def __init__(self, device: WsxDevice, port: int = 0, truth: Path | None = None) -> None:
        self.device, self.truth = device, truth
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._sock.bind(("127.0.0.1", port))
        self._sock.listen(8)
        self._sock.settimeout(0.1)  # accept() wakes up to see a stop
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._conns: list[socket.socket] = []

    @property
    def address(self) -> str:
        """``wsxsim://127.0.0.1:PORT/SERIAL``: what the driver opens."""
        port = self._sock.getsockname()[1]
        return f"wsxsim://127.0.0.1:{port}/{self.device.serial}"

    def start(self) -> None:
        t = threading.Thread(target=self._accept, name="wsx-accept", daemon=True)
        t.start()
        self._threads.append(t)

    def stop(self) -> None:
        self._stop.set()
        try:
            self._sock.close()
        except OSError:
            pass
        for c in list(self._conns):
            try:
                c.shutdown(socket.SHUT_RDWR)
                c.close()
            except OSError:
                pass
        for t in self._threads:
            t.join(timeout=2.0)
        if self.truth is not None:
            write_truth(self.device, self.truth)

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._sock.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            conn.settimeout(None)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._conns.append(conn)
            t = threading.Thread(target=self._serve, args=(conn,), daemon=True)
            t.start()
            self._threads.append(t)

    def _serve(self, conn: socket.socket) -> None:
        raise_serving_priority()
        session = _Session(self.device)
        try:
            while not self._stop.is_set():
                head = _recv_exact(conn, 4)
                if head is None:
                    return
                body = _recv_exact(conn, struct.unpack("<I", head)[0])
                if body is None or not body:
                    return
                conn.sendall(session.handle(body[0], body[1:]))
        except OSError:
            return
        finally:
            conn.close()


class _Session:
    """One host's requests on the link (wsx.md §8)."""

    def __init__(self, device: WsxDevice) -> None:
        self.device = device
        self.generation: int | None = None

    def handle(self, op: int, args: bytes) -> bytes:
        d = self.device
        if op == w.OP_LIST:
            with d.lock:
                present = d.present(d.generation)
                entry = w.list_entry(d.bus, d.address, d.port) if present else b""
            return w.reply(0, bytes([1 if entry else 0]) + entry)
        if op == w.OP_OPEN:
            with d.lock:
                ok = d.present(d.generation) and args[:1] == bytes([d.address])
                self.generation = d.generation if ok else None
            return w.reply(0 if ok else NO_DEVICE)
        if op == w.OP_CLOSE:
            self.generation = None
            return w.reply(0)
        gen = -1 if self.generation is None else self.generation
        if op in (w.OP_SET_CONFIG, w.OP_CLAIM, w.OP_RELEASE):
            return w.reply(0 if d.present(gen) else NO_DEVICE)
        if op == w.OP_CONTROL:
            rt, rq, value, index, length, _timeout = w.CONTROL.unpack_from(args)
            data = args[w.CONTROL.size :]
            status, out = d.control(gen, rt, rq, value, index, data, length)
            return w.reply(status, out)
        if op == w.OP_READ:
            ep, length, timeout = w.READ.unpack_from(args)
            status, out = d.read(gen, ep, length, timeout)
            return w.reply(status, out)
        if op == w.OP_CLEAR_HALT:
            return w.reply(d.clear_halt(gen, args[0]))
        return w.reply(-5)


def _recv_exact(conn: socket.socket, n: int) -> bytes | None:
    buf = bytearray()
    while len(buf) < n:
        chunk = conn.recv(n - len(buf))
        if not chunk:
            return None
        buf += chunk
    return bytes(buf)


def serve_wsx(options: WsxSimOptions, port: int = 0, truth: Path | None = None) -> WsxServer:
    """Build the hub of ``options`` and serve it (started)."""
    server = WsxServer(build_device(options), port, truth)
    server.start()
    return server
