"""A simulated OptiTrack Motive NatNet server on 127.0.0.1 (docs/protocols/natnet.md).

:class:`NatNetServer` binds a command socket (the address a client connects to)
and a data socket on the loopback interface, answers ``NAT_CONNECT`` with the
server info and ``NAT_REQUEST_MODELDEF`` with the model descriptions, and sends
one ``NAT_FRAMEOFDATA`` per frame period: unicast to every client that connected
(to the address its connect came from), or, with ``multicast=True``, to a group
on the loopback interface (tests only). Frames are numbered from the server's
start; the first client's connect anchors the fault schedule. Every frame sent
goes to the truth (:class:`NatNetTruth`) when one is given.

Faults (``faults``, comma-separated, times in s after the first connect):
``drop@T`` (the frame due at T is not sent), ``drop@T:N`` (N frames from T),
``disconnect@T`` (the server falls silent for good: no frames, no replies) and
``disconnect@T:D`` (silent for D s, then back; frame numbers go on),
``late@T[:N]`` (N frames held back and sent :data:`LATE_S` after the last of them
was due, the frames due meanwhile behind them), ``restart@T`` (Motive's frame
numbers start again from 0, as when a take restarts; the stream goes on) and
``slow@T[:N]`` (a client too slow for the stream: its socket buffer is full, so
the N frames the server sends from T are lost in it; emulated by not sending
them, the truth lists them in ``overflowed``).
"""

from __future__ import annotations

import math
import select
import socket
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from spotlab.simulators import natnet_wire as nw
from spotlab.simulators.natnet_scene import MODEL_ID, NatNetScene
from spotlab.simulators.priority import raise_serving_priority

F64 = npt.NDArray[np.float64]

#: Seconds after which a unicast client that sent nothing is forgotten.
CLIENT_TIMEOUT_S = 10.0
CLOCK_HZ = 10_000_000
MULTICAST_GROUP = "239.255.42.99"
#: Seconds a ``late`` fault holds its frames back after the last of them was due.
LATE_S = 0.05
FAULT_KINDS = ("drop", "disconnect", "late", "restart", "slow")


@dataclass(frozen=True)
class NatNetFault:
    """One scheduled fault: ``kind`` (one of :data:`FAULT_KINDS`), time ``at_s``, and ``n``
    frames (drop, late, slow) or ``duration_s`` (disconnect; inf: for good)."""

    kind: str
    at_s: float
    n: int = 1
    duration_s: float = float("inf")


def parse_faults(text: str) -> list[NatNetFault]:
    """``drop@T[:N]``, ``disconnect@T[:D]``, ``late@T[:N]``, ``restart@T`` and
    ``slow@T[:N]`` items, comma-separated.

    Raises
    ------
    ValueError
        On an unknown kind or a bad number.
    """
    out = []
    for item in filter(None, (s.strip() for s in text.split(","))):
        kind, at, rest = item.partition("@")
        when, _, arg = rest.partition(":")
        try:
            if not at:
                raise ValueError
            at_s = float(when)
            if kind in ("drop", "late", "slow"):
                out.append(NatNetFault(kind, at_s, n=int(arg) if arg else 1))
            elif kind == "restart" and not arg:
                out.append(NatNetFault(kind, at_s))
            elif kind == "disconnect":
                out.append(NatNetFault("disconnect", at_s, duration_s=float(arg or "inf")))
            else:
                raise ValueError
        except ValueError:
            raise ValueError(
                f"fault {item!r}: expected drop@T[:N], disconnect@T[:SECONDS], late@T[:N], "
                "restart@T or slow@T[:N]"
            ) from None
        if not at_s >= 0:
            raise ValueError(f"fault {item!r}: T must be >= 0 s")
    return out


