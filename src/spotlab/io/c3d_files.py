"""Reading C3D files: any processor format (Intel, DEC, MIPS), integer or float storage.

The header and the parameter section are parsed here (:mod:`spotlab.io.c3d_header`,
:mod:`spotlab.io.c3d_parameters`); the frame data are decoded with whole-array numpy
work. No third-party C3D package is needed. Writing is in :mod:`spotlab.io.c3d_writer`.
See docs/files.md for the conventions (units, missing data, long trials, what is
tolerated in real files).
"""

from __future__ import annotations

import os
import struct
from pathlib import Path
from typing import Any

import numpy as np

from spotlab.io.c3d_header import C3DHeader, parse_header, read_processor
from spotlab.io.c3d_parameters import (
    C3DParameters,
    ParameterValueError,
    dec_to_ieee,
    parse_parameters,
)
from spotlab.io.trial import MM_PER_UNIT, FileFormatError, Trial

UINT16_MAX = 65535
#: Largest parameter section: its block count is one byte.
MAX_PARAMETER_BLOCKS = 255


class _Lookup:
    """Typed parameter values; every value that cannot be read is named in ``failures``."""

    def __init__(self, params: C3DParameters) -> None:
        self.params = params
        self.failures: list[str] = []

    def __call__(self, key: str, kind: str) -> Any:
        """A parameter's value, or None when absent or unreadable (then named in failures)."""
        param = self.params.get(key)
        if param is None or not param.data:
            return None  # absent, or present with no values (EVENT:TIMES when USED is 0)
        try:
            return _value(param, kind)
        except ParameterValueError as exc:
            self.failures.append(f"{key} ({exc})")
            return None

    def chained(self, group: str, name: str) -> list[str] | None:
        """NAME, NAME2, NAME3, ... joined: the way files store more than 255 labels."""
        first = self(f"{group}:{name}", "strings")
        if first is None:
            return None
        out = list(first)
        k = 2
        while (more := self(f"{group}:{name}{k}", "strings")) is not None:
            out += more
            k += 1
        return out


