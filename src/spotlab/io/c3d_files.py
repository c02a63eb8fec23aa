"""Reading C3D files: any processor format (Intel, DEC, MIPS), integer or float storage.

The ``c3d`` package (optional dependency, extra ``c3d``) parses the header and the
parameter section; the frame data are decoded here with whole-array numpy work
instead of one Python call per frame. Writing is in :mod:`spotlab.io.c3d_writer`.
See docs/files.md for the conventions (units, missing data, long trials).
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from spotlab.io.trial import MM_PER_UNIT, FileFormatError, Trial

UINT16_MAX = 65535


def _import_c3d(path: str | Path) -> Any:
    try:
        import c3d
    except ImportError as exc:
        raise FileFormatError(
            path, "C3D support needs the 'c3d' package: pip install 'spotlab[c3d]'"
        ) from exc
    return c3d


def _clean(text: object) -> str:
    """A parameter string without its padding (spaces, and NULs some writers use)."""
    return str(text).replace("\x00", " ").strip()


def _param(reader: Any, key: str, kind: str) -> Any:
    """A parameter's value, or None when absent or unreadable."""
    param = reader.get(key)
    if param is None:
        return None
    try:
        if kind == "count":  # frame or point counts: 16-bit unsigned, or float when 4 bytes
            if param.bytes_per_element == 4:
                return int(param.float_value)
            return int(param.uint16_value)
        if kind == "float":
            return float(param.float_value)
        if kind == "strings":
            return [_clean(s) for s in np.ravel(param.string_array)]
        if kind == "string":
            return _clean(param.string_value)
        if kind == "floats":
            return np.asarray(param.float_array, dtype=np.float64).ravel()
        if kind == "int16s":
            return np.asarray(param.int16_array, dtype=np.float64).ravel()
        if kind == "uint16s":
            return np.asarray(param.uint16_array, dtype=np.int64).ravel()
        if kind == "times":
            return np.asarray(param.float_array, dtype=np.float64).reshape(-1, 2)
    except Exception:
        return None
    raise AssertionError(kind)


def _frame_range(reader: Any, header: Any) -> tuple[int, int | None]:
    """First frame number and declared frame count (None: as many as the file holds)."""
    start_words = _param(reader, "TRIAL:ACTUAL_START_FIELD", "uint16s")
    end_words = _param(reader, "TRIAL:ACTUAL_END_FIELD", "uint16s")
    first = int(header.first_frame)
    if start_words is not None and len(start_words) >= 2:
        first = int(start_words[0]) + int(start_words[1]) * 65536
    frames = _param(reader, "POINT:FRAMES", "count")
    if frames is not None and 0 < frames < UINT16_MAX:
        return first, frames
    if end_words is not None and len(end_words) >= 2:
        end = int(end_words[0]) + int(end_words[1]) * 65536
        if end >= first:
            return first, end - first + 1
    long_frames = _param(reader, "POINT:LONG_FRAMES", "count")
    if long_frames:
        return first, long_frames
    if frames == UINT16_MAX:
        return first, None
    return first, int(header.last_frame) - int(header.first_frame) + 1


def read_c3d(path: str | Path) -> Trial:
    """Read a C3D file (Intel, DEC or MIPS; integer or float storage).

    Points come back in millimetres (POINT:UNITS m and cm converted), NaN where the
    residual word is negative or a coordinate is not finite; analog channels with
    ANALOG:OFFSET, ANALOG:SCALE and ANALOG:GEN_SCALE applied.

    Raises
    ------
    FileFormatError
        The file cannot be opened, or its header, parameters or data are unusable.
    """
    c3d = _import_c3d(path)

    class _Reader(c3d.Reader):  # type: ignore[name-defined]
        def _check_metadata(self) -> None:
            """Header/parameter disagreements are resolved in read_c3d."""

    try:
        with open(path, "rb") as handle:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                reader = _Reader(handle)
            size = os.fstat(handle.fileno()).st_size
            return _decode(path, c3d, reader, handle, size, [str(w.message) for w in caught])
    except FileFormatError:
        raise
    except OSError as exc:
        raise FileFormatError(path, f"cannot read the file: {exc.strerror or exc}") from exc
    except Exception as exc:
        raise FileFormatError(
            path, f"not a readable C3D file ({type(exc).__name__}: {exc})"
        ) from exc


