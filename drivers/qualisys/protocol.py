"""The host side of Qualisys' QTM real-time protocol: packets, data frames, parameters.

Written from ``docs/protocols/qualisys.md`` (Qualisys' protocol, version 1.25,
little-endian; not from the simulator). A packet is ``uint32 size`` (header
included), ``uint32 type``, then the body; :class:`PacketSplitter` cuts them
out of the TCP byte stream, :func:`parse_data` reads a Data packet's header and
components, the ``*_from`` functions read one component, and
:func:`parse_parameters` the parameters XML.
"""

from __future__ import annotations

import struct
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from spotlab.core.errors import ProtocolError

F64 = npt.NDArray[np.float64]

#: Packet types (qualisys.md §2).
ERROR, COMMAND, XML, DATA, NO_MORE_DATA, C3D_FILE, EVENT, DISCOVER, QTM_FILE = range(9)
PACKET_NAMES = ("Error", "Command", "XML", "Data", "NoMoreData", "C3D", "Event", "Discover", "QTM")
#: Component types (qualisys.md §4).
COMP_3D, COMP_3D_NO_LABELS, COMP_6D, COMP_2D = 1, 2, 5, 7
#: Event names (qualisys.md §5).
EVENTS = {
    1: "connected", 2: "connection closed", 3: "capture started", 4: "capture stopped",
    6: "calibration started", 7: "calibration stopped", 8: "RT from file started",
    9: "RT from file stopped", 10: "waiting for trigger", 11: "camera settings changed",
    12: "QTM shutting down", 13: "capture saved", 16: "trigger",
}  # fmt: skip
HEADER = struct.Struct("<II")
_DATA_HEAD = struct.Struct("<qII")
_COUNTS = struct.Struct("<Ihh")
#: Largest packet the host accepts: a bigger size is a damaged or foreign stream.
MAX_PACKET = 64 << 20
#: QTM's little-endian real-time port (qualisys.md §1).
DEFAULT_PORT = 22223
PROTOCOL_VERSION = "1.25"


def command_packet(text: str) -> bytes:
    """A Command packet: ``text`` and its NUL."""
    body = text.encode() + b"\0"
    return HEADER.pack(HEADER.size + len(body), COMMAND) + body


@dataclass(frozen=True)
class Packet:
    """One packet: its type and body (header removed)."""

    kind: int
    body: bytes

    @property
    def text(self) -> str:
        """The body of an Error, Command or XML packet, NUL removed."""
        return self.body.rstrip(b"\0").decode("utf-8", "replace")


class PacketSplitter:
    """Packets out of a byte stream, from any split of it.

    Attributes
    ----------
    bad_bytes : int
        Bytes dropped because no plausible header started there.
    resyncs : int
        Runs of dropped bytes.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.bad_bytes = 0
        self.resyncs = 0

    @property
    def pending(self) -> int:
        """Bytes buffered, waiting for the rest of their packet."""
        return len(self._buf)

    def feed(self, data: bytes) -> list[Packet]:
        """The packets completed by ``data``."""
        self._buf += data
        out: list[Packet] = []
        dropping = False
        while len(self._buf) >= HEADER.size:
            size, kind = HEADER.unpack_from(self._buf)
            if not HEADER.size <= size <= MAX_PACKET or kind > QTM_FILE:
                del self._buf[:1]
                self.bad_bytes += 1
                if not dropping:
                    self.resyncs += 1
                dropping = True
                continue
            dropping = False
            if len(self._buf) < size:
                break
            out.append(Packet(kind, bytes(self._buf[HEADER.size : size])))
            del self._buf[:size]
        return out

    def clear(self) -> None:
        """Forget a partial packet (the connection it came on is gone)."""
        self._buf.clear()


@dataclass(frozen=True)
class DataFrame:
    """A Data packet: QTM's timestamp (µs), frame number, components by type."""

    timestamp_us: int
    frame: int
    components: dict[int, bytes]


def parse_data(body: bytes) -> DataFrame:
    """Read a Data packet's body (qualisys.md §4).

    Raises
    ------
    ProtocolError
        If the components do not fill the body exactly.
    """
    if len(body) < _DATA_HEAD.size:
        raise ProtocolError(f"a QTM data packet of {len(body)} bytes has no frame header")
    ts, frame, count = _DATA_HEAD.unpack_from(body)
    pos, comps = _DATA_HEAD.size, {}
    for _ in range(count):
        if pos + HEADER.size > len(body):
            raise ProtocolError(f"QTM frame {frame}: component header beyond the packet")
        size, kind = HEADER.unpack_from(body, pos)
        if size < HEADER.size or pos + size > len(body):
            raise ProtocolError(f"QTM frame {frame}: component {kind} of {size} bytes overruns")
        comps[kind] = body[pos + HEADER.size : pos + size]
        pos += size
    if pos != len(body):
        raise ProtocolError(f"QTM frame {frame}: {len(body) - pos} bytes after the components")
    return DataFrame(ts, frame, comps)


