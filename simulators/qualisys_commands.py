"""The command dialogue of the simulated QTM (docs/protocols/qualisys.md §3): what each
client's command packets get back, and the streaming and control state they set.

:class:`QtmDialogue` is mixed into :class:`~spotlab.simulators.qualisys.QualisysServer`,
which keeps the connections, the frame clock and the faults.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from typing import TYPE_CHECKING

from spotlab.simulators import qualisys_wire as qw

if TYPE_CHECKING:
    from spotlab.simulators.qualisys_scene import QualisysScene, SceneFrame

#: Protocol versions the simulator speaks (the layouts of qualisys.md are 1.25's).
VERSIONS = ("1.25",)
QTM_VERSION = "QTM Version is 2024.2 (build 0000, spotlab simulator)"
#: Seconds between the reply to ``Start``/``Stop`` and the capture event (QTM's cameras
#: take time to start; a client that waits for the event after the reply sees it).
EVENT_DELAY_S = 0.05


@dataclass(eq=False)
class Client:
    """One connection: its writer, what it streams (``divisor`` 0: nothing) and its version."""

    writer: asyncio.StreamWriter
    components: tuple[str, ...] = ()
    divisor: int = 0  # 0: not streaming
    version: str = VERSIONS[-1]
    udp: tuple[str, int] | None = None  # where Data packets go by UDP (None: the TCP link)


class QtmDialogue:
    """Answers to the client's commands (the server provides the state named below)."""

    scene: QualisysScene
    state: int
    _clients: set[Client]
    _master: Client | None
    _frame: int
    _loop: asyncio.AbstractEventLoop | None

    @property
    def password(self) -> str | None:
        """The password ``TakeControl`` must give (None: any)."""
        raise NotImplementedError

    @property
    def versions(self) -> tuple[str, ...]:
        """Protocol versions a client may ask for."""
        raise NotImplementedError

    def _data(self, n: int, frame: SceneFrame, components: tuple[str, ...]) -> bytes:
        raise NotImplementedError

    def _anchor_faults(self) -> None:
        raise NotImplementedError

    def _reply(self, client: Client, text: str, kind: int = qw.COMMAND) -> None:
        client.writer.write(qw.text_packet(kind, text))

    def _error_reply(self, client: Client, text: str) -> None:
        self._reply(client, text, qw.ERROR)

    def _broadcast_event(self, event: int, delay_s: float = 0.0) -> None:
        if delay_s > 0 and self._loop is not None:
            self._loop.call_later(delay_s, self._broadcast_event, event)
            return
        self.state = event
        for c in self._clients:
            c.writer.write(qw.event_packet(event))

    def _handle(self, client: Client, packet: qw.ClientPacket) -> None:
        if packet.kind == qw.XML:
            self._error_reply(client, "Setting parameters is not supported by the simulator")
            return
        words = packet.text.split()
        if packet.kind != qw.COMMAND or not words:
            self._error_reply(client, "Parse error")
            return
        verb, args = words[0].lower(), words[1:]
        if verb == "version":
            if not args:
                self._reply(client, f"Version is {client.version}")
            elif args[0] in self.versions:
                client.version = args[0]
                self._reply(client, f"Version set to {args[0]}")
            else:
                self._error_reply(client, "Version NOT supported")
        elif verb == "qtmversion":
            self._reply(client, QTM_VERSION)
        elif verb == "byteorder":
            self._reply(client, "Byte order is little endian")
        elif verb == "getstate":
            client.writer.write(qw.event_packet(self.state))
        elif verb == "getparameters":
            self._parameters(client, [a.lower() for a in args])
        elif verb == "getcurrentframe":
            comps = self._components(client, args)
            if comps is not None:
                n = max(self._frame, 1)
                client.writer.write(self._data(n, self.scene.frame(n), comps))
        elif verb == "streamframes":
            self._stream(client, args)
        elif verb == "takecontrol":
            self._take_control(client, args)
        elif verb == "releasecontrol":
            if self._master is client:
                self._master = None
            self._reply(client, "You are now a regular client")
        elif verb in ("start", "stop"):
            if self._master is not client:
                self._error_reply(client, "You must be master to issue this command")
            elif verb == "start":
                self._reply(client, "Starting measurement")
                self._broadcast_event(qw.EV_CAPTURE_STARTED, EVENT_DELAY_S)
            else:
                self._reply(client, "Stopping measurement")
                self._broadcast_event(qw.EV_CAPTURE_STOPPED, EVENT_DELAY_S)
        else:
            self._error_reply(client, "Parse error")

    def _parameters(self, client: Client, args: list[str]) -> None:
        sections = set()
        for a in args:
            sections |= {"general", "3d", "6d"} if a == "all" else {a}
        known = sections & {"general", "3d", "6d"}
        if not args:
            self._error_reply(client, "Parse error")
            return
        self._reply(client, self.scene.parameters_xml(known), qw.XML)

    def _components(self, client: Client, names: list[str]) -> tuple[str, ...] | None:
        comps = tuple(n.lower() for n in names)
        unknown = [n for n in comps if n not in qw.COMPONENTS]
        if not comps or unknown:
            self._error_reply(
                client, f"Component {unknown[0] if unknown else '(none)'} is not supported"
            )
            return None
        return comps

    def _stream(self, client: Client, args: list[str]) -> None:
        if args and args[0].lower() == "stop":
            client.divisor = 0
            return
        if not args:
            self._error_reply(client, "Parse error")
            return
        how, _, value = args[0].lower().partition(":")
        rate = self.scene.rate_hz
        try:
            if how == "allframes":
                divisor = 1
            elif how == "frequency":
                divisor = max(1, round(rate / float(value)))
            elif how == "frequencydivisor":
                divisor = int(value)
            else:
                raise ValueError(how)
            if divisor < 1:
                raise ValueError(value)
        except (ValueError, ZeroDivisionError):
            self._error_reply(client, f"Parse error: {args[0]}")
            return
        rest = args[1:]
        udp = None
        if rest and rest[0].lower().startswith("udp:"):
            udp = self._udp_target(client, rest[0])
            if udp is None:
                return
            rest = rest[1:]
        comps = self._components(client, rest)
        if comps is None:
            return
        client.components, client.divisor, client.udp = comps, divisor, udp
        self._anchor_faults()

    def _udp_target(self, client: Client, arg: str) -> tuple[str, int] | None:
        """``UDP:PORT`` (to the address the command came from) or ``UDP:ADDR:PORT``."""
        parts = arg.split(":")[1:]
        peer = client.writer.get_extra_info("peername")
        host = parts[0] if len(parts) == 2 else (str(peer[0]) if peer else "127.0.0.1")
        try:
            port = int(parts[-1])
        except ValueError:
            port = -1
        if len(parts) not in (1, 2) or not 1 <= port <= 65535 or not host:
            self._error_reply(client, f"Parse error: {arg}")
            return None
        return host, port

    def _take_control(self, client: Client, args: list[str]) -> None:
        password = self.password
        if self._master is not None and self._master is not client:
            self._error_reply(client, "The client is already master")
        elif password is not None and (not args or args[0] != password):
            self._error_reply(client, "Wrong or missing password")
        else:
            self._master = client
            self._reply(client, "You are now master")
