"""The synthetic ``image2d`` device in a process of its own, streaming raw frames to a socket.

:class:`~spotlab.testing.synthetic_image2d.SyntheticImage2d` makes its frames in the
session's process; a real camera system is another machine and its driver only reads
bytes and decodes them. Here the frames are made and paced by a child process
(``python -m spotlab.testing.image2d_source``) that writes them to one end of a
``socketpair``; :class:`Image2dSourceDevice`, in the session's process, reads the other
end, stamps each frame's ``arrival_ns`` when the read that completes it returns, and
decodes the bytes with ``np.frombuffer``.

Wire layout of one frame (little-endian, no padding), ``32 + 8 M C`` bytes:

======  =====================  ==================================================
offset  field                  type
======  =====================  ==================================================
0       magic ``I2D1``         4 bytes
4       n_cameras (C)          u16
6       n_markers (M)          u16
8       seq                    u64, frame number from 0
16      ticks                  i64, device clock in us (``seq * 1e6 / rate``)
24      sent_ns                i64, the source's ``time.monotonic_ns`` at the write
                               (test-only: how late the source wrote the frame)
32      x, y                   float32 (M, C, 2) px, marker-major; NaN where unseen
======  =====================  ==================================================

Pacing: frame ``k`` is written at ``t0 + k / rate`` on the source's ``time.monotonic_ns``
(the host's ``CLOCK_MONOTONIC``, shared by both processes), ``t0`` the instant the
source is ready; it sleeps between frames, so it competes with the reader for the
cores but not for the reader's interpreter lock. The frames are those of a
:class:`SyntheticImage2d` with the same rig, markers, rate, seed and noise, so
``SyntheticImage2d(...).truth(seq)`` in the reading process gives the true positions.
"""

from __future__ import annotations

import argparse
import select
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from spotlab.acquisition.live.latency import LatencyStats
from spotlab.core.errors import DeviceError
from spotlab.core.frames import FrameBlock
from spotlab.core.stats import LinkStats
from spotlab.core.streams import StreamSpec
from spotlab.core.wire import WireTap
from spotlab.geometry import Rig
from spotlab.testing.synthetic_image2d import TICK_HZ, SyntheticImage2d

__all__ = ["HEADER_BYTES", "MAGIC", "Image2dSourceDevice", "frame_dtype", "serve"]

MAGIC = b"I2D1"
HEADER_BYTES = 32


def frame_dtype(n_cameras: int, n_markers: int) -> np.dtype[Any]:
    """Structured dtype of one wire frame of ``n_cameras`` x ``n_markers`` (see module doc)."""
    return np.dtype(
        [
            ("magic", "S4"),
            ("n_cameras", "<u2"),
            ("n_markers", "<u2"),
            ("seq", "<u8"),
            ("ticks", "<i8"),
            ("sent_ns", "<i8"),
            ("xy", "<f4", (n_markers, n_cameras, 2)),
        ]
    )


def serve(
    sock: socket.socket,
    rig: Rig,
    n_markers: int,
    rate_hz: float,
    *,
    seed: int = 0,
    noise_px: float = 0.2,
    period: int = 600,
    seconds: float | None = None,
) -> int:
    """Write paced frames to ``sock`` until the reader closes it (or ``seconds`` pass).

    Parameters
    ----------
    sock : socket.socket
        Connected stream socket (blocking).
    rig, n_markers, rate_hz, seed, noise_px, period
        As for :class:`SyntheticImage2d` (the same frames).
    seconds : float, optional
        Stop after this long (default: until the reader goes away).

    Returns
    -------
    int
        Frames written.
    """
    device = SyntheticImage2d(
        rig, n_markers, rate_hz, seed=seed, noise_px=noise_px, period=period, paced=False
    )
    dtype = frame_dtype(len(rig), n_markers)
    frames = np.zeros(period, dtype=dtype)
    frames["magic"] = MAGIC
    frames["n_cameras"] = len(rig)
    frames["n_markers"] = n_markers
    frames["xy"] = device.frames()
    out = np.zeros(1, dtype=dtype)
    wire = out.view(np.uint8).data
    t0 = time.monotonic_ns()
    end = None if seconds is None else t0 + round(seconds * 1e9)
    seq = 0
    while True:
        due = t0 + round(seq * 1e9 / rate_hz)
        if end is not None and due > end:
            return seq
        wait = due - time.monotonic_ns()
        if wait > 0:
            time.sleep(wait / 1e9)
        out[0] = frames[seq % period]
        out["seq"] = seq
        out["ticks"] = round(seq * TICK_HZ / rate_hz)
        out["sent_ns"] = time.monotonic_ns()
        try:
            sock.sendall(wire)
        except (BrokenPipeError, ConnectionResetError):
            return seq
        seq += 1