@dataclass
class NatNetTruth:
    """The frames served: frame number, time (s) and markers (mm), written as ``.npz``."""

    path: Path
    labels: tuple[str, ...]
    frames: list[int] = field(default_factory=list)
    times: list[float] = field(default_factory=list)
    markers: list[F64] = field(default_factory=list)
    dropped: list[int] = field(default_factory=list)
    sent_ns: list[int] = field(default_factory=list)
    due_ns: list[int] = field(default_factory=list)
    ticks: list[int] = field(default_factory=list)
    numbers: list[int] = field(default_factory=list)
    late: list[int] = field(default_factory=list)
    overflowed: list[int] = field(default_factory=list)

    def add(
        self,
        frame: int,
        t_s: float,
        x_mm: F64,
        *,
        sent_ns: int = 0,
        due_ns: int = 0,
        ticks: int = 0,
        number: int | None = None,
    ) -> None:
        self.frames.append(frame)
        self.numbers.append(frame if number is None else number)
        self.times.append(t_s)
        self.markers.append(np.array(x_mm, dtype=np.float64))
        self.sent_ns.append(sent_ns)
        self.due_ns.append(due_ns)
        self.ticks.append(ticks)

    def write(self) -> None:
        """Write ``time_s`` (F,), ``markers_mm`` (F, M, 3), ``labels`` (M,), ``frame`` (F,),
        ``dropped`` (frame numbers not sent), ``sent_ns`` (F,: ``time.monotonic_ns()`` when
        the frame was sent), ``due_ns`` (F,: when the server's clock reached the frame, on
        the same clock), ``ticks`` (F,: its mid-exposure stamp, server clock ticks),
        ``number`` (F,: the frame number sent, ``frame`` until a ``restart``), ``late``
        (frames a ``late`` fault held back) and ``overflowed`` (frames a ``slow`` fault
        lost in the client's socket)."""
        m = len(self.labels)
        x = np.stack(self.markers) if self.markers else np.zeros((0, m, 3))
        np.savez(
            self.path,
            time_s=np.asarray(self.times, dtype=np.float64),
            markers_mm=x,
            labels=np.asarray(self.labels, dtype=str),
            frame=np.asarray(self.frames, dtype=np.int64),
            dropped=np.asarray(self.dropped, dtype=np.int64),
            sent_ns=np.asarray(self.sent_ns, dtype=np.int64),
            due_ns=np.asarray(self.due_ns, dtype=np.int64),
            ticks=np.asarray(self.ticks, dtype=np.int64),
            number=np.asarray(self.numbers, dtype=np.int64),
            late=np.asarray(self.late, dtype=np.int64),
            overflowed=np.asarray(self.overflowed, dtype=np.int64),
        )


