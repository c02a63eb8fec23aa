"""A simulated Qualisys QTM real-time server on 127.0.0.1 (docs/protocols/qualisys.md).

:class:`QualisysServer` runs an asyncio TCP server in a thread of its own. Its
cameras capture from start-up (QTM's real-time preview) at ``rate_hz``; frame
*n* (from 1) is taken at ``(n - 1) / rate_hz`` s after start-up and carries
that time in µs as QTM's timestamp (QTM's clock runs fast by ``clock_drift_ppm``). Each
client that asked with
``StreamFrames`` gets the frames of its choice with the components of its
choice; ``GetCurrentFrame``, ``GetParameters``, ``GetState``, ``Version``,
``QTMVersion``, ``ByteOrder``, ``TakeControl``/``ReleaseControl`` (with an
optional password) and ``Start``/``Stop`` are answered as the spec says.

Faults are timed from the first ``StreamFrames`` any client sends:
``drop@T[:N]`` (QTM loses N frames: numbers skip), ``disconnect@T[:OUTAGE_S]``
(every connection closed, new ones refused for the outage), ``late@T[:N]`` (N
frames held back and sent :data:`LATE_S` after the last of them was due, the
frames due meanwhile behind them, as TCP keeps the order), ``restart@T`` (the
capture stopped and started again: ``CaptureStopped``, no frames for
:data:`RESTART_PAUSE_S`, ``CaptureStarted``, frame numbers and timestamps from 1
and 0 again) and ``slow@T[:N]`` (the client's socket is full: the server skips
the N frames for it, and says nothing, as QTM does; its numbers skip). A client
that really reads too slowly gets the same: once more than :data:`SEND_LIMIT`
bytes wait for it, its frames are skipped (``skipped`` in the truth).
A client that asked for ``UDP:[ADDR:]PORT`` gets its Data packets as datagrams
there, one packet each (what the network then loses is the client's loss).
The truth (``truth()``, or the ``.npz`` written by :meth:`QualisysServer.stop`)
holds every frame sent to at least one client.
"""

from __future__ import annotations

import asyncio
import socket
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from spotlab.simulators import qualisys_wire as qw
from spotlab.simulators.clock import DeviceClock
from spotlab.simulators.faults import parse_schedule
from spotlab.simulators.lab import LabPublisher, lab_dir
from spotlab.simulators.priority import raise_serving_priority
from spotlab.simulators.qualisys_commands import VERSIONS, Client, QtmDialogue
from spotlab.simulators.qualisys_scene import QualisysScene, SceneFrame

WELCOME = "QTM RT Interface connected"
#: Fault kinds the QTM simulator injects.
FAULT_KINDS = ("drop", "disconnect", "late", "restart", "slow")
#: Seconds a ``late`` fault holds its frames back after the last of them was due.
LATE_S = 0.05
#: Seconds without frames between ``CaptureStopped`` and ``CaptureStarted`` of a ``restart``.
RESTART_PAUSE_S = 0.1
#: Bytes waiting for a client's socket beyond which its frames are skipped (a client too
#: slow for the stream: QTM drops its frames rather than queue them, and says nothing).
SEND_LIMIT = 256 * 1024
#: Width of the frame pulses of QTM's synchronisation output (published to the lab).
SYNC_PULSE_WIDTH_S = 100e-6


@dataclass
class QualisysSimOptions:
    """What ``spotlab sim qualisys`` serves (see the module docstring)."""

    cameras: int = 8
    markers: int = 40
    rate_hz: float = 100.0
    seed: int = 0
    port: int = 0
    truth: Path | None = None
    faults: str = ""
    password: str | None = None
    versions: tuple[str, ...] = VERSIONS
    clock_drift_ppm: float = 0.0
    lab: Path | None = None
    lab_name: str = ""

    def validate(self) -> None:
        """Raise ValueError naming the first option out of range."""
        QualisysScene(self.markers, self.cameras, self.rate_hz, self.seed, self.clock_drift_ppm)
        if not 0 <= self.port <= 65535:
            raise ValueError(f"--port must be 0 to 65535, got {self.port}")
        try:
            parse_schedule(self.faults, FAULT_KINDS)
        except ValueError as exc:
            raise ValueError(f"--faults: {exc} (the qualisys simulator's kinds)") from None


