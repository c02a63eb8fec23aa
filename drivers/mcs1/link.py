"""A serial link: pyserial's ``serial_for_url`` with clear errors and arrival stamps.

Any pyserial URL works: a device path (``/dev/ttyUSB0``, a pseudo-terminal),
``socket://host:port``, ``spy://...``, and ``sim://...`` (the simulator's handler,
which pyserial imports by name the first time such a URL is opened).
Every chunk read is stamped with ``time.monotonic_ns()`` as the read returns and
handed to ``on_rx``; every write to ``on_tx`` (the driver's wire taps).

Errors name the cause: a missing port is :class:`DeviceNotFound`, a permission
problem says how to fix it (udev rules, ``dialout`` group), and a port that goes
away while in use is :class:`DeviceDisconnected`.
"""

from __future__ import annotations

import array
import errno
import fcntl
import os
import termios
import time
from collections.abc import Callable

import serial

from spotlab.core.errors import (
    ConfigurationError,
    DeviceDisconnected,
    DeviceError,
    DeviceNotFound,
)

ByteTap = Callable[[bytes, int], None]

#: Longest wait of one read when the caller does not bound it (s); keeps callers responsive.
MAX_POLL = 0.1
#: A reply line longer than this without CR is not a reply.
MAX_LINE = 1024

_NOT_FOUND = {errno.ENOENT, errno.ENXIO, errno.ENODEV, errno.ECONNREFUSED, errno.EHOSTUNREACH}
_DENIED = {errno.EACCES, errno.EPERM}
_BUSY = {errno.EBUSY, errno.EAGAIN, errno.EWOULDBLOCK}


def _errno_of(exc: BaseException) -> int | None:
    code = getattr(exc, "errno", None)
    if isinstance(code, int):
        return code
    cause = exc.__cause__ or exc.__context__
    if cause is not None and cause is not exc:
        return _errno_of(cause)
    for code in _NOT_FOUND | _DENIED | _BUSY:
        if f"[Errno {code}]" in str(exc):
            return code
    return None


def open_error(url: str, exc: BaseException) -> DeviceError | ConfigurationError:
    """The spotlab error that explains why ``url`` could not be opened."""
    code = _errno_of(exc)
    if isinstance(exc, ValueError) and "://" in url:
        scheme = url.split("://", 1)[0]
        return ConfigurationError(
            f"cannot open {url!r}: pyserial has no handler for '{scheme}://' URLs"
            + (
                " (the simulators' package, spotlab.simulators, serves sim://)"
                if scheme == "sim"
                else ""
            )
        )
    if code in _NOT_FOUND:
        return DeviceNotFound(
            f"no device at {url}: {exc}. Check that it is plugged in and the path is right "
            "(`spotlab devices` lists the ports found)"
        )
    if code in _DENIED:
        return DeviceError(
            f"permission denied opening {url}: add your user to the 'dialout' group "
            "(then log in again) or install spotlab's udev rules "
            "(udev/*.rules, `udevadm control --reload-rules && udevadm trigger`)"
        )
    if code in _BUSY:
        return DeviceError(f"{url} is in use by another program: {exc}")
    return DeviceError(f"cannot open {url}: {exc}")


#: Where pyserial finds the ``sim://`` handler (``protocol_sim``): imported by pyserial
#: only when such a URL is opened, so production code never imports the simulators.
SIM_HANDLERS = "spotlab.simulators.transports"


def _register_simulators() -> None:
    """Let pyserial find the simulator's ``sim://`` handler (on demand, by name)."""
    if SIM_HANDLERS not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append(SIM_HANDLERS)


