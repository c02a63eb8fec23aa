"""Reading OptiTrack NatNet packets (docs/protocols/natnet.md), written from the spec.

NatNet is OptiTrack's protocol, not spotlab's. This module reads the packet
header (§1), the server info (§3), the model descriptions (§4) and frames of
data (§5) of NatNet 3.x and 4.x, little-endian, and raises
:class:`NatNetFormatError` on anything malformed.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from spotlab.core.errors import ProtocolError

F64 = npt.NDArray[np.float64]

NAT_CONNECT = 0
NAT_SERVERINFO = 1
NAT_REQUEST = 2
NAT_RESPONSE = 3
NAT_REQUEST_MODELDEF = 4
NAT_MODELDEF = 5
NAT_FRAMEOFDATA = 7
NAT_MESSAGESTRING = 8
NAT_DISCONNECT = 9
NAT_KEEPALIVE = 10
NAT_UNRECOGNIZED_REQUEST = 100
#: Every message id of [SDK-T] a packet may carry.
MESSAGE_IDS = frozenset((0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 100))
#: NatNet major versions this reader knows.
MAJORS = (3, 4)

Version = tuple[int, int]
HEADER = struct.Struct("<HH")


class NatNetFormatError(ProtocolError):
    """A NatNet packet that does not parse as docs/protocols/natnet.md lays it out."""


def request(message_id: int, payload: bytes = b"") -> bytes:
    """A client's packet: header and payload."""
    return HEADER.pack(message_id, len(payload)) + payload


def connect_request() -> bytes:
    """``NAT_CONNECT`` as OptiTrack's sample client sends it: ``Ping``, zeros to 270 bytes
    (no NatNet version asked for), NUL (§2)."""
    return request(NAT_CONNECT, b"Ping".ljust(270, b"\0") + b"\0")


class Reader:
    """A cursor over a payload; every read checks the bytes are there."""

    def __init__(self, data: bytes) -> None:
        self.data = memoryview(data)
        self.pos = 0

    def take(self, fmt: str) -> tuple[float | int, ...]:
        s = struct.Struct("<" + fmt)
        if self.pos + s.size > len(self.data):
            raise NatNetFormatError(
                f"payload ends at {len(self.data)} bytes, needs {self.pos + s.size}"
            )
        out = s.unpack_from(self.data, self.pos)
        self.pos += s.size
        return tuple(out)

    def i32(self) -> int:
        return int(self.take("i")[0])

    def u32(self) -> int:
        return int(self.take("I")[0])

    def count(self, limit: int = 100_000) -> int:
        n = self.u32()
        if n > limit:
            raise NatNetFormatError(f"a count of {n} is beyond any NatNet frame")
        return n

    def floats(self, n: int) -> F64:
        if self.pos + 4 * n > len(self.data):
            raise NatNetFormatError(
                f"payload ends at {len(self.data)} bytes, needs {self.pos + 4 * n}"
            )
        with np.errstate(invalid="ignore"):  # a signalling NaN is a NaN
            x = np.frombuffer(self.data, "<f4", n, self.pos).astype(np.float64)
        self.pos += 4 * n
        return x

    def string(self) -> str:
        end = bytes(self.data[self.pos :]).find(b"\0")
        if end < 0:
            raise NatNetFormatError("a string has no terminating NUL")
        text = bytes(self.data[self.pos : self.pos + end]).decode("utf-8", "replace")
        self.pos += end + 1
        return text

    def skip(self, n: int) -> None:
        if n < 0 or self.pos + n > len(self.data):
            raise NatNetFormatError("a data-set size points beyond the payload")
        self.pos += n


def split_packet(data: bytes) -> tuple[int, bytes]:
    """``(message id, payload)`` of one packet.

    Raises
    ------
    NatNetFormatError
        If the header is short or unknown, or the payload shorter than it says.
    """
    if len(data) < HEADER.size:
        raise NatNetFormatError(f"a NatNet packet has a 4-byte header, got {len(data)} bytes")
    message_id, size = HEADER.unpack_from(data)
    if message_id not in MESSAGE_IDS:
        raise NatNetFormatError(f"unknown NatNet message id {message_id}")
    if len(data) - HEADER.size < size:
        raise NatNetFormatError(
            f"NatNet message {message_id} says {size} bytes, holds {len(data) - HEADER.size}"
        )
    return message_id, bytes(data[HEADER.size : HEADER.size + size])


@dataclass(frozen=True)
class ServerInfo:
    """The server's ``NAT_SERVERINFO`` (§3); the fields after the versions are 0 when absent."""

    name: str
    app_version: tuple[int, int, int, int]
    natnet_version: tuple[int, int, int, int]
    clock_hz: int = 0
    data_port: int = 0
    multicast: bool = False
    group: str = ""

    @property
    def version(self) -> Version:
        return self.natnet_version[0], self.natnet_version[1]


def parse_server_info(payload: bytes) -> ServerInfo:
    """Read a ``NAT_SERVERINFO`` payload (at least name and versions, 264 bytes)."""
    if len(payload) < 264:
        raise NatNetFormatError(f"server info holds 264 bytes at least, got {len(payload)}")
    name = payload[:256].split(b"\0", 1)[0].decode("utf-8", "replace")
    app = (payload[256], payload[257], payload[258], payload[259])
    nn = (payload[260], payload[261], payload[262], payload[263])
    if len(payload) < 279:
        return ServerInfo(name, app, nn)
    clock, port, mc = struct.unpack_from("<QHB", payload, 264)
    group = ".".join(str(b) for b in payload[275:279])
    return ServerInfo(name, app, nn, int(clock), int(port), bool(mc), group)


