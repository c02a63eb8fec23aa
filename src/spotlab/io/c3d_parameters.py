"""The C3D parameter section, read and written here (no third-party parser).

A C3D file's parameter section holds groups (POINT, ANALOG, FORCE_PLATFORM, ...) of
typed parameters: characters, bytes, 16-bit integers or 32-bit floats, with up to 7
dimensions (the first varies fastest). :func:`parse_parameters` reads them in any
processor format (Intel, DEC, MIPS) into :class:`C3DParameter` values whose bytes are
converted to Intel (little-endian IEEE) order once, so a writer can copy them as they
are (:func:`serialize_parameters`).

Real files break the manual's rules; what is tolerated, and how, is said in
:func:`parse_parameters` and docs/files.md. Nothing is dropped silently: every record
skipped and every duplicate is a note.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field

import numpy as np

#: Processor codes of byte 4 of the parameter section (83 + n) and their names.
PROCESSORS = {84: "INTEL", 85: "DEC", 86: "MIPS"}

#: Element size in bytes of each parameter type code (-1 characters, 1 byte,
#: 2 16-bit integer, 4 32-bit float).
TYPE_SIZES = {-1: 1, 1: 1, 2: 2, 4: 4}


class ParameterValueError(ValueError):
    """A parameter's stored type or size does not fit the value asked for."""


def dec_to_ieee(raw: bytes | np.ndarray) -> np.ndarray:
    """DEC F-floats (VAX single precision) as IEEE float32.

    Parameters
    ----------
    raw : bytes or ndarray of uint8, length 4 N
        The floats as a DEC processor stores them.

    Returns
    -------
    ndarray, shape (N,), float32
        A DEC float's two 16-bit halves are stored high half first; swapped, the bits
        read as an IEEE float are 4 times the value (the exponent bias is 2 higher and
        the mantissa has no hidden leading 1 before the point). A DEC exponent of 0
        means 0.
    """
    words = np.frombuffer(bytes(raw), dtype="<u2").reshape(-1, 2)[:, ::-1]
    swapped = np.ascontiguousarray(words).view("<f4").ravel()
    zero = (words[:, 1] & 0x7F80) == 0
    with np.errstate(invalid="ignore", over="ignore"):  # NaN and infinite patterns stay so
        quarter = swapped / np.float32(4.0)
    return np.where(zero, np.float32(0.0), quarter).astype(np.float32)


def to_intel(raw: bytes, kind: int, processor: str) -> bytes:
    """Stored values of type ``kind`` converted from ``processor``'s order to Intel's."""
    if processor == "MIPS" and kind in (2, 4):
        return (
            np.frombuffer(raw, dtype=f">{'i2' if kind == 2 else 'f4'}")
            .astype(f"<{'i2' if kind == 2 else 'f4'}")
            .tobytes()
        )
    if processor == "DEC" and kind == 4:
        return dec_to_ieee(raw).astype("<f4").tobytes()
    return raw


