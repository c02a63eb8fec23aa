"""A WSX hub in real time (docs/protocols/wsx.md): requests, frames, events, faults.

The device answers the transfers of §3-§6 with libusb-style statuses (a byte count,
or ``-4`` no device, ``-7`` timeout, ``-8`` overflow, ``-9`` stall), whoever calls it:
the in-process pyusb backend (:mod:`spotlab.simulators.wsx_backend`) or the socket
link (:mod:`spotlab.simulators.wsx_service`). Frames fall due on the host's
monotonic clock; a collection's frame *n* starts ``n / frame_rate`` after
``START`` and is ready once its last marker has fired. Every method is
thread-safe; a bulk read waits (outside the lock) for the next frame or its timeout.
"""

from __future__ import annotations

import struct
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from spotlab.simulators import wsx_wire as w
from spotlab.simulators.wsx_scene import WsxScene

NO_DEVICE, TIMEOUT, OVERFLOW, PIPE, NOT_FOUND = -4, -7, -8, -9, -5
FIFO_BYTES = 4 << 20
FAULT_KINDS = ("stall", "timeout", "short", "babble", "unplug")


@dataclass
class Fault:
    """One scheduled fault: ``kind`` at ``at_s`` after the first START, for ``duration_s``."""

    kind: str
    at_s: float
    duration_s: float = 0.0
    done: bool = False


def parse_faults(text: str) -> list[Fault]:
    """``kind@SECONDS[:DURATION],...`` (wsx.md §9).

    Raises
    ------
    ValueError
        For an unknown kind or a malformed item.
    """
    out = []
    for item in filter(None, (x.strip() for x in text.split(","))):
        kind, at, rest = item.partition("@")
        if kind not in FAULT_KINDS or not at:
            raise ValueError(
                f"fault {item!r}: expected KIND@SECONDS[:DURATION], KIND in {FAULT_KINDS}"
            )
        start, _, dur = rest.partition(":")
        try:
            fault = Fault(kind, float(start), float(dur) if dur else 1.0)
        except ValueError:
            raise ValueError(f"fault {item!r}: SECONDS and DURATION must be numbers") from None
        if fault.at_s < 0 or fault.duration_s <= 0:
            raise ValueError(f"fault {item!r}: times must be positive")
        out.append(fault)
    return out


@dataclass
class Truth:
    """Frames the device took: number, collection, start (device ns), true positions."""

    frame_no: list[int] = field(default_factory=list)
    collection: list[int] = field(default_factory=list)
    start_ns: list[int] = field(default_factory=list)
    points: list[NDArray[np.float64]] = field(default_factory=list)


