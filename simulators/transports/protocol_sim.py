"""pyserial URL handler for in-process simulated devices: ``sim://selspot?...``.

Once ``"spotlab.simulators.transports"`` is in ``serial.protocol_handler_packages``
(``import spotlab.simulators`` puts it there), ``serial.serial_for_url(url)``
returns a port wired to a :class:`Mcs1Device`, e.g.::

    sim://selspot?cameras=4&leds=32&rate=200&seed=1&faults=bitflip@1.5&truth=/tmp/t.csv

Options: see :func:`spotlab.simulators.service.options_from_url`; ``sim://timer?...``
takes the fields of :class:`~spotlab.simulators.service.TimerSimOptions`.

The port behaves like a real one: the device is driven by the world clock
(reads sleep until the device's next byte or frame, never spin), bytes arrive
no faster than the baud rate, and a port whose ``baudrate`` differs from the
device's reads garbage and writes garbage. A BREAK resets the device. During
a disconnect fault reads and writes raise :class:`serial.SerialException`; the
handle stays dead until ``close()`` and ``open()`` again once the device is back.
The device lives as long as this port object: closing and reopening keeps it.
It is switched on 100 ms before the port first opens, and whatever it sends
while the port is closed is lost, so a freshly opened port holds no stale
bytes (send ``RESET:`` or a BREAK to see the banner).

The device runs in the reading thread. When it cannot keep up with the world clock
(a host too busy to render its frames in real time), it catches up
:data:`CATCH_UP_NS` at a time and its clock runs slow, as the pseudo-terminal server's
does: a read returns what those steps sent instead of rendering, ever later, every frame
due since the last read.
"""

from __future__ import annotations

import bisect
import time

import numpy as np
from serial.serialutil import PortNotOpenError, SerialBase, SerialException

from spotlab.simulators.line import garble
from spotlab.simulators.mcs1_device import Mcs1Device
from spotlab.simulators.service import POWER_UP_LEAD_NS, device_from_url

MIN_WAIT_NS = 1_000_000
MAX_WAIT_NS = 50_000_000
#: Bytes reach the host in batches on these boundaries, as a USB-serial adapter
#: hands them over once per 1 ms USB frame (FTDI latency timer set to 1 ms by our
#: udev rules). Without it every read would return the few bytes sent since the last.
USB_FRAME_NS = 1_000_000
#: Device time one read may render when the device has fallen behind the world clock.
CATCH_UP_NS = 10_000_000