@dataclass
class C3DParameter:
    """One parameter, its values in Intel byte order.

    Attributes
    ----------
    group, name : str
        Upper-case as the file spells them.
    kind : int
        -1 characters, 1 byte, 2 16-bit integer, 4 32-bit float.
    dims : tuple of int
        Dimensions, first varying fastest; () for a single value.
    data : bytes
        prod(dims) elements of ``kind``, little-endian.
    description : str
    locked : bool
        The file marks the parameter as not to be edited (negative name length).
    """

    group: str
    name: str
    kind: int
    dims: tuple[int, ...]
    data: bytes
    description: str = ""
    locked: bool = False

    @property
    def key(self) -> str:
        return f"{self.group}:{self.name}"

    def _need(self, *kinds: int) -> None:
        if self.kind not in kinds:
            raise ParameterValueError(f"{self.key} is of type {self.kind}, not {kinds}")
        if not self.data:
            raise ParameterValueError(f"{self.key} is empty")

    def floats(self) -> np.ndarray:
        """All values as float64, in storage order (numbers of any type)."""
        self._need(1, 2, 4)
        if self.kind == 4:
            return np.frombuffer(self.data, dtype="<f4").astype(np.float64)
        if self.kind == 2:
            return np.frombuffer(self.data, dtype="<i2").astype(np.float64)
        return np.frombuffer(self.data, dtype="<i1").astype(np.float64)

    def words(self, signed: bool) -> np.ndarray:
        """16-bit integer values (type 2) as int64, read signed or unsigned."""
        self._need(2)
        return np.frombuffer(self.data, dtype="<i2" if signed else "<u2").astype(np.int64)

    def count(self) -> int:
        """A count (frames, points, channels, blocks): the first value, unsigned.

        16-bit counts are unsigned (DATA_START 188 > 127, POINT:FRAMES up to 65535);
        a float count (some writers use one) is rounded; a byte count is unsigned too.
        """
        self._need(1, 2, 4)
        if self.kind == 2:
            return int(self.words(signed=False)[0])
        if self.kind == 1:
            return int(self.data[0])
        value = float(self.floats()[0])
        if not np.isfinite(value) or value < 0:
            raise ParameterValueError(f"{self.key} = {value} is not a count")
        return round(value)

    def strings(self) -> list[str]:
        """Character values as strings: one per column of the first dimension.

        Padding (spaces, NULs) is stripped. A 1-D character parameter is one string.
        """
        self._need(-1)
        width = self.dims[0] if self.dims else 1
        if width == 0:
            return []
        text = self.data.decode("latin-1")
        return [
            text[i : i + width].replace("\x00", " ").strip() for i in range(0, len(text), width)
        ]


@dataclass
class C3DParameters:
    """All groups of a parameter section, in file order.

    Attributes
    ----------
    groups : dict of str to dict of str to C3DParameter
        Group name to parameter name to parameter.
    descriptions : dict of str to str
        Group name to the group's description.
    processor : str
        "INTEL", "DEC" or "MIPS".
    notes : list of str
        What was tolerated while parsing (duplicates, skipped records, a section that
        ends early).
    repeated : dict of str to int
        ``GROUP:NAME`` of every parameter the file gives more than once, and how often.
    """

    groups: dict[str, dict[str, C3DParameter]] = field(default_factory=dict)
    descriptions: dict[str, str] = field(default_factory=dict)
    processor: str = "INTEL"
    notes: list[str] = field(default_factory=list)
    repeated: dict[str, int] = field(default_factory=dict)

    def get(self, key: str) -> C3DParameter | None:
        """The parameter ``GROUP:NAME``, or None when the file has none."""
        group, _, name = key.upper().partition(":")
        return self.groups.get(group, {}).get(name)

    def put(self, param: C3DParameter) -> None:
        """Add or replace a parameter (its group is made when missing)."""
        self.groups.setdefault(param.group, {})[param.name] = param
        self.descriptions.setdefault(param.group, "")

    def remove(self, key: str) -> None:
        group, _, name = key.upper().partition(":")
        self.groups.get(group, {}).pop(name, None)


def _int8(b: int) -> int:
    return b - 256 if b > 127 else b