class NatNetServer:
    """The simulated Motive: command and data sockets on 127.0.0.1, a serving thread.

    Parameters
    ----------
    scene : NatNetScene
    version : tuple of int
        NatNet version served, (3, 1) or (4, 1).
    port : int
        Command port (0: any free port); the data socket takes any free port, or
        ``port + 1`` with multicast (clients join the group on the data port).
    truth : path, optional
        Where :meth:`stop` writes the truth (``.npz``).
    faults : str
        Fault schedule (see the module docstring).
    multicast : bool
        Send frames to ``239.255.42.99`` on the loopback interface instead of unicast.
    client_timeout_s : float
        Seconds after which a unicast client that sent nothing is forgotten.
    clock_drift_ppm : float
        Error of the server's oscillator in parts per million (positive runs fast):
        frame ``k`` is taken when the server's clock reads ``k / rate`` s after start,
        ``k / rate / (1 + drift)`` s of this host's clock.
    clock_offset_s : float
        Seconds the server's clock reads at start (its stamps and timestamps).
    """

    def __init__(
        self,
        scene: NatNetScene,
        *,
        version: nw.Version = (4, 1),
        port: int = 0,
        truth: Path | None = None,
        faults: str = "",
        multicast: bool = False,
        client_timeout_s: float = CLIENT_TIMEOUT_S,
        clock_drift_ppm: float = 0.0,
        clock_offset_s: float = 0.0,
    ) -> None:
        if version not in nw.VERSIONS:
            raise ValueError(f"NatNet version {version} is not one of {nw.VERSIONS}")
        self.scene = scene
        self.version = version
        self.multicast = multicast
        self.client_timeout_s = client_timeout_s
        if not -1000.0 <= clock_drift_ppm <= 1000.0:
            raise ValueError(f"the clock drift must be within +-1000 ppm, got {clock_drift_ppm}")
        if not clock_offset_s >= 0.0:
            raise ValueError(f"the clock offset must be >= 0 s, got {clock_offset_s}")
        self.clock_rate = 1.0 + clock_drift_ppm * 1e-6
        self.clock_offset_s = clock_offset_s
        self.faults = parse_faults(faults)
        self.truth = NatNetTruth(truth, scene.labels) if truth is not None else None
        self.cmd = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.cmd.bind(("127.0.0.1", port))
        self.port = self.cmd.getsockname()[1]
        self.data = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        if multicast:
            self.data.bind(("127.0.0.1", self.port + 1))
            self.data.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 1)
            self.data.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
            self.data.setsockopt(
                socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1")
            )
        else:
            self.data.bind(("127.0.0.1", 0))
        self.data_port = self.data.getsockname()[1]
        self.clients: dict[tuple[str, int], float] = {}
        self.frames_sent = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._start_s = 0.0
        self._anchor_s: float | None = None
        self._next = 0
        self._held: list[tuple[bytes, int]] = []
        self._hold_until = 0
        self._modeldef = nw.model_definitions(
            version, "walker", scene.labels, scene.rigid_bodies(), scene.cameras()
        )

    @property
    def address(self) -> str:
        """``host:port`` a client connects to."""
        return f"127.0.0.1:{self.port}"

    # -- life cycle ----------------------------------------------------------------
    def start(self) -> NatNetServer:
        """Start streaming (frame 0 is due now) in a thread of its own."""
        self._start_s = time.monotonic()
        self._thread = threading.Thread(target=self._run, name="natnet-sim", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread, close the sockets, write the truth."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
        self.cmd.close()
        self.data.close()
        if self.truth is not None:
            self.truth.write()

    def __enter__(self) -> NatNetServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- serving -------------------------------------------------------------------
    def _silent(self, now: float) -> bool:
        if self._anchor_s is None:
            return False
        t = now - self._anchor_s
        return any(
            f.kind == "disconnect" and f.at_s <= t < f.at_s + f.duration_s for f in self.faults
        )

    def _first(self, f: NatNetFault) -> int:
        """The first frame due at or after fault ``f``'s time (after the anchor)."""
        assert self._anchor_s is not None
        rate = self.scene.rate_hz
        return math.ceil((self._anchor_s - self._start_s + f.at_s) * rate - 1e-9)

    def _hit(self, k: int, kind: str) -> NatNetFault | None:
        """The fault of ``kind`` whose frames (its first and the ``n - 1`` after) hold
        frame ``k``, if any."""
        if self._anchor_s is None:
            return None
        for f in self.faults:
            if f.kind == kind and self._first(f) <= k < self._first(f) + f.n:
                return f
        return None

    def _dropped(self, k: int) -> bool:
        """Whether frame ``k`` is one of a drop's."""
        return self._hit(k, "drop") is not None

    def _number(self, k: int) -> int:
        """Motive's frame number of frame ``k``: from 0 again after each restart."""
        base = 0
        if self._anchor_s is not None:
            for f in self.faults:
                if f.kind == "restart" and self._first(f) <= k:
                    base = max(base, self._first(f))
        return k - base

    def _run(self) -> None:
        raise_serving_priority()
        while not self._stop.is_set():
            now = time.monotonic()
            due = self._start_s + self._next / self.scene.rate_hz / self.clock_rate
            wait = max(0.0, due - now)
            ready, _, _ = select.select([self.cmd], [], [], min(wait, 0.05))
            if ready:
                self._on_command(time.monotonic())
                continue
            if time.monotonic() >= due:
                self._send_frame(self._next)
                self._next += 1

    def _on_command(self, now: float) -> None:
        try:
            data, addr = self.cmd.recvfrom(65536)
        except OSError:
            return
        if self._silent(now):
            return
        try:
            message_id, _ = nw.parse_packet(data)
        except ValueError:
            return  # not NatNet: ignored, as a server on a shared port would
        if message_id == nw.NAT_CONNECT:
            if self._anchor_s is None:
                self._anchor_s = now
            self.clients[addr] = now
            info = nw.server_info(
                self.version,
                clock_hz=CLOCK_HZ,
                data_port=self.data_port,
                multicast=self.multicast,
                group=MULTICAST_GROUP,
            )
            self.cmd.sendto(info, addr)
        elif message_id == nw.NAT_REQUEST_MODELDEF:
            self.clients[addr] = now
            self.cmd.sendto(self._modeldef, addr)
        elif message_id == nw.NAT_KEEPALIVE:
            if addr in self.clients:
                self.clients[addr] = now
        elif message_id == nw.NAT_DISCONNECT:
            self.clients.pop(addr, None)
        elif message_id in (nw.NAT_REQUEST, nw.NAT_REQUEST_FRAMEOFDATA):
            self.cmd.sendto(nw.packet(nw.NAT_UNRECOGNIZED_REQUEST, b""), addr)

    def _send_frame(self, k: int) -> None:
        now = time.monotonic()
        for addr, seen in list(self.clients.items()):
            if now - seen > self.client_timeout_s:
                del self.clients[addr]
        if not self.clients and not self.multicast:
            return
        self._release(k)
        t = float(self.scene.time_s(k))
        if self._silent(now):
            return
        if self._dropped(k):
            if self.truth is not None:
                self.truth.dropped.append(k)
            return
        if self._hit(k, "slow") is not None:
            if self.truth is not None:
                self.truth.overflowed.append(k)
            return
        late = self._hit(k, "late")
        if late is not None:
            release = self._first(late) + late.n - 1 + max(1, round(LATE_S * self.scene.rate_hz))
            self._hold_until = max(self._hold_until, release)
            if self.truth is not None:
                self.truth.late.append(k)
        x = self.scene.markers_mm(np.array([t]))[0]
        clock_s = self.clock_offset_s + t  # the server's clock at frame k: k / rate after start
        tc, sub = nw.timecode(clock_s)
        mid = round(clock_s * CLOCK_HZ)
        content = nw.FrameContent(
            frame_number=self._number(k),
            marker_set="walker",
            markers_m=x / 1000.0,
            labelled_ids=[MODEL_ID << 16 | (i + 1) for i in range(x.shape[0])],
            timecode=tc,
            timecode_sub=sub,
            timestamp_s=clock_s,
            stamps=(mid, mid + CLOCK_HZ // 500, mid + 3 * CLOCK_HZ // 1000),
            rigid_bodies=self.scene.poses(x),
        )
        pkt = nw.frame_of_data(self.version, content)
        self.frames_sent += 1
        row = -1
        if self.truth is not None:
            row = len(self.truth.frames)
            due_ns = round((self._start_s + k / self.scene.rate_hz / self.clock_rate) * 1e9)
            self.truth.add(k, t, x, due_ns=due_ns, ticks=mid, number=self._number(k))
        if k < self._hold_until:
            self._held.append((pkt, row))
        else:
            self._transmit([(pkt, row)])

    def _release(self, k: int) -> None:
        """Send the frames a ``late`` fault held, once frame ``k`` is due after the hold."""
        if self._held and k >= self._hold_until:
            held, self._held = self._held, []
            self._transmit(held)

    def _transmit(self, packets: list[tuple[bytes, int]]) -> None:
        """Send frames (with their truth rows, -1: none) to the group or every client."""
        targets = [(MULTICAST_GROUP, self.data_port)] if self.multicast else list(self.clients)
        for pkt, row in packets:
            for addr in targets:
                try:
                    self.data.sendto(pkt, addr)
                except OSError:
                    continue
            if self.truth is not None and row >= 0:
                self.truth.sent_ns[row] = time.monotonic_ns()