class WsxDevice:
    """One simulated hub.

    Parameters
    ----------
    scene : WsxScene
        Sensors and markers.
    serial : str
        Serial number (string 3).
    setup : wsx_wire.Setup
        The set-up after power-up.
    faults : list of Fault, optional
    clock : callable
        Host monotonic ns (tests may pass their own).
    registered : bool
        Factory calibration in the device frame (True) or each sensor's own (False).
    """

    def __init__(
        self,
        scene: WsxScene,
        serial: str,
        setup: w.Setup,
        faults: list[Fault] | None = None,
        clock: Callable[[], int] = time.monotonic_ns,
        registered: bool = True,
    ) -> None:
        self.scene, self.serial, self.default_setup = scene, serial, setup
        self.registered = registered
        self.faults = faults or []
        self.clock = clock
        self.lock = threading.RLock()
        self.bus, self.address, self.port = 1, 7, 2
        self.generation = 0
        self.boot_ns = clock()
        self.attached = True
        self.truth = Truth()
        self.collections = 0
        self.fault_log: list[dict[str, object]] = []
        self._first_start: int | None = None
        self._gone_until: int | None = None
        self._power_on()

    # -- state ----------------------------------------------------------------------
    def _power_on(self) -> None:
        self.setup = replace(self.default_setup)
        self.streaming = False
        self.last_error = w.E_NONE
        self.halted = False
        self.fifo: deque[bytes] = deque()
        self.fifo_bytes = 0
        self.events: deque[bytes] = deque()
        self.sent = self.dropped = 0
        self.bits = 0
        self._next_frame = 0
        self._start_ns = 0
        self._after_drop = False
        self._short = self._babble = False
        self._mute_until: int | None = None

    def device_ns(self, now: int) -> int:
        """Device clock (ns since power-up) at host time ``now``."""
        return now - self.boot_ns

    def _period_ns(self) -> float:
        return 1e12 / self.setup.frame_rate_mhz

    def _fire_ns(self) -> NDArray[np.int64]:
        s = self.setup
        k = np.arange(s.markers)
        return np.round(1e12 * (k + s.duty_permille / 2000.0) / s.marker_rate_mhz).astype(np.int64)

    def _ready_ns(self, n: int) -> int:
        s = self.setup
        return int(
            self._start_ns + n * self._period_ns() + 1e12 * (s.markers + 1) / s.marker_rate_mhz
        )

    # -- time -------------------------------------------------------------------------
    def _update(self, now: int) -> None:
        """Apply due faults and queue the frames that are ready by ``now``."""
        if self._gone_until is not None and now >= self._gone_until:
            self._gone_until = None
            self.attached = True
            self.address = self.address % 127 + 1
            self.boot_ns = now
            self._power_on()
        if self._first_start is not None:
            for f in self.faults:
                if not f.done and now >= self._first_start + f.at_s * 1e9:
                    f.done = True
                    self._apply(f, now)
        if self.streaming and self.attached:
            self._produce(now)

    def _apply(self, f: Fault, now: int) -> None:
        self.fault_log.append({"kind": f.kind, "at_s": f.at_s, "duration_s": f.duration_s})
        if f.kind == "stall":
            self.halted = True
            self._event(w.EV_STALL, w.EP_FRAMES)
        elif f.kind == "timeout":
            self._mute_until = now + int(f.duration_s * 1e9)
        elif f.kind == "short":
            self._short = True
        elif f.kind == "babble":
            self._babble = True
        elif f.kind == "unplug":
            if self.streaming:
                self._produce(now)
            self.attached = False
            self.generation += 1
            self._gone_until = now + int(f.duration_s * 1e9)

    def _event(self, code: int, detail: int) -> None:
        self.events.append(w.encode_event(code, self._next_frame, detail))

    def _produce(self, now: int) -> None:
        dev_now = self.device_ns(now)
        n0 = self._next_frame
        n1 = n0
        while self._ready_ns(n1) <= dev_now and n1 - n0 < 4096:
            n1 += 1
        if n1 == n0:
            return
        self._next_frame = n1
        s, scene = self.setup, self.scene
        n = np.arange(n0, n1)
        starts = np.round(self._start_ns + n * self._period_ns()).astype(np.int64)
        fire = self._fire_ns()
        t_fire = (starts[:, None] + fire[None, :]) / 1e9
        full = scene.positions(t_fire)
        m = np.arange(s.markers)
        pts = full[:, m, m, :]
        truth = scene.positions(starts / 1e9)
        centroid, peak, code = scene.readings(pts, s)
        muted = self._mute_until is not None and now < self._mute_until
        flags = s.flags & w.FLAG_NO_INTERPOLATION
        for i, k in enumerate(n):
            self.truth.frame_no.append(int(k))
            self.truth.collection.append(self.collections)
            self.truth.start_ns.append(int(starts[i]))
            self.truth.points.append(truth[i])
            frame = w.encode_frame(
                int(k), int(starts[i]),
                flags | (w.FRAME_AFTER_DROP if self._after_drop else 0),
                fire, centroid[i], peak[i], code[i], 0, self.dropped,
            )  # fmt: skip
            if muted or self.fifo_bytes + len(frame) > FIFO_BYTES:
                self.dropped += 1
                self._after_drop = True
                self.bits |= w.STATUS_OVERFLOW
                if not muted:
                    self._event(w.EV_OVERFLOW, self.dropped)
                continue
            self._after_drop = False
            self.fifo.append(frame)
            self.fifo_bytes += len(frame)

    # -- requests ---------------------------------------------------------------------
    def present(self, generation: int) -> bool:
        with self.lock:
            self._update(self.clock())
            return self.attached and generation == self.generation

    def control(
        self, generation: int, request_type: int, request: int, value: int, index: int,
        data: bytes, length: int,
    ) -> tuple[int, bytes]:  # fmt: skip
        """A control transfer: (status, IN data)."""
        with self.lock:
            now = self.clock()
            self._update(now)
            if not self.attached or generation != self.generation:
                return NO_DEVICE, b""
            if request_type & 0x60 == 0:
                return self._standard(request_type, request, value, index, length)
            if request_type & 0x60 != 0x40:
                return PIPE, b""
            status, out = self._vendor(request_type & 0x80 != 0, request, index, data, now)
            if status == PIPE:
                return status, b""
            self.last_error = w.E_NONE
            return (len(out) if request_type & 0x80 else len(data)), out[:length]

    def _standard(
        self, request_type: int, request: int, value: int, index: int, length: int
    ) -> tuple[int, bytes]:
        if request == 6 and request_type == 0x80:  # GET_DESCRIPTOR
            kind, i = value >> 8, value & 0xFF
            desc = {1: w.device_descriptor(), 2: w.configuration_descriptor()}.get(kind)
            if kind == 3:
                desc = w.string_descriptor(i, self.serial)
            if desc is None:
                return PIPE, b""
            return min(length, len(desc)), desc[:length]
        if request == 9 and request_type == 0x00:  # SET_CONFIGURATION
            return 0, b""
        if request == 1 and request_type == 0x02 and value == 0:  # CLEAR_FEATURE(HALT)
            if index == w.EP_FRAMES:
                self.halted = False
            return 0, b""
        if request == 11 and request_type == 0x01:  # SET_INTERFACE
            return 0, b""
        return PIPE, b""

    def _refuse(self, code: int) -> tuple[int, bytes]:
        self.last_error = code
        return PIPE, b""

    def _vendor(
        self, is_in: bool, request: int, index: int, data: bytes, now: int
    ) -> tuple[int, bytes]:
        if request == w.REQ_INFO and is_in:
            return 0, w.encode_info(self.scene.n_sensors)
        if request == w.REQ_GET_SETUP and is_in:
            return 0, w.encode_setup(self.setup)
        if request == w.REQ_STATUS and is_in:
            ms = self.device_ns(now) // 1_000_000
            return 0, w.encode_status(
                self.streaming, self.last_error, self.bits, self.sent, self.dropped, ms
            )
        if request == w.REQ_CALIBRATION and is_in:
            if not 0 <= index < self.scene.n_sensors:
                return self._refuse(w.E_SENSOR)
            return 0, self.scene.calibration_record(index, self.registered)
        if request == w.REQ_SET_SETUP and not is_in:
            if self.streaming:
                return self._refuse(w.E_BUSY)
            setup, err = w.parse_setup(bytes(data))
            if err:
                return self._refuse(err)
            if setup.markers != self.scene.n_markers:
                # strobers with other marker counts would fire nothing we model
                self.scene = _rescene(self.scene, setup.markers)
            self.setup = setup
            return 0, b""
        if request == w.REQ_START and not is_in:
            if not self.streaming:
                self.streaming = True
                self.collections += 1
                self._start_ns = self.device_ns(now)
                self._next_frame = 0
                self.sent = self.dropped = 0
                self.bits = 0
                self.fifo.clear()
                self.fifo_bytes = 0
                if self._first_start is None:
                    self._first_start = now
            return 0, b""
        if request == w.REQ_STOP and not is_in:
            if self.streaming:
                self._produce(now)
            self.streaming = False
            return 0, b""
        return self._refuse(w.E_UNKNOWN)

    def clear_halt(self, generation: int, endpoint: int) -> int:
        with self.lock:
            self._update(self.clock())
            if not self.attached or generation != self.generation:
                return NO_DEVICE
            if endpoint == w.EP_FRAMES:
                self.halted = False
            return 0

    def read(
        self, generation: int, endpoint: int, length: int, timeout_ms: int
    ) -> tuple[int, bytes]:
        """A bulk or interrupt IN transfer: (status, data)."""
        deadline = self.clock() + max(1, timeout_ms) * 1_000_000
        while True:
            with self.lock:
                now = self.clock()
                self._update(now)
                if not self.attached or generation != self.generation:
                    return NO_DEVICE, b""
                if endpoint == w.EP_EVENTS:
                    if self.events:
                        return w.EVENT_BYTES, self.events.popleft()
                    wake = deadline
                elif endpoint != w.EP_FRAMES:
                    return PIPE, b""
                elif self.halted:
                    return PIPE, b""
                elif self._mute_until is not None and now < self._mute_until:
                    wake = min(deadline, self._mute_until)
                elif self.fifo:
                    return self._take(length)
                else:
                    wake = deadline
                    if self.streaming:
                        wake = min(wake, self.boot_ns + self._ready_ns(self._next_frame))
            if now >= deadline:
                return TIMEOUT, b""
            time.sleep(max(0.0, min(wake, deadline) - now) / 1e9 + 1e-4)

    def _take(self, length: int) -> tuple[int, bytes]:
        out = bytearray()
        while self.fifo and len(out) + len(self.fifo[0]) <= length:
            frame = self.fifo.popleft()
            self.fifo_bytes -= len(frame)
            out += frame
            self.sent += 1
        if not out:  # the host's buffer is smaller than a frame: babble
            frame = self.fifo.popleft()
            self.fifo_bytes -= len(frame)
            return OVERFLOW, b""
        if self._babble:
            self._babble = False
            return OVERFLOW, b""
        if self._short:
            self._short = False
            first = struct.unpack_from("<I", out, 4)[0]
            out = out[: first // 2]
        return len(out), bytes(out)


def _rescene(scene: WsxScene, markers: int) -> WsxScene:
    """The same sensors with another number of markers on the body."""
    return WsxScene(scene.n_sensors, markers, scene.seed, scene.model)