def parse_parameters(section: bytes, processor_code: int) -> C3DParameters:
    """Parse a parameter section (from its 4-byte header to the end of what was read).

    Parameters
    ----------
    section : bytes
        The section as the file stores it, starting at its first byte; it may run
        past the section's end (the records say where they stop).
    processor_code : int
        Byte 4 of the section (84 Intel, 85 DEC, 86 MIPS).

    Returns
    -------
    C3DParameters

    Notes
    -----
    Tolerated, each with a note:

    * two groups with one name (Vicon Nexus writes an empty second PROCESSING group,
      sample33): their parameters are merged under the name;
    * a parameter given more than once in a group (113 PROCESSING parameters in
      sample33, up to 30 times): the **last** record wins. There the later records
      hold the newer values, and ezc3d keeps the last too, so both readers agree;
    * a parameter whose group id has no group record: kept under ``GROUPn``;
    * a record that does not fit the section, an unknown type code, a name that is not
      printable or a pointer that goes backwards (sample18's last "group": a 9-byte
      name of NULs and control bytes, pointer -1): parsing stops there and what was
      read so far is kept.

    Raises
    ------
    ValueError
        The processor code is not 84, 85 or 86.
    """
    if processor_code not in PROCESSORS:
        raise ValueError(f"unknown processor type {processor_code} in the parameter section")
    processor = PROCESSORS[processor_code]
    out = C3DParameters(processor=processor)
    big = processor == "MIPS"
    group_names: dict[int, str] = {}
    pending: list[tuple[int, C3DParameter]] = []
    seen_groups: set[int] = set()
    pos = 4
    end = len(section)
    while pos + 2 <= end:
        n_chars, gid = _int8(section[pos]), _int8(section[pos + 1])
        if n_chars == 0 or gid == 0:
            break  # the end of the section (or its zero padding)
        record = _record(section, pos, abs(n_chars), gid, big, processor)
        if record is None:
            out.notes.append(f"parameter section: record at byte {pos} is cut off; stopped there")
            break
        name, next_offset, body = record
        if next_offset < 0 or not name or not name.isprintable():
            out.notes.append(
                f"parameter section: damaged record at byte {pos} (name {name!r}, pointer "
                f"{next_offset}); stopped there"
            )
            break
        if gid < 0:
            group = name.upper()
            if -gid in seen_groups or group in group_names.values():
                out.notes.append(f"group {group} appears more than once: merged")
            seen_groups.add(-gid)
            group_names[-gid] = group
            out.descriptions.setdefault(group, str(body))
        elif isinstance(body, C3DParameter):
            body.locked = n_chars < 0
            body.name = name.upper()
            pending.append((gid, body))
        if next_offset == 0:
            break
        pos += 2 + abs(n_chars) + next_offset
    repeats: dict[str, int] = {}
    orphans: dict[int, int] = {}
    for gid, param in pending:
        group = group_names.get(gid, "")
        if not group:
            group = f"GROUP{gid}"
            orphans[gid] = orphans.get(gid, 0) + 1
        param.group = group
        out.descriptions.setdefault(group, "")
        if param.name in out.groups.get(group, {}):
            repeats[param.key] = repeats.get(param.key, 1) + 1
        out.put(param)
    if repeats:
        names = sorted(repeats, key=lambda k: (-repeats[k], k))
        shown = ", ".join(f"{k} x{repeats[k]}" for k in names[:3])
        more = f" and {len(names) - 3} more" if len(names) > 3 else ""
        out.notes.append(
            f"{len(repeats)} parameter(s) given more than once ({shown}{more}): "
            "the last record of each is used"
        )
    for gid, count in orphans.items():
        out.notes.append(
            f"{count} parameter(s) of group id {gid}, which has no group record: kept as GROUP{gid}"
        )
    out.repeated = repeats
    return out


def _record(
    section: bytes, pos: int, n: int, gid: int, big: bool, processor: str
) -> tuple[str, int, str | C3DParameter] | None:
    """Name, pointer to the next record and body (description or parameter) at ``pos``."""
    end = len(section)
    p = pos + 2
    if p + n + 2 > end:
        return None
    name = section[p : p + n].decode("latin-1").strip()
    p += n
    (next_offset,) = struct.unpack(">h" if big else "<h", section[p : p + 2])
    p += 2
    if gid < 0:
        if p >= end:
            return name, next_offset, ""
        length = section[p]
        return name, next_offset, section[p + 1 : p + 1 + length].decode("latin-1").strip()
    if p + 2 > end:
        return None
    kind, n_dims = _int8(section[p]), section[p + 1]
    p += 2
    if kind not in TYPE_SIZES or p + n_dims > end:
        return None
    dims = tuple(section[p : p + n_dims])
    p += n_dims
    size = TYPE_SIZES[kind] * math.prod(dims)
    if p + size > end:
        return None
    data = to_intel(section[p : p + size], kind, processor)
    p += size
    description = ""
    if p < end:
        length = section[p]
        description = section[p + 1 : p + 1 + length].decode("latin-1").strip()
    return name, next_offset, C3DParameter("", name, kind, dims, data, description)