@dataclass(frozen=True)
class ModelDefinitions:
    """What ``NAT_MODELDEF`` described (§4): marker sets (name -> labels), rigid bodies
    (name -> id), camera names."""

    marker_sets: dict[str, tuple[str, ...]] = field(default_factory=dict)
    rigid_bodies: dict[str, int] = field(default_factory=dict)
    cameras: tuple[str, ...] = ()


def parse_model_definitions(payload: bytes, version: Version) -> ModelDefinitions:
    """Read a ``NAT_MODELDEF`` payload: marker sets, rigid bodies, cameras; other dataset
    types are skipped by their size (NatNet >= 4.1) and refused before."""
    r = Reader(payload)
    sets: dict[str, tuple[str, ...]] = {}
    bodies: dict[str, int] = {}
    cams: list[str] = []
    sized = version >= (4, 1)
    for _ in range(r.count(10_000)):
        kind = r.u32()
        size = r.u32() if sized else -1
        start = r.pos
        if kind == 0:
            name = r.string()
            sets[name] = tuple(r.string() for _ in range(r.count()))
        elif kind == 1:
            name = r.string()
            bodies[name] = r.i32()
            r.take("i3f")  # parent id, offset
            if version >= (4, 2):
                r.take("4f")
            n = r.count()
            r.floats(3 * n)
            r.take(f"{n}i")
            if version >= (4, 0):
                for _ in range(n):
                    r.string()
        elif kind == 5:
            cams.append(r.string())
            r.take("7f")
        elif sized:
            r.skip(size)
        else:
            raise NatNetFormatError(f"model description of type {kind} is not read before 4.1")
        if sized and r.pos - start != size:
            raise NatNetFormatError(f"model description of type {kind} is not {size} bytes")
    return ModelDefinitions(sets, bodies, tuple(cams))


@dataclass(frozen=True)
class FrameOfData:
    """One ``NAT_FRAMEOFDATA`` (§5).

    Attributes
    ----------
    frame_number : int
    marker_sets : dict of str to ndarray (n, 3)
        Positions in m, per marker set.
    labelled_ids : tuple of int
    labelled_m : ndarray of float64, shape (L, 3)
    labelled_params : tuple of int
    rigid_bodies : dict of int to ndarray (9,)
        Per id: x, y, z (m), qx, qy, qz, qw, mean error (m), tracking valid (1 or 0).
    timecode, timecode_sub : int
    timestamp_s : float
    stamps : tuple of 3 int
        Mid-exposure, data received, transmit (0 before NatNet 3).
    params : int
    """

    frame_number: int
    marker_sets: dict[str, F64]
    labelled_ids: tuple[int, ...]
    labelled_m: F64
    labelled_params: tuple[int, ...]
    rigid_bodies: dict[int, F64]
    timecode: int
    timecode_sub: int
    timestamp_s: float
    stamps: tuple[int, int, int]
    params: int


def _rigid_body(r: Reader, version: Version) -> tuple[int, F64]:
    rb_id = r.i32()
    pose = r.floats(7)
    if version < (3, 0):
        n = r.count()
        r.floats(3 * n)
        r.take(f"{n}i{n}f")
    err = r.floats(1)
    (params,) = r.take("h")
    valid = np.array([float(int(params) & 0x01)])  # bit 0: tracking valid
    return rb_id, np.concatenate([pose, err, valid])


def _channels(r: Reader) -> None:
    r.i32()
    for _ in range(r.count()):
        r.floats(r.count())


def parse_frame(payload: bytes, version: Version) -> FrameOfData:
    """Read a ``NAT_FRAMEOFDATA`` payload of NatNet ``version`` (3.x or 4.x)."""
    r = Reader(payload)
    sized = version >= (4, 1)

    def dataset() -> tuple[int, int]:
        n = r.count()
        size = r.u32() if sized else -1
        return n, size

    number = r.i32()
    sets: dict[str, F64] = {}
    n, _ = dataset()
    for _ in range(n):
        name = r.string()
        sets[name] = r.floats(3 * r.count()).reshape(-1, 3)
    n, _ = dataset()
    r.floats(3 * n)  # legacy unlabelled markers
    bodies: dict[int, F64] = {}
    n, _ = dataset()
    for _ in range(n):
        rb_id, pose = _rigid_body(r, version)
        bodies[rb_id] = pose
    n, _ = dataset()
    for _ in range(n):  # skeletons
        r.i32()
        for _ in range(r.count()):
            _rigid_body(r, version)
    if sized:
        n, size = dataset()  # assets: read by their size
        r.skip(size)
    n, _ = dataset()
    rec = "i3ffhf" if version >= (3, 0) else "i3ffh"
    ids, pos, params = [], [], []
    for _ in range(n):
        v = r.take(rec)
        ids.append(int(v[0]))
        pos.append(v[1:4])
        params.append(int(v[5]) & 0xFFFF)
    for _ in range(2):  # force plates, devices
        n, _ = dataset()
        for _ in range(n):
            _channels(r)
    tc, sub, ts = r.take("IId")
    stamps = (0, 0, 0)
    if version >= (3, 0):
        a, b, c = r.take("QQQ")
        stamps = (int(a), int(b), int(c))
    if version[0] >= 4:
        r.take("II")  # precision timestamp
    (frame_params,) = r.take("h")
    labelled = np.asarray(pos, dtype=np.float64).reshape(-1, 3)
    return FrameOfData(
        number, sets, tuple(ids), labelled, tuple(params), bodies,
        int(tc), int(sub), float(ts), stamps, int(frame_params) & 0xFFFF,
    )  # fmt: skip