def _value(param: Any, kind: str) -> Any:
    if kind == "count":  # frame, point or channel counts: unsigned
        return param.count()
    if kind == "float":
        return float(param.floats()[0])
    if kind == "strings":
        return param.strings()
    if kind == "string":
        return " ".join(param.strings()).strip()
    if kind == "floats":
        return param.floats()
    if kind == "uint16s":
        return param.words(signed=False)
    if kind == "times":
        values = param.floats()
        return values[: len(values) // 2 * 2].reshape(-1, 2)
    raise AssertionError(kind)


def _frame_range(get: _Lookup, header: C3DHeader) -> tuple[int, int | None]:
    """First frame number and declared frame count (None: as many as the file holds)."""
    start_words = get("TRIAL:ACTUAL_START_FIELD", "uint16s")
    end_words = get("TRIAL:ACTUAL_END_FIELD", "uint16s")
    first = header.first_frame
    if start_words is not None and len(start_words) >= 2:
        first = int(start_words[0]) + int(start_words[1]) * 65536
    frames = get("POINT:FRAMES", "count")
    if frames is not None and 0 < frames < UINT16_MAX:
        return first, frames
    if end_words is not None and len(end_words) >= 2:
        end = int(end_words[0]) + int(end_words[1]) * 65536
        if end >= first:
            return first, end - first + 1
    long_frames = get("POINT:LONG_FRAMES", "count")
    if long_frames:
        return first, long_frames
    if frames == UINT16_MAX:
        return first, None
    return first, header.last_frame - header.first_frame + 1


def read_c3d_parameters(path: str | Path) -> tuple[C3DHeader, C3DParameters]:
    """The header and every parameter group of a C3D file, without its frames.

    Raises
    ------
    FileFormatError
        The file cannot be opened or has no C3D header and parameter section.
    """
    try:
        with open(path, "rb") as handle:
            return _read_metadata(path, handle)
    except OSError as exc:
        raise FileFormatError(path, f"cannot read the file: {exc.strerror or exc}") from exc


def _read_metadata(path: str | Path, handle: Any) -> tuple[C3DHeader, C3DParameters]:
    raw = handle.read(512)
    if len(raw) < 512 or raw[1] != 0x50 or raw[0] == 0:
        raise FileFormatError(path, "not a readable C3D file (no C3D header)")
    handle.seek((raw[0] - 1) * 512)
    section = handle.read(MAX_PARAMETER_BLOCKS * 512)
    # the section's length: its own block count, or up to the data when that says more
    # (a chain of records that runs on past both is cut there: sample02's SGI copies)
    blocks = section[2] if len(section) > 2 else 0
    mips = len(section) > 3 and section[3] == 86  # big-endian words
    data_block = struct.unpack(">H" if mips else "<H", raw[16:18])[0]
    if data_block > raw[0]:
        blocks = max(blocks, data_block - raw[0])
    section = section[: 512 * blocks] if blocks else section
    try:
        processor = read_processor(raw, section)
        params = parse_parameters(section, section[3])
    except ValueError as exc:
        raise FileFormatError(path, f"not a readable C3D file ({exc})") from exc
    return parse_header(raw, processor), params


def read_c3d(path: str | Path) -> Trial:
    """Read a C3D file (Intel, DEC or MIPS; integer or float storage).

    Points come back in millimetres (POINT:UNITS m and cm converted), NaN where the
    residual word is negative or a coordinate is not finite; analog channels with
    ANALOG:OFFSET, ANALOG:SCALE and ANALOG:GEN_SCALE applied. Every parameter group
    of the file is kept in ``metadata["c3d_parameters"]`` (a
    :class:`~spotlab.io.c3d_parameters.C3DParameters`), which
    :func:`~spotlab.io.c3d_writer.write_c3d` writes back.

    Raises
    ------
    FileFormatError
        The file cannot be opened, or its header, parameters or data are unusable.
    """
    try:
        with open(path, "rb") as handle:
            size = os.fstat(handle.fileno()).st_size
            header, params = _read_metadata(path, handle)
            # damaged words may be signalling NaNs or overflow when scaled: they
            # become NaN or infinite values (missing samples), not warnings
            with np.errstate(invalid="ignore", over="ignore"):
                return _decode(path, header, params, handle, size)
    except OSError as exc:
        raise FileFormatError(path, f"cannot read the file: {exc.strerror or exc}") from exc


def _decode(
    path: str | Path, header: C3DHeader, params: C3DParameters, handle: Any, size: int
) -> Trial:
    notes = list(params.notes)
    get = _Lookup(params)
    scale = get("POINT:SCALE", "float")
    if scale is None or scale == 0 or not np.isfinite(scale):
        scale = header.scale_factor
    if scale == 0 or not np.isfinite(scale):
        raise FileFormatError(path, "POINT:SCALE and the header scale factor are both 0")
    if abs(scale - header.scale_factor) > 1e-6 * abs(scale):
        scale = _settle_scale(scale, header.scale_factor, notes)
    is_float = scale < 0
    point_rate = get("POINT:RATE", "float") or header.frame_rate
    if not (point_rate > 0 and np.isfinite(point_rate)):
        raise FileFormatError(path, "no point rate (POINT:RATE and header frame rate are 0)")

    # Layout candidates (parameters first, then the header); the first that fits the file wins.
    used_param = get("POINT:USED", "count")
    markers = [m for m in (used_param, header.point_count) if m is not None]
    channels_param = get("ANALOG:USED", "count")
    analog_rate = get("ANALOG:RATE", "float")
    per_frame_header = header.analog_per_frame
    per_frame = per_frame_header
    if analog_rate and np.isfinite(analog_rate) and analog_rate > 0:
        per_frame = round(analog_rate / point_rate)
    if channels_param is None:
        channels_param = header.analog_count // per_frame_header if per_frame_header else 0
    channels = channels_param if per_frame > 0 else 0

    data_block = get("POINT:DATA_START", "count") or header.data_block
    if data_block != header.data_block and header.data_block > 0:
        notes.append(f"header data block {header.data_block} != POINT:DATA_START {data_block}")
        data_block = header.data_block
    if data_block < 1:
        raise FileFormatError(path, "no data start block (header word 9 and POINT:DATA_START)")
    offset = (data_block - 1) * 512
    available = max(size - offset, 0)
    word = 4 if is_float else 2
    first, declared = _frame_range(get, header)

    n_markers = markers[0]
    for m in markers:
        frame_bytes = (4 * m + channels * per_frame) * word
        if declared is None or frame_bytes * declared <= available:
            n_markers = m
            break
    if len(set(markers)) > 1:
        notes.append(f"header says {header.point_count} points, POINT:USED {used_param}")
    frame_bytes = (4 * n_markers + channels * per_frame) * word
    if frame_bytes == 0:
        raise FileFormatError(
            path,
            "the file holds no point or analog data (other groups, e.g. ROTATION, are not read)",
        )
    held = available // frame_bytes
    if declared is not None and declared <= 0:
        notes.append(f"{declared} frames declared (last frame before the first): read {held}")
        declared = None
    n_frames = held if declared is None else declared
    if n_frames > held:
        notes.append(f"{n_frames} frames declared, the file holds {held}: read {held}")
        n_frames = held
    if n_frames == 0:
        raise FileFormatError(
            path, f"the file holds no whole frame ({frame_bytes} bytes from block {data_block})"
        )

    handle.seek(offset)
    raw = handle.read(n_frames * frame_bytes)
    words_per_frame = frame_bytes // word
    big = params.processor == "MIPS"
    unsigned = (get("ANALOG:FORMAT", "string") or "").upper() == "UNSIGNED"
    if is_float:
        if params.processor == "DEC":
            values = dec_to_ieee(raw)
        else:
            values = np.frombuffer(raw, dtype=">f4" if big else "<f4")
        block = values.reshape(n_frames, words_per_frame)
        pts = block[:, : 4 * n_markers].reshape(n_frames, n_markers, 4).astype(np.float64)
        invalid = ~(pts[:, :, 3] > -1.0)  # a negative residual word (or NaN) marks a gap
        xyz = pts[:, :, :3]
        analog_raw = block[:, 4 * n_markers :].astype(np.float64)
    else:
        block_i = np.frombuffer(raw, dtype=">i2" if big else "<i2")
        block_i = block_i.reshape(n_frames, words_per_frame)
        pts_i = block_i[:, : 4 * n_markers].reshape(n_frames, n_markers, 4)
        invalid = pts_i[:, :, 3] < 0
        # scaled as the c3d package and ezc3d do, to float32: the integer and float
        # copies of one recording (sample01, sample02) then give identical values
        xyz = (pts_i[:, :, :3] * abs(scale)).astype(np.float32).astype(np.float64)
        analog_words = block_i[:, 4 * n_markers :]
        if unsigned:
            analog_words = analog_words.view(">u2" if big else "<u2")
        analog_raw = analog_words.astype(np.float64)
    invalid |= ~np.isfinite(xyz).all(axis=2)
    points = np.where(invalid[:, :, None], np.nan, xyz)

    unit_list = get("POINT:UNITS", "strings") or []
    file_units = unit_list[0].lower() if unit_list and unit_list[0] else ""
    units = "mm"
    if file_units in MM_PER_UNIT:
        points *= MM_PER_UNIT[file_units]
    elif file_units:
        units = file_units
        notes.append(f"POINT:UNITS {file_units!r} is not a length unit we convert: left as is")

    analog = analog_raw.reshape(n_frames * per_frame, channels) if channels else np.zeros((0, 0))
    if channels:
        analog = _scale_analog(get, analog, channels, unsigned, notes)
    labels = _labels(get.chained("POINT", "LABELS"), n_markers, "POINT")
    analog_labels = _labels(get.chained("ANALOG", "LABELS"), channels, "ANALOG")
    events = _events(get)
    if get.failures:
        notes.append(
            f"{len(get.failures)} parameter(s) could not be read and were taken as absent: "
            + "; ".join(get.failures)
        )
    return Trial(
        points=points,
        labels=labels,
        point_rate=float(point_rate),
        analog=analog,
        analog_labels=analog_labels,
        analog_rate=float(point_rate * per_frame) if channels else 0.0,
        first_frame=first,
        events=events if events else [(label, "", t) for label, t in header.events],
        units=units,
        metadata={
            "format": "c3d",
            "processor": params.processor,
            "storage": "float" if is_float else "integer",
            "point_scale": float(scale),
            "file_units": file_units,
            "header_events": list(header.events),
            "notes": notes,
            "unreadable_parameters": list(get.failures),
            "c3d_parameters": params,
            "point_kinds": _point_kinds(get),
        },
    )


#: POINT parameters listing the labels of points that are not markers (Vicon, pyCGM2:
#: model outputs stored as points), and the kind each stands for.
_NOT_MARKERS = {
    "ANGLES": "angle",
    "FORCES": "force",
    "MOMENTS": "moment",
    "POWERS": "power",
    "SCALARS": "scalar",
    "REACTIONS": "reaction",
    "MODELED_MARKERS": "modelled",
}


def _point_kinds(get: _Lookup) -> dict[str, str]:
    """Labels of points that are not measured markers (model outputs), and their kind:
    those listed by POINT:ANGLES, FORCES, MOMENTS, POWERS, SCALARS, MODELED_MARKERS and
    any other POINT parameter named in POINT:TYPE_GROUPS."""
    groups = dict(_NOT_MARKERS)
    named = get("POINT:TYPE_GROUPS", "strings") or []
    for name in named[::2]:
        groups.setdefault(name.upper(), name.lower())
    kinds: dict[str, str] = {}
    for key, kind in groups.items():
        for label in get(f"POINT:{key}", "strings") or []:
            if label:
                kinds.setdefault(label, kind)
    return kinds


def _settle_scale(parameter: float, in_header: float, notes: list[str]) -> float:
    """The point scale when POINT:SCALE and the header's copy disagree.

    Integer storage in both: the header's value, which the recording system wrote
    beside the data. The one shared file where they differ (MACsample, sample06)
    decides it: with the header's 0.05511 its markers are an adult's (foot 191 mm,
    shoulders 404 mm apart, shoulder marker up to 1.49 m, walking at 1.22 m/s); with
    POINT:SCALE 0.02154 they would be 0.39 times that (a 75 mm foot, a shoulder at
    0.58 m) - see docs/files.md. Otherwise (float storage, where the scale only
    gives the storage by its sign): the parameter, as the C3D manual says.
    """
    if parameter > 0 and in_header > 0 and np.isfinite(in_header):
        notes.append(
            f"header scale {in_header:g} used; POINT:SCALE says {parameter:g} "
            f"(x {parameter / in_header:.4g})"
        )
        return in_header
    notes.append(f"POINT:SCALE {parameter:g} used; the header says {in_header:g}")
    return parameter


def _scale_analog(
    get: _Lookup, analog: np.ndarray, channels: int, unsigned: bool, notes: list[str]
) -> np.ndarray:
    """``(raw - ANALOG:OFFSET) * ANALOG:SCALE * ANALOG:GEN_SCALE``, channel by channel.

    ANALOG:OFFSET is a 16-bit word whose sign follows the converter: unsigned when
    ANALOG:FORMAT says UNSIGNED, or when the samples themselves show an unsigned
    16-bit converter (float storage, none negative and some above 32767, as in
    sample07): a word stored as -32768 there is the converter's midpoint 32768.
    """

    def per_channel(values: np.ndarray | None, default: float) -> np.ndarray:
        out = np.full(channels, default)
        if values is not None and len(values):
            n = min(len(values), channels)
            out[:n] = values[:n]
        return out

    offsets = get("ANALOG:OFFSET", "floats")
    if offsets is not None and (offsets < 0).any():
        stored = get.params.get("ANALOG:OFFSET")
        from_data = bool(analog.size) and analog.min() >= 0 and analog.max() > 32767
        if stored is not None and stored.kind == 2 and (unsigned or from_data):
            offsets = np.where(offsets < 0, offsets + 65536.0, offsets)
            if not unsigned:
                notes.append(
                    "ANALOG:OFFSET read as unsigned 16-bit words: the analog samples lie in "
                    f"0..65535 (max {analog.max():g}), an unsigned converter's range"
                )
    scales = per_channel(get("ANALOG:SCALE", "floats"), 1.0)
    gen_scale = get("ANALOG:GEN_SCALE", "float")
    gen = 1.0 if gen_scale is None else gen_scale
    result: np.ndarray = (analog - per_channel(offsets, 0.0)) * (scales * gen)
    return result


def _labels(found: list[str] | None, n: int, group: str) -> list[str]:
    labels = list(found or [])[:n]
    labels += [f"{group}{i + 1}" for i in range(len(labels), n)]
    return labels


def _events(get: _Lookup) -> list[tuple[str, str, float]]:
    """The EVENT group's events as (label, context, time in s)."""
    events: list[tuple[str, str, float]] = []
    used = get("EVENT:USED", "count") or 0
    times = get("EVENT:TIMES", "times")
    labels = get("EVENT:LABELS", "strings") or []
    contexts = get("EVENT:CONTEXTS", "strings") or []
    if used and times is not None:
        for i in range(min(used, len(times))):
            label = labels[i] if i < len(labels) else ""
            context = contexts[i] if i < len(contexts) else ""
            events.append((label, context, float(times[i, 0] * 60.0 + times[i, 1])))
    return events
