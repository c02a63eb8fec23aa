"""The server side of OptiTrack's NatNet bytes, written from docs/protocols/natnet.md.

NatNet is OptiTrack's protocol (Motive's data stream), not spotlab's: this module
encodes the subset our simulator serves — server info, model descriptions and
frames of data for NatNet 3.1 and 4.1 — exactly as the spec's tables (§3-§5) lay
them out. It is tested against the spec's golden vectors; the driver's decoder
(``spotlab.drivers.natnet``) is written separately from the same spec.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

F64 = npt.NDArray[np.float64]

NAT_CONNECT = 0
NAT_SERVERINFO = 1
NAT_REQUEST = 2
NAT_REQUEST_MODELDEF = 4
NAT_MODELDEF = 5
NAT_REQUEST_FRAMEOFDATA = 6
NAT_FRAMEOFDATA = 7
NAT_DISCONNECT = 9
NAT_KEEPALIVE = 10
NAT_UNRECOGNIZED_REQUEST = 100

#: Model-description dataset types (§4).
DESC_MARKER_SET = 0
DESC_RIGID_BODY = 1
DESC_CAMERA = 5

Version = tuple[int, int]
#: The NatNet versions this simulator serves.
VERSIONS: tuple[Version, ...] = ((3, 1), (4, 1))
#: Motive's version announced with each NatNet version (§3).
APP_VERSIONS: dict[Version, tuple[int, int, int, int]] = {
    (3, 1): (2, 2, 0, 0),
    (4, 1): (3, 1, 0, 0),
}

_HEAD = struct.Struct("<HH")


def packet(message_id: int, payload: bytes) -> bytes:
    """One NatNet packet: u16 message id, u16 payload size, payload (§1)."""
    if len(payload) > 0xFFFF:
        raise ValueError(f"a NatNet payload holds at most 65535 bytes, got {len(payload)}")
    return _HEAD.pack(message_id, len(payload)) + payload


def _cstr(text: str) -> bytes:
    return text.encode("utf-8") + b"\0"


def _sized(version: Version) -> bool:
    """Whether data sets carry their byte size (NatNet >= 4.1)."""
    return version >= (4, 1)


def _dataset(version: Version, count: int, items: bytes) -> bytes:
    head = struct.pack("<I", count)
    if _sized(version):
        head += struct.pack("<I", len(items))
    return head + items


def server_info(
    version: Version,
    *,
    name: str = "spotlab-natnet-sim",
    clock_hz: int = 10_000_000,
    data_port: int = 1511,
    multicast: bool = False,
    group: str = "239.255.42.99",
) -> bytes:
    """The ``NAT_SERVERINFO`` packet (§3): name, versions, clock, data port, multicast."""
    raw_name = name.encode("utf-8")
    if len(raw_name) > 255:
        raise ValueError("a NatNet application name holds at most 255 bytes")
    body = raw_name.ljust(256, b"\0")
    body += bytes(APP_VERSIONS.get(version, (0, 0, 0, 0)))
    body += bytes((version[0], version[1], 0, 0))
    body += struct.pack("<QHB", clock_hz, data_port, int(multicast))
    body += bytes(int(x) for x in group.split("."))
    return packet(NAT_SERVERINFO, body)


@dataclass(frozen=True)
class RigidBodyDescription:
    """A rigid body of the model descriptions (§4).

    Attributes
    ----------
    name : str
    id : int
    offsets_m : ndarray of float64, shape (n, 3)
        Its markers' places relative to the body's origin, in m.
    marker_names : tuple of str
    """

    name: str
    id: int
    offsets_m: F64
    marker_names: tuple[str, ...]


@dataclass(frozen=True)
class CameraDescription:
    """A camera of the model descriptions: name, position (m), quaternion (x, y, z, w)."""

    name: str
    position_m: tuple[float, float, float]
    quaternion: tuple[float, float, float, float]


def model_definitions(
    version: Version,
    marker_set: str,
    labels: Sequence[str],
    rigid_bodies: Sequence[RigidBodyDescription] = (),
    cameras: Sequence[CameraDescription] = (),
) -> bytes:
    """The ``NAT_MODELDEF`` packet (§4): one marker set, rigid bodies, cameras."""
    sets: list[tuple[int, bytes]] = []
    body = _cstr(marker_set) + struct.pack("<I", len(labels)) + b"".join(map(_cstr, labels))
    sets.append((DESC_MARKER_SET, body))
    for rb in rigid_bodies:
        off = np.asarray(rb.offsets_m, dtype="<f4").reshape(-1, 3)
        body = _cstr(rb.name) + struct.pack("<ii3f", rb.id, -1, 0.0, 0.0, 0.0)
        if version >= (4, 2):
            body += struct.pack("<4f", 0.0, 0.0, 0.0, 1.0)
        if version >= (3, 0):
            n = off.shape[0]
            body += struct.pack("<I", n) + off.tobytes()
            body += struct.pack(f"<{n}i", *range(1, n + 1))
            if version >= (4, 0):
                body += b"".join(map(_cstr, rb.marker_names))
        sets.append((DESC_RIGID_BODY, body))
    for cam in cameras:
        body = _cstr(cam.name) + struct.pack("<3f4f", *cam.position_m, *cam.quaternion)
        sets.append((DESC_CAMERA, body))
    out = struct.pack("<I", len(sets))
    for kind, body in sets:
        out += struct.pack("<I", kind)
        if _sized(version):
            out += struct.pack("<I", len(body))
        out += body
    return packet(NAT_MODELDEF, out)


@dataclass(frozen=True)
class RigidBodyPose:
    """A rigid body in one frame: id, position (m), quaternion (x, y, z, w), mean error (m)."""

    id: int
    position_m: tuple[float, float, float]
    quaternion: tuple[float, float, float, float]
    mean_error_m: float
    valid: bool = True


@dataclass(frozen=True)
class FrameContent:
    """What one ``NAT_FRAMEOFDATA`` carries (§5).

    Attributes
    ----------
    frame_number : int
    marker_set : str
        Name of the one marker set.
    markers_m : ndarray of float64, shape (M, 3)
        The marker set's markers (m), in the description's order.
    labelled_ids : sequence of int
        Id (``model << 16 | marker``) of each labelled marker; positions are ``markers_m``.
    timecode, timecode_sub : int
    timestamp_s : float
    stamps : tuple of 3 int
        Mid-exposure, data-received and transmit stamps (clock ticks).
    rigid_bodies : sequence of RigidBodyPose
    marker_size_m : float
    marker_params : int
    params : int
    """

    frame_number: int
    marker_set: str
    markers_m: F64
    labelled_ids: Sequence[int]
    timecode: int
    timecode_sub: int
    timestamp_s: float
    stamps: tuple[int, int, int]
    rigid_bodies: Sequence[RigidBodyPose] = field(default_factory=tuple)
    marker_size_m: float = 0.014
    marker_params: int = 0x0C
    params: int = 0


def frame_of_data(version: Version, f: FrameContent) -> bytes:
    """The ``NAT_FRAMEOFDATA`` packet of one frame in NatNet ``version`` (3.x or 4.x)."""
    xyz = np.asarray(f.markers_m, dtype="<f4").reshape(-1, 3)
    m = xyz.shape[0]
    if len(f.labelled_ids) != m:
        raise ValueError(f"{len(f.labelled_ids)} labelled ids for {m} markers")
    out = struct.pack("<i", f.frame_number)
    out += _dataset(version, 1, _cstr(f.marker_set) + struct.pack("<I", m) + xyz.tobytes())
    out += _dataset(version, 0, b"")  # legacy unlabelled markers
    rbs = b"".join(
        struct.pack("<i3f4ffh", r.id, *r.position_m, *r.quaternion, r.mean_error_m, int(r.valid))
        for r in f.rigid_bodies
    )
    out += _dataset(version, len(f.rigid_bodies), rbs)
    out += _dataset(version, 0, b"")  # skeletons
    if version >= (4, 1):
        out += _dataset(version, 0, b"")  # assets
    rec = struct.Struct("<i3ffhf" if version >= (3, 0) else "<i3ffh")
    tail = (0.0,) if version >= (3, 0) else ()
    labelled = b"".join(
        rec.pack(int(i), *map(float, p), f.marker_size_m, f.marker_params, *tail)
        for i, p in zip(f.labelled_ids, xyz, strict=True)
    )
    out += _dataset(version, m, labelled)
    out += _dataset(version, 0, b"")  # force plates
    out += _dataset(version, 0, b"")  # devices
    out += struct.pack("<IId", f.timecode, f.timecode_sub, f.timestamp_s)
    if version >= (3, 0):
        out += struct.pack("<QQQ", *f.stamps)
    if version[0] >= 4:
        out += struct.pack("<II", 0, 0)  # precision timestamp: not available
    out += struct.pack("<hi", f.params, 0)  # params, end-of-data tag
    return packet(NAT_FRAMEOFDATA, out)


def timecode(seconds: float, fps: int = 30) -> tuple[int, int]:
    """SMPTE timecode ``hh << 24 | mm << 16 | ss << 8 | ff`` of a time, and 0 subframe."""
    total = int(np.floor(seconds * fps + 1e-9))
    ff = total % fps
    s = total // fps
    return ((s // 3600) % 24) << 24 | ((s // 60) % 60) << 16 | (s % 60) << 8 | ff, 0


def parse_packet(data: bytes) -> tuple[int, bytes]:
    """``(message id, payload)`` of a client's packet; the payload is cut to its size.

    Raises
    ------
    ValueError
        If the packet is shorter than its header says.
    """
    if len(data) < _HEAD.size:
        raise ValueError("a NatNet packet has at least 4 bytes")
    message_id, size = _HEAD.unpack_from(data)
    if len(data) - _HEAD.size < size:
        raise ValueError(f"packet {message_id} says {size} bytes, holds {len(data) - 4}")
    return message_id, data[_HEAD.size : _HEAD.size + size]