class SerialLink:
    """One serial port or pyserial URL.

    Parameters
    ----------
    url : str or path-like
        Device path or pyserial URL.
    on_rx, on_tx : callable, optional
        ``f(data, t_ns)`` called for every chunk read (with its arrival stamp)
        and every chunk written (stamped just before the write).
    """

    def __init__(
        self,
        url: str | os.PathLike[str],
        *,
        on_rx: ByteTap | None = None,
        on_tx: ByteTap | None = None,
    ) -> None:
        self.url = os.fspath(url)
        self.on_rx = on_rx
        self.on_tx = on_tx
        # One pyserial object for the link's life, opened and closed as needed: some
        # handlers keep state in it (a sim:// port keeps its simulated device).
        self._port_obj: serial.SerialBase | None = None
        self._ser: serial.SerialBase | None = None  # the port object while open
        self._timeout: float | None = -1.0

    @property
    def is_open(self) -> bool:
        """Whether the port is open."""
        return self._ser is not None

    @property
    def baud(self) -> int:
        """Current baud rate of the host side."""
        return int(self._port().baudrate)

    def open(self, baud: int = 9_600) -> None:
        """Open the port at ``baud``, 8N1, no flow control.

        Raises
        ------
        DeviceNotFound
            If the port does not exist (the message names it).
        DeviceError
            If access is denied (the message says how to get it) or the port is busy.
        ConfigurationError
            If the URL's scheme has no pyserial handler.
        """
        if self._ser is not None:
            return
        try:
            if self._port_obj is None:
                if self.url.startswith("sim://"):
                    _register_simulators()
                ser = serial.serial_for_url(self.url, do_not_open=True)
                ser.write_timeout = 2.0
                if "://" not in self.url:
                    ser.exclusive = True  # two programs on one port garble both sessions
                self._port_obj = ser
            ser = self._port_obj
            ser.baudrate = baud
            ser.timeout = 0
            ser.open()
        except (serial.SerialException, OSError, ValueError) as exc:
            raise open_error(self.url, exc) from exc
        self._ser = ser
        self._timeout = 0

    def close(self) -> None:
        """Close the port; safe to call when closed or after the port went away."""
        ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.close()
            except (serial.SerialException, OSError):
                pass

    def reopen(self, baud: int = 9_600) -> None:
        """Close and open again (after a disconnection)."""
        self.close()
        self.open(baud)

    def _port(self) -> serial.SerialBase:
        if self._ser is None:
            raise DeviceDisconnected(f"{self.url} is not open")
        return self._ser

    def _lost(self, what: str, exc: BaseException) -> DeviceDisconnected:
        return DeviceDisconnected(f"{self.url} went away during {what}: {exc}")

    def _set_timeout(self, ser: serial.SerialBase, timeout: float) -> None:
        # Changing pyserial's timeout reconfigures the port: only do it on change.
        if timeout != self._timeout:
            ser.timeout = timeout
            self._timeout = timeout

    def read(self, timeout: float | None) -> tuple[bytes, int]:
        """Whatever the port has, waiting up to ``timeout`` s for the first byte.

        Parameters
        ----------
        timeout : float or None
            Longest wait in seconds; ``None`` waits at most :data:`MAX_POLL`.

        Returns
        -------
        data : bytes
            The bytes read, empty on timeout.
        t_ns : int
            ``time.monotonic_ns()`` when the read returned.

        Raises
        ------
        DeviceDisconnected
            If the port went away.
        """
        ser = self._port()
        wait = MAX_POLL if timeout is None else round(max(0.0, min(timeout, MAX_POLL * 10)), 3)
        try:
            waiting = _bytes_waiting(ser)
            if not waiting:
                self._set_timeout(ser, wait)
                data = ser.read(1)
                waiting = _bytes_waiting(ser) if data else 0
                if waiting:
                    data += ser.read(waiting)
            else:
                data = ser.read(waiting)
        except (serial.SerialException, OSError) as exc:
            raise self._lost("a read", exc) from exc
        t_ns = time.monotonic_ns()
        if data and self.on_rx is not None:
            self.on_rx(data, t_ns)
        return data, t_ns

    def read_line(self, deadline: float) -> tuple[bytes, int]:
        """One line up to and including CR, read byte by byte (nothing after it is read).

        Parameters
        ----------
        deadline : float
            ``time.monotonic()`` value after which to give up.

        Returns
        -------
        line : bytes
            The line with its CR; without CR when the deadline passed (possibly empty)
            or after :data:`MAX_LINE` bytes.
        t_ns : int
            Arrival stamp of the last byte.
        """
        ser = self._port()
        line = bytearray()
        t_ns = time.monotonic_ns()
        try:
            while len(line) < MAX_LINE:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    break
                self._set_timeout(ser, round(remaining, 3))
                byte = ser.read(1)
                t_ns = time.monotonic_ns()
                if byte:
                    line += byte
                    if byte == b"\r":
                        break
        except (serial.SerialException, OSError) as exc:
            raise self._lost("a read", exc) from exc
        data = bytes(line)
        if data and self.on_rx is not None:
            self.on_rx(data, t_ns)
        return data, t_ns

    def write(self, data: bytes) -> int:
        """Write ``data`` and wait until it has left the host; return the send stamp (ns).

        Raises
        ------
        DeviceDisconnected
            If the port went away.
        """
        ser = self._port()
        t_ns = time.monotonic_ns()
        if self.on_tx is not None:
            self.on_tx(data, t_ns)
        try:
            ser.write(data)
            ser.flush()
        except (serial.SerialException, OSError) as exc:
            raise self._lost("a write", exc) from exc
        return t_ns

    def send_break(self, duration: float = 0.25) -> bool:
        """Send a serial BREAK; ``False`` when the transport cannot (it is then a no-op).

        Raises
        ------
        DeviceDisconnected
            If the port went away.
        """
        ser = self._port()
        try:
            ser.send_break(duration)
        except (NotImplementedError, AttributeError):
            return False
        except (serial.SerialException, OSError) as exc:
            if _errno_of(exc) in (errno.ENOTTY, errno.EINVAL):
                return False
            raise self._lost("a BREAK", exc) from exc
        return True

    def set_baud(self, baud: int) -> None:
        """Change the host side's baud rate.

        Raises
        ------
        ConfigurationError
            If the port or adapter refuses the rate.
        DeviceDisconnected
            If the port went away.
        """
        ser = self._port()
        try:
            ser.baudrate = baud
        except ValueError as exc:
            raise ConfigurationError(f"{self.url} does not support {baud} baud: {exc}") from exc
        except (serial.SerialException, OSError) as exc:
            raise self._lost("a baud-rate change", exc) from exc


def _bytes_waiting(ser: serial.SerialBase) -> int:
    """Bytes ready to read without blocking.

    pyserial's ``socket://`` answers ``in_waiting`` with 0 or 1 (it only asks
    ``select``), which would make every read of a TCP link return one byte; ask
    the socket itself how much it holds.
    """
    sock = getattr(ser, "_socket", None)
    if sock is not None:
        count = array.array("i", [0])
        try:
            fcntl.ioctl(sock.fileno(), termios.FIONREAD, count)
        except OSError:
            return int(ser.in_waiting)
        return max(int(count[0]), int(ser.in_waiting))
    return int(ser.in_waiting)
