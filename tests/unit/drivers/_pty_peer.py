"""A tiny scripted SPX device on the master side of a real pseudo-terminal.

It answers commands as selspot.md says (banner, OKAY, VER reply, data frames
after ``START:``, the STOP reply in an event frame), and lets a test override
any verb's answer, stay silent, reset itself, or pull the cable. The driver
opens ``peer.path`` — a symlink to the pty, like ``/dev/serial/by-id/...`` —
so a "returned" device can be a new pty behind the same path.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import select
import threading
import time
import tty
from collections.abc import Callable
from pathlib import Path

from _spx_wire import SpxStream, event_frame, line

BANNER = b"RESET7DB2\r"
Answer = bytes | None | Callable[[str], bytes | None]


class SpxPeer:
    """Scripted SPX device. Use as a context manager; ``close()`` joins the thread.

    Parameters
    ----------
    folder : Path
        Where to put the ``port`` symlink.
    answers : dict
        Per verb (``"START"``), the bytes to send instead of the normal answer,
        ``None`` for no answer, or a callable ``f(args) -> bytes | None``.
    silent : bool
        Answer nothing at all (a device that is off).
    version : str
        ``VER:0`` reply text.
    rate_hz : float
        Data frame rate while streaming (the peer does not follow ``RATE``).
    """

    def __init__(
        self,
        folder: Path,
        *,
        answers: dict[str, Answer] | None = None,
        silent: bool = False,
        version: str = "SPX 1.0 TEST0001 4 128",
        rate_hz: float = 200.0,
    ) -> None:
        self.path = str(folder / "port")
        self.answers = dict(answers or {})
        self.silent = silent
        self.version = version
        self.period = 1.0 / rate_hz
        self.commands: list[bytes] = []
        self.streaming = False
        self.frames_sent = 0
        self.cams, self.leds, self.slot = 1, 8, 100
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._master = -1
        self._slave = -1
        self._connected = False
        self._stream: SpxStream | None = None
        self._next_frame = 0.0
        self._seq = 0
        self._plug()
        self._thread = threading.Thread(target=self._run, name="spx-peer", daemon=True)
        self._thread.start()

    # -- test controls -------------------------------------------------------------
    def __enter__(self) -> SpxPeer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)
        with self._lock:
            self._unplug()

    def write(self, data: bytes) -> None:
        """Send raw bytes to the host now."""
        with self._lock:
            self._send(data)

    def reset_itself(self) -> None:
        """A spontaneous reset: stop streaming, send the banner (selspot.md §7)."""
        with self._lock:
            self.streaming = False
            self._send(BANNER)

    def go_quiet(self) -> None:
        """Stop streaming without a word."""
        with self._lock:
            self.streaming = False

    def pull_cable(self) -> None:
        """The port disappears (the host's reads fail, the path is gone)."""
        with self._lock:
            self.streaming = False
            self._unplug()

    def plug_back(self) -> None:
        """A port reappears at the same path (a new pty), device in its reset state."""
        with self._lock:
            self._plug()

    def sent_commands(self) -> list[str]:
        """Commands received so far, as ``VERB:ARGS`` without CRC."""
        return [c[:-4].decode() if b":" in c else c.decode() for c in self.commands]

    # -- internals -------------------------------------------------------------------
    def _plug(self) -> None:
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        flags = fcntl.fcntl(self._master, fcntl.F_GETFL)
        fcntl.fcntl(self._master, fcntl.F_SETFL, flags | os.O_NONBLOCK)
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.path)
        os.symlink(os.ttyname(self._slave), self.path)
        self._buf = b""
        self._connected = True

    def _unplug(self) -> None:
        if not self._connected:
            return
        self._connected = False
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.path)
        os.close(self._master)
        os.close(self._slave)

    def _send(self, data: bytes) -> None:
        if not self._connected:
            return
        with contextlib.suppress(BlockingIOError):  # host not reading: bytes lost, as on a wire
            os.write(self._master, data)

    def _run(self) -> None:
        while not self._stop.is_set():
            with self._lock:
                master = self._master if self._connected else -1
            if master < 0:
                time.sleep(0.005)
                continue
            try:
                ready, _, _ = select.select([master], [], [], 0.002)
            except (OSError, ValueError):
                continue
            with self._lock:
                if not self._connected or master != self._master:
                    continue
                if ready:
                    try:
                        data = os.read(master, 4096)
                    except OSError as exc:
                        if exc.errno not in (errno.EIO, errno.EAGAIN):
                            raise
                        data = b""
                    self._buf += data
                    while b"\r" in self._buf:
                        cmd, self._buf = self._buf.split(b"\r", 1)
                        self._handle(cmd)
                self._tick()

    def _tick(self) -> None:
        now = time.monotonic()
        if not self.streaming or now < self._next_frame or self._stream is None:
            return
        self._next_frame += self.period
        i = self.frames_sent
        self._send(self._stream.append(i, seq=self._seq))
        self._seq = (self._seq + 1) & 0xFFFF
        self.frames_sent += 1

    def _handle(self, raw: bytes) -> None:
        if not raw:
            return
        self.commands.append(raw)
        if self.silent:
            return
        text = raw.decode(errors="replace")
        verb, _, args = text[:-4].partition(":") if ":" in text else (text, "", "")
        if verb in self.answers:
            answer = self.answers[verb]
            reply = answer(args) if callable(answer) else answer
            if reply is not None:
                self._send(reply)
            return
        if verb == "RESET":
            self.streaming = False
            self._send(BANNER)
        elif verb == "VER":
            self._send(line(self.version))
        elif verb == "START":
            self._send(line("OKAY"))
            self._stream = SpxStream(n_leds=self.leds, n_cams=self.cams, slot_us=self.slot)
            self._seq = 0
            self.frames_sent = 0
            self.streaming = True
            self._next_frame = time.monotonic()
        elif verb == "STOP":
            self.streaming = False
            self._send(event_frame("OKAY"))
        else:
            if verb == "CAMS":
                self.cams = int(args)
            elif verb == "LEDT":
                self.leds = len(args) // 4
            elif verb == "SLOT":
                self.slot = int(args)
            self._send(line("OKAY"))