def _decode(
    path: str | Path, c3d: Any, reader: Any, handle: Any, size: int, notes: list[str]
) -> Trial:
    header = reader.header
    dtypes = reader._dtypes
    scale = _param(reader, "POINT:SCALE", "float")
    if scale is None or scale == 0:
        scale = float(header.scale_factor)
    if scale == 0:
        raise FileFormatError(path, "POINT:SCALE and the header scale factor are both 0")
    if abs(scale - float(header.scale_factor)) > 1e-6 * abs(scale):
        notes.append(f"POINT:SCALE {scale:g} used; the header says {header.scale_factor:g}")
    is_float = scale < 0
    point_rate = _param(reader, "POINT:RATE", "float") or float(header.frame_rate)
    if not point_rate > 0:
        raise FileFormatError(path, "no point rate (POINT:RATE and header frame rate are 0)")

    # Layout candidates (parameters first, then the header); the first that fits the file wins.
    used_param = _param(reader, "POINT:USED", "count")
    markers = [m for m in (used_param, int(header.point_count)) if m is not None]
    channels_param = _param(reader, "ANALOG:USED", "count")
    analog_rate = _param(reader, "ANALOG:RATE", "float")
    per_frame_header = int(header.analog_per_frame)
    per_frame = round(analog_rate / point_rate) if analog_rate else per_frame_header
    if channels_param is None:
        channels_param = int(header.analog_count) // per_frame_header if per_frame_header else 0
    channels = channels_param if per_frame > 0 else 0

    data_block = _param(reader, "POINT:DATA_START", "count") or int(header.data_block)
    if data_block != int(header.data_block) and int(header.data_block) > 0:
        notes.append(f"header data block {header.data_block} != POINT:DATA_START {data_block}")
        data_block = int(header.data_block)
    offset = (data_block - 1) * 512
    available = max(size - offset, 0)
    word = 4 if is_float else 2
    first, declared = _frame_range(reader, header)

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
    n_frames = held if declared is None else declared
    if n_frames > held:
        notes.append(f"{n_frames} frames declared, the file holds {held}: read {held}")
        n_frames = held

    handle.seek(offset)
    raw = handle.read(n_frames * frame_bytes)
    words_per_frame = frame_bytes // word
    if is_float:
        if dtypes.is_dec:
            values = np.asarray(c3d.c3d.DEC_to_IEEE_BYTES(raw), dtype=np.float32)
        else:
            values = np.frombuffer(raw, dtype=">f4" if dtypes.is_mips else "<f4")
        block = values.reshape(n_frames, words_per_frame)
        pts = block[:, : 4 * n_markers].reshape(n_frames, n_markers, 4).astype(np.float64)
        invalid = ~(pts[:, :, 3] > -1.0)  # a negative residual word (or NaN) marks a gap
        xyz = pts[:, :, :3]
        analog_raw = block[:, 4 * n_markers :].astype(np.float64)
    else:
        int_dtype = ">i2" if dtypes.is_mips else "<i2"
        block_i = np.frombuffer(raw, dtype=int_dtype).reshape(n_frames, words_per_frame)
        pts_i = block_i[:, : 4 * n_markers].reshape(n_frames, n_markers, 4)
        invalid = pts_i[:, :, 3] < 0
        # scaled as the c3d package and ezc3d do, to float32: the integer and float
        # copies of one recording (sample01, sample02) then give identical values
        xyz = (pts_i[:, :, :3] * abs(scale)).astype(np.float32).astype(np.float64)
        analog_words = block_i[:, 4 * n_markers :]
        if (_param(reader, "ANALOG:FORMAT", "string") or "").upper() == "UNSIGNED":
            analog_words = analog_words.view(">u2" if dtypes.is_mips else "<u2")
        analog_raw = analog_words.astype(np.float64)
    invalid |= ~np.isfinite(xyz).all(axis=2)
    points = np.where(invalid[:, :, None], np.nan, xyz)

    unit_list = _param(reader, "POINT:UNITS", "strings") or []
    file_units = unit_list[0].lower() if unit_list and unit_list[0] else ""
    units = "mm"
    if file_units in MM_PER_UNIT:
        points *= MM_PER_UNIT[file_units]
    elif file_units:
        units = file_units
        notes.append(f"POINT:UNITS {file_units!r} is not a length unit we convert: left as is")

    analog = analog_raw.reshape(n_frames * per_frame, channels) if channels else np.zeros((0, 0))
    if channels:
        analog = _scale_analog(reader, analog, channels)
    labels = _labels(_param(reader, "POINT:LABELS", "strings"), n_markers, "POINT")
    analog_labels = _labels(_param(reader, "ANALOG:LABELS", "strings"), channels, "ANALOG")
    events, header_events = _events(reader, header)
    return Trial(
        points=points,
        labels=labels,
        point_rate=float(point_rate),
        analog=analog,
        analog_labels=analog_labels,
        analog_rate=float(point_rate * per_frame) if channels else 0.0,
        first_frame=first,
        events=events if events else [(label, "", t) for label, t in header_events],
        units=units,
        metadata={
            "format": "c3d",
            "processor": str(reader.proc_type),
            "storage": "float" if is_float else "integer",
            "point_scale": float(scale),
            "file_units": file_units,
            "header_events": header_events,
            "notes": notes,
            "point_kinds": _point_kinds(reader),
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


def _point_kinds(reader: Any) -> dict[str, str]:
    """Labels of points that are not measured markers (model outputs), and their kind:
    those listed by POINT:ANGLES, FORCES, MOMENTS, POWERS, SCALARS, MODELED_MARKERS and
    any other POINT parameter named in POINT:TYPE_GROUPS."""
    groups = dict(_NOT_MARKERS)
    named = _param(reader, "POINT:TYPE_GROUPS", "strings") or []
    for name in named[::2]:
        groups.setdefault(name.upper(), name.lower())
    kinds: dict[str, str] = {}
    for key, kind in groups.items():
        for label in _param(reader, f"POINT:{key}", "strings") or []:
            if label:
                kinds.setdefault(label, kind)
    return kinds


def _scale_analog(reader: Any, analog: np.ndarray, channels: int) -> np.ndarray:
    def per_channel(values: np.ndarray | None, default: float) -> np.ndarray:
        out = np.full(channels, default)
        if values is not None and len(values):
            n = min(len(values), channels)
            out[:n] = values[:n]
        return out

    unsigned = (_param(reader, "ANALOG:FORMAT", "string") or "").upper() == "UNSIGNED"
    offsets = per_channel(_param(reader, "ANALOG:OFFSET", "uint16s" if unsigned else "int16s"), 0.0)
    scales = per_channel(_param(reader, "ANALOG:SCALE", "floats"), 1.0)
    gen_scale = _param(reader, "ANALOG:GEN_SCALE", "float")
    gen = 1.0 if gen_scale is None else gen_scale
    result: np.ndarray = (analog - offsets) * (scales * gen)
    return result


def _labels(found: list[str] | None, n: int, group: str) -> list[str]:
    labels = list(found or [])[:n]
    labels += [f"{group}{i + 1}" for i in range(len(labels), n)]
    return labels


def _events(
    reader: Any, header: Any
) -> tuple[list[tuple[str, str, float]], list[tuple[str, float]]]:
    events: list[tuple[str, str, float]] = []
    used = _param(reader, "EVENT:USED", "count") or 0
    times = _param(reader, "EVENT:TIMES", "times")
    labels = _param(reader, "EVENT:LABELS", "strings") or []
    contexts = _param(reader, "EVENT:CONTEXTS", "strings") or []
    if used and times is not None:
        for i in range(min(used, len(times))):
            label = labels[i] if i < len(labels) else ""
            context = contexts[i] if i < len(contexts) else ""
            events.append((label, context, float(times[i, 0] * 60.0 + times[i, 1])))
    header_events = [
        (str(label).strip(), float(t))
        for label, t in zip(header.event_labels, header.event_timings, strict=False)
    ]
    return events, header_events