@dataclass
class _Truth:
    frames: list[int] = field(default_factory=list)
    markers: list[np.ndarray] = field(default_factory=list)
    positions: list[np.ndarray] = field(default_factory=list)
    rotations: list[np.ndarray] = field(default_factory=list)
    qtm_frames: list[int] = field(default_factory=list)
    late: list[int] = field(default_factory=list)
    skipped: list[int] = field(default_factory=list)


class QualisysServer(QtmDialogue):
    """The simulated QTM: ``start()``, then clients connect to :attr:`address`; ``stop()``.

    Parameters
    ----------
    options : QualisysSimOptions
        Scene, rate, port, password, faults and truth file.
    """

    def __init__(self, options: QualisysSimOptions) -> None:
        options.validate()
        self.options = options
        self.scene = QualisysScene(
            options.markers, options.cameras, options.rate_hz, options.seed, options.clock_drift_ppm
        )
        self.faults = parse_schedule(options.faults, FAULT_KINDS)
        self.fault_log: list[dict[str, Any]] = []
        self.state = qw.EV_CONNECTED
        self.port = 0
        self.connections = 0
        self._truth = _Truth()
        self._clients: set[Client] = set()
        self._master: Client | None = None
        self._anchor: float | None = None
        self._refuse_until = 0.0
        self._dropped: set[int] = set()
        self._skipped: set[int] = set()
        self._late_release: dict[int, int] = {}
        self._hold_until = 0
        self._held: list[tuple[Client, bytes]] = []
        self._stop_at: dict[int, int] = {}
        self._base = 0
        self._frame = 0
        self._t0 = 0.0
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stopping: asyncio.Event | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._udp: socket.socket | None = None
        self.udp_send_errors = 0
        self.lab: LabPublisher | None = None

    @property
    def password(self) -> str | None:
        """The password ``TakeControl`` must give (None: any)."""
        return self.options.password

    @property
    def versions(self) -> tuple[str, ...]:
        """Protocol versions a client may ask for."""
        return self.options.versions

    # -- life cycle --------------------------------------------------------------
    @property
    def address(self) -> str:
        """``127.0.0.1:PORT``, what a client connects to."""
        return f"127.0.0.1:{self.port}"

    def start(self) -> QualisysServer:
        """Bind and serve in a thread; returns once clients can connect.

        Raises
        ------
        OSError
            If the port cannot be bound.
        """
        self._thread = threading.Thread(target=self._run, name="qtm-sim", daemon=True)
        self._thread.start()
        self._ready.wait(10.0)
        if self._error is not None:
            raise self._error
        return self

    def stop(self) -> None:
        """Close every connection, stop serving, write the truth file if one was asked."""
        if self._thread is None:
            return
        if self._loop is not None and self._stopping is not None:
            self._loop.call_soon_threadsafe(self._stopping.set)
        self._thread.join(10.0)
        self._thread = None
        if self.lab is not None:
            self.lab.stopped(time.monotonic_ns())
        if self.options.truth is not None:
            self.write_truth(self.options.truth)

    def __enter__(self) -> QualisysServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def truth(self) -> dict[str, Any]:
        """Every frame sent to a client: ``frame`` (F,: the server's tick, from 1, which is
        QTM's frame number until a ``restart``), ``qtm_frame`` (F,: the number sent),
        ``time_s`` (F,), ``timestamp_us`` (F,: as sent), ``markers_mm`` (F, M, 3), ``labels``
        (M,), ``body_names`` (B,), ``body_positions_mm`` (F, B, 3), ``body_rotations``
        (F, B, 3, 3) (body to world), ``late`` (ticks of the frames a ``late`` fault held
        back) and ``skipped`` (ticks a ``slow`` fault did not send)."""
        t = self._truth
        frames = np.asarray(t.frames, dtype=np.int64)
        qtm = np.asarray(t.qtm_frames, dtype=np.int64)
        f, m, b = len(frames), self.scene.n_markers, len(self.scene.body_names)
        return {
            "frame": frames,
            "qtm_frame": qtm,
            "late": np.asarray(t.late, dtype=np.int64),
            "skipped": np.asarray(t.skipped, dtype=np.int64),
            "time_s": (frames - 1) / self.scene.rate_hz,
            "timestamp_us": np.array([self.scene.timestamp_us(int(n)) for n in qtm], np.int64),
            "markers_mm": np.array(t.markers).reshape(f, m, 3),
            "labels": np.array(self.scene.labels),
            "body_names": np.array(self.scene.body_names),
            "body_positions_mm": np.array(t.positions).reshape(f, b, 3),
            "body_rotations": np.array(t.rotations).reshape(f, b, 3, 3),
        }

    def write_truth(self, path: Path) -> None:
        """Write :meth:`truth` as a ``.npz`` file."""
        with open(path, "wb") as f:
            np.savez(f, **self.truth())

    def _publish(self, t0_ns: int) -> None:
        """With a lab name: publish the frame pulses of QTM's synchronisation output.

        QTM's clock (:class:`~spotlab.simulators.clock.DeviceClock`, powered up at
        ``t0_ns``) runs ``clock_drift_ppm`` fast; frame *n* is due at its oscillator time
        ``(n - 1) (1 + drift) / rate``, which is world time ``t0 + (n - 1) / rate``, and its
        counter reads the frame's timestamp: a timer input wired to the lab name sees one
        edge per frame at the frame's true instant.
        """
        o = self.options
        if not o.lab_name:
            return
        clock = DeviceClock(drift_ppm=o.clock_drift_ppm, epoch_ns=t0_ns)
        self.lab = LabPublisher(lab_dir(o.lab), o.lab_name, clock, SYNC_PULSE_WIDTH_S)
        period_osc = (1.0 + o.clock_drift_ppm * 1e-6) / self.scene.rate_hz
        self.lab.started(0, t0_ns, 0.0, period_osc)

    # -- the event loop ----------------------------------------------------------
    def _run(self) -> None:
        raise_serving_priority()
        loop = asyncio.new_event_loop()
        self._loop = loop
        try:
            loop.run_until_complete(self._main())
        except BaseException as exc:  # reported to start() when it fails to bind
            self._error = exc
            self._ready.set()
        finally:
            loop.close()

    async def _main(self) -> None:
        self._stopping = asyncio.Event()
        server = await asyncio.start_server(self._serve_client, "127.0.0.1", self.options.port)
        self._udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._udp.setblocking(False)
        self.port = int(server.sockets[0].getsockname()[1])
        t0_ns = time.monotonic_ns()
        self._t0 = t0_ns * 1e-9
        self._publish(t0_ns)
        ticker = asyncio.ensure_future(self._ticker())
        self._ready.set()
        try:
            await self._stopping.wait()
        finally:
            ticker.cancel()
            server.close()
            for client in list(self._clients):
                client.writer.close()
            await server.wait_closed()
            self._udp.close()

    async def _ticker(self) -> None:
        n = 1
        period = 1.0 / self.scene.rate_hz
        while True:
            delay = self._t0 + (n - 1) * period - time.monotonic()
            await asyncio.sleep(max(delay, 0.0))
            self._timed_faults()
            self._emit(n)
            self._frame = n
            n += 1

    # -- frames ----------------------------------------------------------------------
    def _emit(self, n: int) -> None:
        if self._held and n >= self._hold_until:
            for client, data in self._held:
                if client in self._clients:
                    self._send_frame(client, data)
            self._held = []
        self._restart(n)
        if n < self._base + 1:  # capture stopped
            return
        takers = [c for c in self._clients if c.divisor and (n - 1) % c.divisor == 0]
        if not takers:
            return
        if n in self._dropped:
            return
        t = self._truth
        if n in self._skipped:
            t.skipped.append(n)
            return
        if n in self._late_release:
            self._hold_until = max(self._hold_until, self._late_release[n])
            t.late.append(n)
        number = n - self._base
        frame = self.scene.frame(n)
        full = [
            c
            for c in takers
            if c.udp is None and c.writer.transport.get_write_buffer_size() > SEND_LIMIT
        ]
        if full:
            t.skipped.append(n)
            takers = [c for c in takers if c not in full]
            if not takers:
                return
        for client in takers:
            data = self._data(number, frame, client.components)
            if n < self._hold_until:
                self._held.append((client, data))
            else:
                self._send_frame(client, data)
        t.frames.append(n)
        t.qtm_frames.append(number)
        t.markers.append(frame.markers)
        t.positions.append(frame.body_positions)
        t.rotations.append(frame.body_rotations)

    def _send_frame(self, client: Client, data: bytes) -> None:
        """A Data packet on the client's TCP link, or as one datagram where it asked."""
        if client.udp is None or self._udp is None:
            client.writer.write(data)
            return
        try:
            self._udp.sendto(data, client.udp)
        except OSError:  # a full send buffer or no route: the datagram is lost
            self.udp_send_errors += 1

    def _data(self, n: int, frame: SceneFrame, components: tuple[str, ...]) -> bytes:
        parts = []
        for name in components:
            if name == "3d":
                parts.append(qw.component_3d(frame.markers))
            elif name == "3dnolabels":
                parts.append(qw.component_3d_no_labels(frame.markers))
            elif name == "6d":
                parts.append(qw.component_6d(frame.body_positions, frame.body_rotations))
            elif name == "2d":
                parts.append(qw.component_2d(self.scene.view_2d(frame.markers)))
        return qw.data_packet(self.scene.timestamp_us(n), n, parts)

    # -- faults ------------------------------------------------------------------------
    def _restart(self, n: int) -> None:
        """A ``restart`` due at tick ``n``: stop the capture; start it again when due."""
        if n in self._stop_at:
            self._base = self._stop_at[n] - 1  # the restarted capture's frame 1
            self._broadcast_event(qw.EV_CAPTURE_STOPPED)
        elif n == self._base + 1 and self._base and self.state == qw.EV_CAPTURE_STOPPED:
            self._broadcast_event(qw.EV_CAPTURE_STARTED)

    def _anchor_faults(self) -> None:
        if self._anchor is not None:
            return
        self._anchor = time.monotonic()
        first = self._frame + 1
        for spec in self.faults:
            if spec.kind == "drop":
                at = first + round(spec.at_s * self.scene.rate_hz)
                count = round(spec.arg or 1)
                self._dropped.update(range(at, at + count))
                self.fault_log.append({"kind": "drop", "at_s": spec.at_s, "frames": [at, count]})
            elif spec.kind in ("late", "slow"):
                at = first + round(spec.at_s * self.scene.rate_hz)
                count = round(spec.arg or 1)
                if spec.kind == "slow":
                    self._skipped.update(range(at, at + count))
                else:
                    release = at + count - 1 + max(1, round(LATE_S * self.scene.rate_hz))
                    self._late_release.update({k: release for k in range(at, at + count)})
                self.fault_log.append({"kind": spec.kind, "at_s": spec.at_s, "frames": [at, count]})
            elif spec.kind == "restart":
                at = first + round(spec.at_s * self.scene.rate_hz)
                resume = at + max(1, round(RESTART_PAUSE_S * self.scene.rate_hz))
                self._stop_at[at] = resume
                self.fault_log.append({"kind": "restart", "at_s": spec.at_s, "frames": [at]})

    def _timed_faults(self) -> None:
        if self._anchor is None:
            return
        since = time.monotonic() - self._anchor
        for spec in self.faults:
            if spec.kind != "disconnect" or spec.at_s > since:
                continue
            if any(e["kind"] == "disconnect" and e["at_s"] == spec.at_s for e in self.fault_log):
                continue
            outage = spec.arg or 1.0
            self._refuse_until = time.monotonic() + outage
            self.fault_log.append(
                {"kind": "disconnect", "at_s": spec.at_s, "outage_s": outage, "frame": self._frame}
            )
            for client in list(self._clients):
                client.writer.write(qw.event_packet(qw.EV_CONNECTION_CLOSED))
                client.writer.close()
                self._drop_client(client)

    # -- clients ------------------------------------------------------------------------
    def _drop_client(self, client: Client) -> None:
        self._clients.discard(client)
        if self._master is client:
            self._master = None

    async def _serve_client(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter
    ) -> None:
        if time.monotonic() < self._refuse_until:
            writer.close()
            return
        self.connections += 1
        client = Client(writer)
        self._clients.add(client)
        writer.write(qw.text_packet(qw.COMMAND, WELCOME))
        commands = qw.CommandReader()
        try:
            while client in self._clients:
                data = await reader.read(65536)
                if not data:
                    break
                for packet in commands.feed(data):
                    self._handle(client, packet)
                await writer.drain()
        except (ConnectionError, ValueError):
            pass
        finally:
            self._drop_client(client)
            writer.close()
