"""A WSX hub (docs/protocols/wsx.md) as a spotlab device, through pyusb.

The driver finds the hub by VID:PID and serial number, claims interface 0, reads
its information and set-up, sends the set-up it is asked for (a refused one is an
error naming the device's reason), reads every position sensor's factory
calibration into the stream's metadata, starts a collection and reads frames from
the bulk endpoint (events from the interrupt endpoint now and then), journalling
every transfer as it arrived. Faults are counted in :attr:`WsxDriver.usb_faults`
and journalled as link events: a stall is cleared (``clear_halt``) and reading
goes on; a timeout (no frame for a while) and an overflow (babble) are counted; an
unplugged hub is looked for by serial number until it returns, then configured
and started again.

``port`` is ``wsxsim://HOST:PORT/SERIAL`` (a simulator in another process, over
:class:`~spotlab.drivers.wsx.link.SocketBackend`), or ``usb``, ``usb:SERIAL`` or
``SERIAL`` for hardware through libusb (the ``libusb-package`` wheel, else the
system's libusb).
"""

from __future__ import annotations

import errno
import os
import time
from dataclasses import replace
from typing import Any

import usb.core
import usb.util

from spotlab.core.errors import ConfigurationError, DeviceDisconnected, DeviceError, DeviceNotFound
from spotlab.core.frames import FrameBlock
from spotlab.core.streams import StreamSpec
from spotlab.drivers.base import DeviceInfo, Driver
from spotlab.drivers.wsx import usbio
from spotlab.drivers.wsx.decoding import LAYOUT, UNITS, VALUES, WsxDecoder
from spotlab.drivers.wsx.protocol import (
    CALIBRATION,
    CCDS,
    EP_EVENTS,
    EP_FRAMES,
    GET_SETUP,
    INFO,
    NO_INTERPOLATION,
    SET_SETUP,
    START,
    STATUS,
    STOP,
    Info,
    Setup,
    Status,
    error_text,
    parse_calibration,
)

READ_BYTES = 1 << 16
EVENT_POLL_S = 0.25
FAULT_KINDS = ("stalls", "timeouts", "short", "babble", "unplugs", "refused")