def _counted(comp: bytes, record: int, what: str, signed: bool = False) -> tuple[int, int]:
    if len(comp) < _COUNTS.size:
        raise ProtocolError(f"QTM {what} component of {len(comp)} bytes has no header")
    n = struct.unpack_from("<i" if signed else "<I", comp)[0]
    if n < 0 or _COUNTS.size + n * record != len(comp):
        raise ProtocolError(f"QTM {what} component: {n} items do not fill {len(comp)} bytes")
    return n, _COUNTS.size


def _f64(a: npt.NDArray[np.float32]) -> F64:
    """float32 from the wire to float64; a signalling NaN stays NaN, silently."""
    with np.errstate(invalid="ignore"):
        return a.astype(np.float64)


def markers_3d_from(comp: bytes) -> F64:
    """Labelled markers of a 3D component: (M, 3) mm, NaN where not seen."""
    n, off = _counted(comp, 12, "3D")
    return _f64(np.frombuffer(comp, "<f4", 3 * n, off).reshape(n, 3))


def markers_no_labels_from(comp: bytes) -> tuple[F64, npt.NDArray[np.int64]]:
    """Markers of a 3DNoLabels component: (K, 3) mm and their ids (K,)."""
    n, off = _counted(comp, 16, "3DNoLabels")
    rec = np.frombuffer(comp, [("xyz", "<f4", 3), ("id", "<u4")], n, off)
    return _f64(rec["xyz"]), rec["id"].astype(np.int64)


def bodies_6d_from(comp: bytes) -> tuple[F64, F64]:
    """Rigid bodies of a 6D component: positions (B, 3) mm, rotations (B, 3, 3) body to
    world (the matrix is sent column by column)."""
    n, off = _counted(comp, 48, "6D", signed=True)
    v = _f64(np.frombuffer(comp, "<f4", 12 * n, off).reshape(n, 12))
    return v[:, :3], v[:, 3:].reshape(n, 3, 3).transpose(0, 2, 1)


def markers_2d_from(comp: bytes) -> list[tuple[F64, F64]]:
    """Per camera of a 2D component: sub-pixel (K, 2) coordinates and (K, 2) diameters."""
    if len(comp) < _COUNTS.size:
        raise ProtocolError(f"QTM 2D component of {len(comp)} bytes has no header")
    (n_cams,) = struct.unpack_from("<I", comp)
    pos, out = _COUNTS.size, []
    for _ in range(n_cams):
        if pos + 5 > len(comp):
            raise ProtocolError("QTM 2D component: camera header beyond the component")
        k = struct.unpack_from("<i", comp, pos)[0]
        pos += 5
        if k < 0 or pos + 12 * k > len(comp):
            raise ProtocolError(f"QTM 2D component: {k} markers overrun the component")
        rec = np.frombuffer(comp, [("xy", "<i4", 2), ("d", "<u2", 2)], k, pos)
        out.append((rec["xy"].astype(np.float64), rec["d"].astype(np.float64)))
        pos += 12 * k
    return out


@dataclass(frozen=True)
class QtmParameters:
    """What the driver reads of QTM's parameters (qualisys.md §6)."""

    rate_hz: float
    labels: tuple[str, ...]
    bodies: tuple[str, ...] = ()
    cameras: int = 0
    extra: dict[str, str] = field(default_factory=dict)

    def to_dict(self) -> dict[str, object]:
        """JSON-safe form."""
        return {
            "rate_hz": self.rate_hz,
            "labels": list(self.labels),
            "bodies": list(self.bodies),
            "cameras": self.cameras,
        }


def parse_parameters(xml: str) -> QtmParameters:
    """Frequency, labels, bodies and cameras of a ``GetParameters All`` document.

    Raises
    ------
    ProtocolError
        If the document is not XML or lacks the frequency.
    """
    if "<!DOCTYPE" in xml or "<!ENTITY" in xml:
        raise ProtocolError("QTM parameters hold a DOCTYPE or ENTITY: refused (QTM sends none)")
    try:
        root = ET.fromstring(xml)  # noqa: S314 (no DTD, hence no entity expansion)
    except ET.ParseError as exc:
        raise ProtocolError(f"QTM parameters are not XML: {exc}") from None
    freq = root.findtext("General/Frequency")
    try:
        rate = float(freq or "")
    except ValueError:
        raise ProtocolError(
            f"QTM parameters give no frequency (General/Frequency={freq!r})"
        ) from None
    labels = tuple((e.text or "").strip() for e in root.findall("The_3D/Label/Name"))
    bodies = tuple((e.text or "").strip() for e in root.findall("The_6D/Body/Name"))
    return QtmParameters(rate, labels, bodies, len(root.findall("General/Camera")))