def serialize_parameters(params: C3DParameters) -> bytes:
    """The parameter section of an Intel file, padded to whole 512-byte blocks.

    Groups are numbered 1, 2, ... in ``params.groups`` order; each group record is
    followed by its parameters. Byte 3 holds the number of blocks, byte 4 the Intel
    processor code 84.
    """
    body = bytearray()
    for gid, (group, members) in enumerate(params.groups.items(), start=1):
        body += _group_record(group, gid, params.descriptions.get(group, ""))
        for param in members.values():
            body += _param_record(param, gid)
    body += b"\x00\x00"  # a zero name length ends the section
    n_blocks = (4 + len(body) + 511) // 512
    if n_blocks > 255:
        raise ValueError(f"the parameters need {n_blocks} blocks, more than 255")
    out = bytes([1, 0x50, n_blocks, 84]) + bytes(body)
    return out + b"\x00" * (512 * n_blocks - len(out))


def _text(value: str, limit: int) -> bytes:
    raw = value.encode("latin-1", errors="replace")[:limit]
    return raw


def _group_record(name: str, gid: int, description: str) -> bytes:
    key = _text(name, 127)
    desc = _text(description, 255)
    tail = bytes([len(desc)]) + desc
    return bytes([len(key), 256 - gid]) + key + struct.pack("<h", 2 + len(tail)) + tail


def _param_record(param: C3DParameter, gid: int) -> bytes:
    key = _text(param.name, 127)
    desc = _text(param.description, 255)
    kind_byte = param.kind & 0xFF
    tail = bytes([kind_byte, len(param.dims), *param.dims]) + param.data + bytes([len(desc)]) + desc
    if 2 + len(tail) > 32767:
        raise ValueError(f"{param.key} holds {len(param.data)} bytes, too many for one record")
    n = len(key) if not param.locked else 256 - len(key)
    return bytes([n, gid]) + key + struct.pack("<h", 2 + len(tail)) + tail


def make_parameter(
    group: str, name: str, value: object, description: str = "", width: int | None = None
) -> C3DParameter:
    """A parameter from Python values.

    Parameters
    ----------
    value : str, list of str, int, float, or ndarray
        A str is one character parameter; a list of str is a 2-D one (padded to
        ``width`` or the longest); an int or an int16/uint16 array a 16-bit integer
        parameter; a float or a float array a float parameter (arrays keep their shape,
        stored first index fastest as C3D does, i.e. Fortran order).
    """
    if isinstance(value, str):
        raw = value.encode("latin-1", errors="replace")
        return C3DParameter(group, name, -1, (len(raw),), raw, description)
    if isinstance(value, list) and all(isinstance(v, str) for v in value):
        texts = [str(v).encode("latin-1", errors="replace") for v in value]
        w = width or max([1, *(len(t) for t in texts)])
        data = b"".join(t[:w].ljust(w) for t in texts)
        return C3DParameter(group, name, -1, (w, len(texts)), data, description)
    if isinstance(value, bool | int | np.integer):
        return C3DParameter(group, name, 2, (), struct.pack("<H", int(value) & 0xFFFF), description)
    if isinstance(value, float | np.floating):
        return C3DParameter(group, name, 4, (), struct.pack("<f", float(value)), description)
    arr = np.asarray(value)
    dims = tuple(int(d) for d in arr.shape)
    if arr.dtype.kind in "iu":
        data = (arr.astype(np.int64) & 0xFFFF).astype("<u2").tobytes(order="F")
        return C3DParameter(group, name, 2, dims, data, description)
    return C3DParameter(group, name, 4, dims, arr.astype("<f4").tobytes(order="F"), description)