class Image2dSourceDevice:
    """Device reading the frames of a source process (see the module docstring).

    Parameters
    ----------
    rig : Rig
        Cameras of the source.
    n_markers : int
        Markers per frame.
    rate_hz : float
        Frame rate.
    name : str
        Stream name.
    seed, noise_px, period
        As for :class:`SyntheticImage2d` (the source's frames).
    poll_s : float, optional
        None (default): each read waits in the kernel until bytes arrive
        (``poll``), waking at the byte. A number: non-blocking reads with sleeps of
        this many seconds in between (how a polling driver reads a port).
    start_timeout_s : float
        How long :meth:`start` waits for the source's first bytes.

    Attributes
    ----------
    truth_device : SyntheticImage2d
        The same frames' device, not started: ``truth_device.truth(seq)``.
    behind : LatencyStats
        Arrival stamp minus the source's write instant, per frame (transport and the
        reader's wake-up).
    """

    def __init__(
        self,
        rig: Rig,
        n_markers: int,
        rate_hz: float,
        *,
        name: str = "source",
        seed: int = 0,
        noise_px: float = 0.2,
        period: int = 600,
        poll_s: float | None = None,
        start_timeout_s: float = 30.0,
    ) -> None:
        self.rig = rig
        self.name = name
        self.stats = LinkStats()
        self.n_markers = int(n_markers)
        self.rate_hz = float(rate_hz)
        self.poll_s = poll_s
        self.start_timeout_s = float(start_timeout_s)
        self._args = {"seed": seed, "noise_px": noise_px, "period": period}
        self.truth_device = SyntheticImage2d(
            rig, n_markers, rate_hz, name=name, seed=seed, noise_px=noise_px, period=period
        )
        self._dtype = frame_dtype(len(rig), self.n_markers)
        self._size = self._dtype.itemsize
        self._buf = bytearray(self._size * 256)
        self._view = memoryview(self._buf)
        self._fill = 0
        self._sock: socket.socket | None = None
        self._proc: subprocess.Popen[bytes] | None = None
        self._poller: select.poll | None = None
        self._tmp: str | None = None
        self._taps: list[WireTap] = []
        self.behind = LatencyStats()

    @property
    def spec(self) -> StreamSpec:
        """Description of the stream (that of the in-process device of the same frames)."""
        return self.truth_device.spec

    def metadata(self) -> dict[str, Any]:
        """Family and stream description."""
        return self.truth_device.metadata()

    def add_tap(self, tap: WireTap) -> None:
        """Register a listener of link events (bytes are not passed on)."""
        self._taps.append(tap)

    def start(self) -> None:
        """Start the source process; return once its first bytes are readable.

        Raises
        ------
        DeviceError
            If the source does not write within ``start_timeout_s``.
        """
        if self._proc is not None:
            return
        self._tmp = tempfile.mkdtemp(prefix="spotlab-i2d-")
        rig_path = Path(self._tmp) / "rig.toml"
        self.rig.save(rig_path)
        ours, theirs = socket.socketpair()
        cmd = [
            sys.executable,
            "-m",
            "spotlab.testing.image2d_source",
            "--fd",
            str(theirs.fileno()),
            "--rig",
            str(rig_path),
            "--markers",
            str(self.n_markers),
            "--rate",
            repr(self.rate_hz),
            "--seed",
            str(self._args["seed"]),
            "--noise",
            repr(self._args["noise_px"]),
            "--period",
            str(self._args["period"]),
        ]
        self._proc = subprocess.Popen(cmd, pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL)
        theirs.close()
        self._sock = ours
        self._poller = select.poll()
        self._poller.register(ours, select.POLLIN)
        if not self._poller.poll(self.start_timeout_s * 1e3):
            self.close()
            raise DeviceError(f"{self.name}: the source wrote nothing in {self.start_timeout_s} s")
        if self.poll_s is not None:
            ours.setblocking(False)
        for tap in self._taps:
            tap.on_event(self.name, "started", {"pid": self._proc.pid}, time.monotonic_ns())

    def stop(self) -> None:
        """End the source process (the socket stays open until :meth:`close`)."""
        proc = self._proc
        if proc is not None and proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(5.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        for tap in self._taps:
            tap.on_event(self.name, "stopped", {}, time.monotonic_ns())

    def close(self) -> None:
        """Stop the source, close the socket, remove the rig file; safe to call twice."""
        self.stop()
        self._proc = None
        if self._sock is not None:
            self._sock.close()
            self._sock = None
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None

    def _read(self, timeout: float | None) -> int:
        """One read into the buffer after waiting up to ``timeout`` s; bytes read (0: none)."""
        sock, poller = self._sock, self._poller
        if sock is None or poller is None:
            raise DeviceError(f"{self.name}: recv before start")
        if self._fill == len(self._buf):  # the reader is 256 frames behind: grow
            self._buf.extend(bytes(len(self._buf)))
            self._view = memoryview(self._buf)
        if self.poll_s is None:
            if not poller.poll(None if timeout is None else timeout * 1e3):
                return 0
            n = sock.recv_into(self._view[self._fill :])
        else:
            deadline = None if timeout is None else time.monotonic() + timeout
            while True:
                try:
                    n = sock.recv_into(self._view[self._fill :])
                    break
                except BlockingIOError:
                    if deadline is not None and time.monotonic() >= deadline:
                        return 0
                    time.sleep(self.poll_s)
        if n == 0:
            raise DeviceError(f"{self.name}: the source closed the link")
        return n

    def recv(self, timeout: float | None = None) -> FrameBlock | None:
        """The frames completed by the next read, or None after ``timeout`` seconds.

        Raises
        ------
        DeviceError
            If the source went away or a frame does not start with the magic.
        """
        size = self._size
        n = self._read(timeout)
        if not n:
            return None
        arrival = time.monotonic_ns()
        self._fill += n
        count = self._fill // size
        if not count:
            return None
        used = count * size
        raw = np.frombuffer(self._buf, dtype=self._dtype, count=count)
        if not (raw["magic"] == MAGIC).all():
            raise DeviceError(f"{self.name}: frame without its magic: the stream is out of step")
        xy = raw["xy"].astype(np.float64)
        seq = raw["seq"].astype(np.int64)
        ticks = raw["ticks"].copy()
        for sent in raw["sent_ns"]:
            self.behind.add(arrival - int(sent))
        rest = self._fill - used
        if rest:
            self._buf[:rest] = self._buf[used : self._fill]
        self._fill = rest
        self.stats.frames += count
        return FrameBlock(
            seq=seq,
            ticks=ticks,
            arrival_ns=np.full(count, arrival, dtype=np.int64),
            data=xy,
            flags=np.isfinite(xy[..., 0]).astype(np.uint8),
            status=np.zeros(count, np.uint16),
        )


def main(argv: list[str] | None = None) -> int:
    """Entry of the source process: ``python -m spotlab.testing.image2d_source --fd N ...``."""
    parser = argparse.ArgumentParser(description="paced synthetic image2d frames to a socket")
    parser.add_argument("--fd", type=int, required=True, help="connected stream socket")
    parser.add_argument("--rig", required=True, help="rig TOML")
    parser.add_argument("--markers", type=int, required=True)
    parser.add_argument("--rate", type=float, required=True)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--noise", type=float, default=0.2)
    parser.add_argument("--period", type=int, default=600)
    parser.add_argument("--seconds", type=float, default=None)
    args = parser.parse_args(argv)
    sock = socket.socket(fileno=args.fd)
    try:
        serve(
            sock,
            Rig.load(args.rig),
            args.markers,
            args.rate,
            seed=args.seed,
            noise_px=args.noise,
            period=args.period,
            seconds=args.seconds,
        )
    except KeyboardInterrupt:
        pass
    finally:
        sock.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
