"""Serve a simulated device on a real pseudo-terminal, behind a stable path.

The host opens :attr:`PtyServer.path` with plain pyserial (``serial.Serial(path)``)
and goes through the real termios code. The path is a symlink in a private
temporary folder that points at the current ``/dev/pts/N``, as a udev by-id link
points at ``/dev/ttyUSBn``. On a disconnect fault the server closes the master
(the host's reads fail with EIO), removes the link, and after the fault's delay
opens a new pseudo-terminal and points the link at it: the host reopens the
same path.

A pseudo-terminal carries any baud rate at memory speed; the device paces
itself. The host port's configured rate is read back (``TCGETS2``) and a
mismatch with the device's rate garbles the bytes both ways, as on a real line.
A BREAK cannot cross a pseudo-terminal: hosts reset with ``RESET:`` instead.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import select
import shutil
import struct
import tempfile
import termios
import threading
import time
import tty
from pathlib import Path
from types import TracebackType

import numpy as np

from spotlab.simulators.line import Segment, garble
from spotlab.simulators.mcs1_device import Mcs1Device
from spotlab.simulators.priority import raise_serving_priority

TCGETS2 = 0x802C542A  # _IOR('T', 0x2A, struct termios2) on Linux
MIN_WAIT_S = 0.002  # a USB-serial adapter delivers in ms chunks too (FTDI: 1-16 ms)
MAX_WAIT_S = 0.05
#: Bytes an adapter and the host's driver take in before flow control holds the device
#: back (what waits beyond this counts against the device's FIFO).
HOST_SLACK = 1 << 16
#: A device more than this far behind real time (ns) catches up in steps of this length,
#: writing to the port between them. What one step adds (12 kB at 12 Mbaud) must stay
#: within HOST_SLACK: the device judges its FIFO by the host backlog read before the
#: step, and bytes beyond the buffer's limit would be cut mid-frame (CRC errors).
CATCH_UP_NS = 10_000_000


def tty_baud(fd: int) -> int | None:
    """Output baud rate configured on a terminal (either side of a pty), or None if unknown."""
    try:
        buf = fcntl.ioctl(fd, TCGETS2, bytes(44))
        return int(struct.unpack_from("=I", buf, 40)[0]) or None
    except OSError:
        pass
    try:
        code = termios.tcgetattr(fd)[5]
    except termios.error:
        return None
    for name in dir(termios):
        if name.startswith("B") and name[1:].isdigit() and getattr(termios, name) == code:
            return int(name[1:]) or None
    return None


class PtyServer:
    """A simulated device on a pseudo-terminal, served by one thread.

    Parameters
    ----------
    device : Mcs1Device
        The device to serve (closed by :meth:`stop`).
    name : str
        File name of the stable link.

    Attributes
    ----------
    path : Path
        The stable link to open (valid after :meth:`start`).
    stats : dict
        ``bytes_out``, ``bytes_in``, ``overrun_bytes`` (output the host did not
        read in time and the pty could not hold; flow control keeps it at 0: the
        device sees what waits here in ``host_backlog`` and drops whole frames from
        its FIFO instead), ``reconnects``.
    """

    def __init__(self, device: Mcs1Device, name: str = "selspot") -> None:
        self.device = device
        self._dir = Path(tempfile.mkdtemp(prefix="spotlab-sim-"))
        self.path = self._dir / name
        self.stats = {"bytes_out": 0, "bytes_in": 0, "overrun_bytes": 0, "reconnects": 0}
        self._master: int | None = None
        self._slave: int | None = None
        self._pending = bytearray()
        self._resets_seen = device.resets
        self._rng = np.random.default_rng(0x9714)
        self._stop = threading.Event()
        self._wake_r, self._wake_w = os.pipe()
        self._thread: threading.Thread | None = None

    @property
    def pts(self) -> str | None:
        """The current ``/dev/pts/N``, or None while disconnected."""
        return os.ttyname(self._slave) if self._slave is not None else None

    def start(self) -> PtyServer:
        """Open the pseudo-terminal and start serving."""
        if self._thread is not None:
            raise RuntimeError("PtyServer already started")
        self.device.output(time.monotonic_ns())  # sent before the port existed: lost
        self._open_pty()
        self._thread = threading.Thread(target=self._run, name="spotlab-sim-pty", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop serving, close every descriptor, remove the link folder, close the device."""
        self._stop.set()
        with contextlib.suppress(OSError):
            os.write(self._wake_w, b"x")
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        self._close_pty()
        for fd in (self._wake_r, self._wake_w):
            with contextlib.suppress(OSError):
                os.close(fd)
        self._wake_r = self._wake_w = -1
        shutil.rmtree(self._dir, ignore_errors=True)
        self.device.close()

    def __enter__(self) -> PtyServer:
        return self if self._thread is not None else self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()

    # -- pseudo-terminal ---------------------------------------------------------
    def _open_pty(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        tmp = self._dir / (self.path.name + ".new")
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        os.symlink(os.ttyname(slave), tmp)
        os.replace(tmp, self.path)

    def _close_pty(self) -> None:
        with contextlib.suppress(FileNotFoundError):
            self.path.unlink()
        for fd in (self._master, self._slave):
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = None
        self._pending.clear()

    # -- serving -----------------------------------------------------------------
    def _run(self) -> None:
        raise_serving_priority()
        served: int | None = None
        while not self._stop.is_set():
            # A device that fell behind (its host is busy) catches up in steps, its
            # bytes written between them, as a real one sends while it works.
            real = time.monotonic_ns()
            behind = served is not None and real - served > CATCH_UP_NS
            now = served + CATCH_UP_NS if served is not None and behind else real
            if self.device.link_down(now):
                now = served = real  # nothing to send while the port is away: keep time
                if self._master is not None:
                    self._close_pty()
                self.device.output_segments(now)  # what went on the dead link is lost
                back = self.device.link_return_ns(now)
                # Wake at least every MAX_WAIT_S: the device keeps running (and is kept
                # caught up) while its port is away, ready to answer the moment it returns.
                wait = (
                    MAX_WAIT_S
                    if back is None
                    else max(MIN_WAIT_S, min(MAX_WAIT_S, (back - now) / 1e9))
                )
                select.select([self._wake_r], [], [], wait)
                continue
            served = now
            if self._master is None:
                self._open_pty()
                self.stats["reconnects"] += 1
            self._serve_once(now, behind=now < real)

    def _serve_once(self, now: int, behind: bool = False) -> None:
        master = self._master
        assert master is not None
        host_baud = tty_baud(master)
        self.device.host_backlog = max(0, len(self._pending) - HOST_SLACK)
        for seg in self._segments(now):
            data = seg.data
            if host_baud is not None and host_baud != seg.baud:
                data = garble(data, seg.baud, host_baud, self._rng)
            self._pending += data
        self._flush_pending(master, self.device.fifo_bytes + 2 * HOST_SLACK)
        self.device.host_backlog = max(0, len(self._pending) - HOST_SLACK)
        nxt = self.device.next_event_ns()
        wait = MAX_WAIT_S if nxt is None else min(max((nxt - now) / 1e9, MIN_WAIT_S), MAX_WAIT_S)
        if behind:
            wait = 0.0
        writers = [master] if self._pending else []
        readable, _, _ = select.select([master, self._wake_r], writers, [], wait)
        if master in readable:
            try:
                data = os.read(master, 4096)
            except (BlockingIOError, InterruptedError):
                data = b""
            except OSError:
                data = b""
            if data:
                self.stats["bytes_in"] += len(data)
                self.device.receive(data, time.monotonic_ns(), line_baud=tty_baud(master))
        if self._wake_r in readable:
            with contextlib.suppress(OSError):
                os.read(self._wake_r, 64)

    def _segments(self, now: int) -> list[Segment]:
        """The device's output until ``now``; a reset meanwhile empties what flow control
        held back (bytes the host had not taken: they were still in the device's FIFO)."""
        segments = self.device.output_segments(now)
        if self.device.resets != self._resets_seen:
            self._resets_seen = self.device.resets
            if len(self._pending) > HOST_SLACK:
                self._pending.clear()
                segments = [g for g in segments if g.end_ns >= self.device.last_reset_ns]
        return segments

    def _flush_pending(self, master: int, limit: int) -> None:
        while self._pending:
            try:
                n = os.write(master, self._pending)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                self._pending.clear()
                break
            self.stats["bytes_out"] += n
            del self._pending[:n]
        if len(self._pending) > limit:
            extra = len(self._pending) - limit
            self.stats["overrun_bytes"] += extra
            del self._pending[limit:]