class WsxDriver(Driver):
    """A WSX hub's CCD readings as a ``linear1d`` stream.

    Parameters
    ----------
    port : str
        ``wsxsim://HOST:PORT/SERIAL``, ``usb``, ``usb:SERIAL`` or ``SERIAL``.
    name : str, optional
        Stream name (default ``"wsx"``).
    rate_hz, marker_rate_hz : float, optional
        Frame and marker rates (default: what the hub has).
    markers : int, optional
        Markers N (default: the hub's); all on strober port 1 unless ``ports``.
    ports : str, optional
        Markers per strober port, ``8+8+8``.
    duty, threshold, gain, voltage_dv : optional
        Duty cycle (0.10-0.85), threshold (1-255), gain (1-1000), LED voltage (0.1 V).
    raw : bool
        Set ``NO_INTERPOLATION``: reconstruction takes each marker at its firing instant.
    read_timeout : float
        Seconds one bulk read waits.
    silence_timeout : float
        Seconds without a frame that count as one timeout fault.
    reconnect_timeout : float, optional
        Seconds an unplugged hub may stay away before ``recv`` raises (default: forever).
    """

    family = "wsx"

    def __init__(
        self,
        port: str | os.PathLike[str],
        *,
        name: str | None = None,
        rate_hz: float | None = None,
        markers: int | None = None,
        marker_rate_hz: float | None = None,
        ports: str | None = None,
        duty: float | None = None,
        threshold: int | None = None,
        gain: int | None = None,
        voltage_dv: int | None = None,
        raw: bool = False,
        read_timeout: float = 0.1,
        silence_timeout: float = 0.5,
        reconnect_timeout: float | None = None,
    ) -> None:
        super().__init__(port, name=name)
        self.target = usbio.parse_port(self.port)
        self.want = {
            "rate_hz": rate_hz, "markers": markers, "marker_rate_hz": marker_rate_hz,
            "ports": usbio.parse_ports(ports), "duty": duty, "threshold": threshold,
            "gain": gain, "voltage_dv": voltage_dv,
        }  # fmt: skip
        self.raw = bool(raw)
        self.read_timeout, self.silence_timeout = read_timeout, silence_timeout
        self.reconnect_timeout = reconnect_timeout
        self.usb_faults = dict.fromkeys(FAULT_KINDS, 0)
        self.dev: Any = None
        self.serial = ""
        self.info: Info | None = None
        self.setup: Setup | None = None
        self.calibration: list[dict[str, Any]] = []
        self._decoder: WsxDecoder | None = None
        self._spec: StreamSpec | None = None
        self._last_frame = 0.0
        self._silent = False
        self._last_events = 0.0

    # -- description ------------------------------------------------------------------
    @property
    def spec(self) -> StreamSpec:
        if self._spec is None:
            raise DeviceError(f"{self.name}: the WSX stream is known only after start()")
        return self._spec

    def metadata(self) -> dict[str, Any]:
        """Spec (set-up and factory calibration in its metadata), layout and decoder."""
        return {
            **super().metadata(),
            "layout": LAYOUT,
            "decoder": "spotlab.drivers.wsx:decoder_from_metadata",
            "serial": self.serial,
        }

    @classmethod
    def detect(cls) -> list[DeviceInfo]:
        """WSX hubs on this machine's USB (libusb), by VID:PID."""
        return usbio.detect(cls.family)

    # -- bring-up ---------------------------------------------------------------------
    def _start(self) -> None:
        self.dev, self.serial = usbio.open_hub(self.target, self.name)
        self._tap_event("open", port=self.port, serial=self.serial)
        self.info = Info.decode(self._ctrl_in(INFO, 16))
        current = Setup.decode(self._ctrl_in(GET_SETUP, 32))
        self.setup = self._configure(self._wanted(current))
        self.calibration = [
            ccd
            for s in range(self.info.sensors)
            for ccd in parse_calibration(self._ctrl_in(CALIBRATION, 188, index=s), s)
        ]
        self._decoder = WsxDecoder(self.setup.markers, self.info.sensors, self.stats)
        self._spec = self._make_spec()
        self._begin()

    def _begin(self) -> None:
        self._ctrl_out(START)
        self._last_frame = self._last_events = time.monotonic()
        self._silent = False
        self._tap_event("started", rate_hz=self.spec.rate_hz)

    def _wanted(self, current: Setup) -> Setup:
        w = self.want
        n = current.markers if w["markers"] is None else int(w["markers"])
        ports = w["ports"] or ((n, 0, 0, 0) if n != current.markers else current.ports)
        if w["markers"] is None and w["ports"]:
            n = sum(ports)
        mrate = current.marker_rate_mhz
        if w["marker_rate_hz"] is not None:
            mrate = round(float(w["marker_rate_hz"]) * 1000)
        frate = current.frame_rate_mhz
        if w["rate_hz"] is not None:
            frate = round(float(w["rate_hz"]) * 1000)
        elif frate * (n + 2) > mrate:
            frate = mrate // (n + 2)
        flags = (current.flags & ~NO_INTERPOLATION) | (NO_INTERPOLATION if self.raw else 0)
        return replace(
            current, markers=n, ports=ports, marker_rate_mhz=mrate, frame_rate_mhz=frate,
            duty_permille=current.duty_permille if w["duty"] is None else round(1000 * w["duty"]),
            threshold=current.threshold if w["threshold"] is None else int(w["threshold"]),
            gain=current.gain if w["gain"] is None else int(w["gain"]),
            voltage_dv=current.voltage_dv if w["voltage_dv"] is None else int(w["voltage_dv"]),
            flags=flags,
        )  # fmt: skip

    def _configure(self, setup: Setup) -> Setup:
        """Send ``setup``; a stall is the device refusing it: raise with its reason."""
        try:
            self._tap_tx(setup.encode(), time.monotonic_ns())
            self.dev.ctrl_transfer(0x40, SET_SETUP, 0, 0, setup.encode(), 1000)
        except usb.core.USBError as exc:
            if exc.errno != errno.EPIPE:
                raise DeviceError(f"{self.name}: set-up not sent to {self.port}: {exc}") from exc
            self.usb_faults["refused"] += 1
            status = Status.decode(self._ctrl_in(STATUS, 16))
            self._tap_event("error", fault="refused", code=status.last_error)
            raise ConfigurationError(
                f"{self.name}: the WSX hub {self.serial} refused the set-up "
                f"({setup.markers} markers at {setup.rate_hz:g} Hz, marker rate "
                f"{setup.marker_rate_hz:g} Hz): error {error_text(status.last_error)}"
            ) from None
        got = Setup.decode(self._ctrl_in(GET_SETUP, 32))
        self._tap_event("configured", **got.to_dict())
        return got

    def _make_spec(self) -> StreamSpec:
        assert self.setup is not None and self.info is not None
        s = self.setup
        return StreamSpec(
            name=self.name, kind="linear1d", n_sensors=self.info.sensors * CCDS,
            n_markers=s.markers, rate_hz=s.rate_hz, tick_hz=float(self.info.clock_hz),
            slot_period_s=1.0 / s.marker_rate_hz, values=VALUES, units=UNITS,
            metadata={
                "setup": s.to_dict(), "calibration": self.calibration,
                "info": {**self.info.__dict__}, "position_sensors": self.info.sensors,
                "interpolate": not (s.flags & NO_INTERPOLATION),
            },
        )  # fmt: skip

    def _ctrl_in(self, request: int, length: int, index: int = 0) -> bytes:
        return bytes(self.dev.ctrl_transfer(0xC0, request, 0, index, length, 1000))

    def _ctrl_out(self, request: int) -> None:
        self.dev.ctrl_transfer(0x40, request, 0, 0, None, 1000)

    # -- streaming --------------------------------------------------------------------
    def _recv_internal(self, timeout: float | None) -> FrameBlock | None:
        if self.dev is None or self._decoder is None:
            raise DeviceError(f"{self.name} ({self.port}) is not streaming: call start() first")
        wait = self.read_timeout if timeout is None else min(timeout, self.read_timeout)
        try:
            self._poll_events()
            data = bytes(self.dev.read(EP_FRAMES, READ_BYTES, max(1, round(wait * 1000))))
        except usb.core.USBTimeoutError:
            self._check_silence()
            return None
        except usb.core.USBError as exc:
            self._fault(exc)
            return None
        t_ns = time.monotonic_ns()
        self._last_frame = time.monotonic()
        self._silent = False
        self.stats.bytes += len(data)
        if len(data) % self._decoder.size:
            self.usb_faults["short"] += 1
            self._tap_event("error", fault="short", bytes=len(data))
        self._tap_rx(data, t_ns)
        return self._decoder.feed(data, t_ns)

    def _poll_events(self) -> None:
        now = time.monotonic()
        if now - self._last_events < EVENT_POLL_S:
            return
        self._last_events = now
        try:
            data = bytes(self.dev.read(EP_EVENTS, 16, 1))
        except usb.core.USBTimeoutError:
            return
        self._tap_rx(data, time.monotonic_ns())
        assert self._decoder is not None
        self._decoder.feed(data, time.monotonic_ns())

    def _check_silence(self) -> None:
        limit = max(self.silence_timeout, 3.0 / self.spec.rate_hz)
        if not self._silent and time.monotonic() - self._last_frame > limit:
            self._silent = True
            self.usb_faults["timeouts"] += 1
            self._tap_event("error", fault="timeout", seconds=self.silence_timeout)

    def _fault(self, exc: usb.core.USBError) -> None:
        if exc.errno == errno.EPIPE:
            self.usb_faults["stalls"] += 1
            self._tap_event("error", fault="stall", endpoint=EP_FRAMES)
            try:
                self.dev.clear_halt(EP_FRAMES)
            except usb.core.USBError as again:
                if again.errno != errno.ENODEV:
                    raise DeviceError(f"{self.name}: cannot clear the stall: {again}") from again
                self._unplugged()
            return
        if exc.errno == errno.EOVERFLOW:
            self.usb_faults["babble"] += 1
            self._tap_event("error", fault="babble")
            return
        if exc.errno in (errno.ENODEV, errno.EIO, errno.ENOENT):
            self._unplugged()
            return
        raise DeviceError(f"{self.name}: USB error on {self.port}: {exc}") from exc

    def _unplugged(self) -> None:
        """The hub is gone: wait for it (by serial), configure and start it again."""
        assert self._decoder is not None and self.setup is not None
        self.usb_faults["unplugs"] += 1
        self._tap_event("disconnected", reason="the WSX hub was unplugged (ENODEV)")
        self._decoder.mark_discontinuity()
        usbio.release(self.dev)
        self.dev = None
        since = time.monotonic()
        target = replace(self.target, serial=self.serial)
        while True:
            if (
                self.reconnect_timeout is not None
                and time.monotonic() - since > self.reconnect_timeout
            ):
                raise DeviceDisconnected(
                    f"{self.name}: the WSX hub {self.serial} has been away for "
                    f"{time.monotonic() - since:.1f} s"
                )
            try:
                self.dev, _ = usbio.open_hub(target, self.name)
                self._configure(self.setup)
                self._begin()
                break
            except (DeviceNotFound, usb.core.USBError):
                usbio.release(self.dev)
                self.dev = None
                time.sleep(0.1)
        self.stats.reconnects += 1
        self._tap_event("reconnected", port=self.port, address=int(self.dev.address))

    def _stop(self) -> None:
        if self.dev is not None:
            try:
                self._ctrl_out(STOP)
            except usb.core.USBError:
                pass
        self._tap_event("stopped")

    def _close(self) -> None:
        if self.dev is not None:
            usbio.release(self.dev)
            self.dev = None
            self._tap_event("close", port=self.port)