class Serial(SerialBase):
    """A simulated serial port (pyserial ``SerialBase`` subclass)."""

    is_open: bool

    def __init__(self, *args: object, **kwargs: object) -> None:
        self.device: Mcs1Device | None = None
        self._rx = bytearray()
        self._bauds: list[tuple[int, int]] = []
        self._opened_ns = 0
        self._clock_ns = 0  # the device's time as this port last drove it
        self._dead = False
        self._rng = np.random.default_rng(0x5E41)
        super().__init__(*args, **kwargs)

    # -- pyserial hooks ------------------------------------------------------
    def open(self) -> None:
        """Open the port (building the device on first open)."""
        if self._port is None:
            raise SerialException("Port must be configured before it can be used.")
        if self.is_open:
            raise SerialException("Port is already open.")
        now = time.monotonic_ns()
        if self.device is None:
            try:
                self.device = device_from_url(self.portstr, now_ns=now - POWER_UP_LEAD_NS)
            except ValueError as exc:
                raise SerialException(f"could not open port {self.portstr!r}: {exc}") from exc
        if self.device.link_down(now):
            raise SerialException(f"could not open port {self.portstr!r}: device disconnected")
        self.device.output(now)  # sent while the port was closed: nobody listened
        self._opened_ns = self._clock_ns = now
        self._dead = False
        self._bauds = [(now, int(self._baudrate))]
        self.is_open = True

    def close(self) -> None:
        """Close the port; the simulated device keeps running (its files are flushed)."""
        if self.is_open and self.device is not None:
            self.device.flush(self._clock_ns)
        self.is_open = False
        self._rx.clear()

    def __del__(self) -> None:
        # The device's files get their last rows, without simulating the time since.
        device = getattr(self, "device", None)
        if device is not None:
            try:
                device.close(catch_up=False)
            except Exception:  # noqa: S110 - never raise from a finaliser
                pass

    def _reconfigure_port(self) -> None:
        if self.is_open:
            self._bauds.append((self._now(), int(self._baudrate)))
            del self._bauds[:-64]

    def _update_break_state(self) -> None:
        if self._break_state and self.device is not None:
            now = self._now()
            self._check_link(now)
            self.device.send_break(now)

    def _update_rts_state(self) -> None:
        pass

    def _update_dtr_state(self) -> None:
        pass

    @property
    def cts(self) -> bool:
        return True

    @property
    def dsr(self) -> bool:
        return True

    @property
    def ri(self) -> bool:
        return False

    @property
    def cd(self) -> bool:
        return True

    # -- data ----------------------------------------------------------------
    def _now(self) -> int:
        """The device's time: the world clock's, unless the device has fallen behind it
        with work due (then one :data:`CATCH_UP_NS` step further)."""
        real = time.monotonic_ns()
        clock = self._clock_ns
        if self.device is not None and clock and real - clock > CATCH_UP_NS:
            due = self.device.next_event_ns()
            if due is not None and due < real:
                self._clock_ns = clock + CATCH_UP_NS
                return self._clock_ns
        self._clock_ns = max(clock, real)
        return self._clock_ns

    def _check_link(self, now: int) -> Mcs1Device:
        if not self.is_open or self.device is None:
            raise PortNotOpenError()
        if not self._dead and self.device.link_broken_between(self._opened_ns, now):
            self._dead = True
        if self._dead:
            raise SerialException(
                "device reports readiness to read but returned no data (device disconnected)"
            )
        return self.device

    def _baud_at(self, t_ns: int) -> int:
        i = bisect.bisect_right(self._bauds, (t_ns, 1 << 62)) - 1
        return self._bauds[max(i, 0)][1]

    def _pull(self) -> None:
        now = self._now()
        device = self._check_link(now)
        for seg in device.output_segments(now - now % USB_FRAME_NS):
            rx_baud = self._baud_at(seg.end_ns)
            self._rx += (
                seg.data if rx_baud == seg.baud else garble(seg.data, seg.baud, rx_baud, self._rng)
            )

    @property
    def in_waiting(self) -> int:
        """Bytes received and not yet read."""
        self._pull()
        return len(self._rx)

    def read(self, size: int = 1) -> bytes:
        """Up to ``size`` bytes, waiting at most ``timeout`` s (None: until there are enough)."""
        deadline = (
            None if self._timeout is None else time.monotonic_ns() + round(self._timeout * 1e9)
        )
        while True:
            self._pull()
            if len(self._rx) >= size:
                break
            now = time.monotonic_ns()
            if deadline is not None and now >= deadline:
                break
            assert self.device is not None
            nxt = self.device.next_event_ns()
            wait = MAX_WAIT_NS if nxt is None else min(max(nxt - now, MIN_WAIT_NS), MAX_WAIT_NS)
            if deadline is not None:
                wait = min(wait, deadline - now)
            time.sleep(wait / 1e9)
        data = bytes(self._rx[:size])
        del self._rx[:size]
        return data

    def write(self, data: bytes | bytearray | memoryview) -> int:
        """Send bytes to the device at the port's baud rate."""
        now = self._now()
        device = self._check_link(now)
        payload = bytes(data)
        device.receive(payload, now, line_baud=int(self._baudrate))
        return len(payload)

    def flush(self) -> None:
        """Wait until every written byte has reached the device."""
        if self.device is not None and self.is_open:
            wait = self.device.host_bytes_done_ns() - self._now()
            if wait > 0:
                time.sleep(wait / 1e9)

    def reset_input_buffer(self) -> None:
        """Throw away what was received and not read."""
        self._pull()
        self._rx.clear()

    def reset_output_buffer(self) -> None:
        """Nothing waits in an output buffer: written bytes are already on their way."""
        self._check_link(time.monotonic_ns())
