"""Writing C3D files: Intel float, header and parameters built here, frames by numpy.

Every parameter group a read file brought (``trial.metadata["c3d_parameters"]``:
FORCE_PLATFORM, SUBJECTS, MANUFACTURER, PROCESSING, ...) is written back unless the
caller names it in ``drop``; the parameters that describe the data written (point and
analog layout, scales, rates, labels, frame range, events) are set from the trial.
See docs/files.md for what is written and how trials longer than 65 535 frames are stored.
"""

from __future__ import annotations

import copy
from collections.abc import Collection
from pathlib import Path

import numpy as np

from spotlab.io.c3d_header import C3DHeader, serialize_header
from spotlab.io.c3d_parameters import (
    C3DParameter,
    C3DParameters,
    make_parameter,
    serialize_parameters,
)
from spotlab.io.trial import FileFormatError, Trial

UINT16_MAX = 65535
#: Most entries one parameter can hold (its dimensions are bytes); more go to NAME2, ...
CHUNK = 255

#: Parameters rewritten from the trial: a copy brought by the file is replaced or removed.
_POINT_OWNED = ("USED", "SCALE", "RATE", "DATA_START", "FRAMES", "UNITS", "LONG_FRAMES")
_ANALOG_OWNED = ("USED", "RATE", "SCALE", "OFFSET", "GEN_SCALE", "FORMAT")
_PER_ENTRY = ("LABELS", "DESCRIPTIONS", "UNITS")  # one entry per point / channel (NAME2, ...)


def write_c3d(path: str | Path, trial: Trial, drop: Collection[str] = ()) -> None:
    """Write ``trial`` as an Intel float C3D file (points in mm, POINT:SCALE -1).

    Parameters
    ----------
    path : str or Path
    trial : Trial
        Points (mm), analog samples (physical units) and events; the parameter
        groups of the file it was read from, if any, in ``metadata["c3d_parameters"]``.
    drop : collection of str
        Group names (e.g. ``{"FORCE_PLATFORM"}``) not to write back.

    Notes
    -----
    Coordinates and analog samples are stored as float32; analog channels with
    ANALOG:SCALE 1, ANALOG:OFFSET 0 and GEN_SCALE 1 (the samples are already in
    physical units). Missing points (NaN) get residual -1, seen points residual 0.
    More than 65 535 frames: POINT:FRAMES 65535 with the true range in
    TRIAL:ACTUAL_START_FIELD / ACTUAL_END_FIELD (and POINT:LONG_FRAMES), the header's
    frame words capped.

    Raises
    ------
    FileFormatError
        The trial is inconsistent or not in mm, or the file cannot be written.
    """
    trial.check(path)
    if trial.units != "mm":
        raise FileFormatError(path, f"points must be in mm to be written, not {trial.units!r}")
    if trial.n_frames == 0:
        raise FileFormatError(path, "a C3D file needs at least one frame")
    params = _parameters(trial, {g.upper() for g in drop})
    header = C3DHeader(
        point_count=min(trial.n_markers, UINT16_MAX),
        analog_count=min(trial.analog.shape[1] * trial.analog_per_frame, UINT16_MAX),
        first_frame=min(max(trial.first_frame, 1), UINT16_MAX),
        last_frame=min(max(trial.first_frame, 1) + trial.n_frames - 1, UINT16_MAX),
        scale_factor=-1.0,
        analog_per_frame=trial.analog_per_frame,
        frame_rate=float(trial.point_rate),
    )
    try:
        section = _section(params, header)
    except ValueError as exc:
        raise FileFormatError(path, f"cannot write the parameters: {exc}") from exc
    block = _data_section(trial, trial.analog_per_frame, trial.analog.shape[1])
    pad = b"\x00" * (-block.nbytes % 512)
    try:
        with open(path, "wb") as handle:
            handle.write(serialize_header(header))
            handle.write(section)
            handle.write(block.data)  # C-contiguous: written without a copy
            handle.write(pad)
    except OSError as exc:
        raise FileFormatError(path, f"cannot write the file: {exc.strerror or exc}") from exc


def _section(params: C3DParameters, header: C3DHeader) -> bytes:
    """The parameter section, with POINT:DATA_START pointing just past it."""
    description = "First block of the data section"
    params.put(make_parameter("POINT", "DATA_START", 0, description))
    blocks = len(serialize_parameters(params)) // 512
    header.data_block = header.parameter_block + blocks
    params.put(make_parameter("POINT", "DATA_START", header.data_block, description))
    section = serialize_parameters(params)  # as long: DATA_START is one 16-bit word either way
    assert len(section) == 512 * blocks
    return section


def _parameters(trial: Trial, drop: set[str]) -> C3DParameters:
    """The file's groups (a copy) with everything that describes the data set from ``trial``."""
    brought = trial.metadata.get("c3d_parameters")
    params = copy.deepcopy(brought) if isinstance(brought, C3DParameters) else C3DParameters()
    params.notes, params.repeated = [], {}
    for group in drop:
        params.groups.pop(group, None)
        params.descriptions.pop(group, None)
    n_markers, channels = trial.n_markers, trial.analog.shape[1]
    for name in _POINT_OWNED:
        params.remove(f"POINT:{name}")
    _replace_entries(params, "POINT", n_markers, trial.labels)
    params.put(make_parameter("POINT", "USED", n_markers, "Number of 3D points"))
    params.put(make_parameter("POINT", "SCALE", -1.0, "3D scale factor (float storage)"))
    params.put(make_parameter("POINT", "RATE", float(trial.point_rate), "Frames per second"))
    params.put(make_parameter("POINT", "UNITS", "mm", "Units of the 3D points"))
    params.put(make_parameter("POINT", "FRAMES", min(trial.n_frames, UINT16_MAX), "Frames"))
    if trial.n_frames > UINT16_MAX:
        params.put(make_parameter("POINT", "LONG_FRAMES", float(trial.n_frames), "Frames"))

    for name in _ANALOG_OWNED:
        params.remove(f"ANALOG:{name}")
    _replace_entries(params, "ANALOG", channels, trial.analog_labels)
    if channels or "ANALOG" in params.groups:
        params.put(make_parameter("ANALOG", "USED", channels, "Number of analog channels"))
        params.put(make_parameter("ANALOG", "RATE", float(trial.analog_rate), "Samples/s"))
        params.put(make_parameter("ANALOG", "GEN_SCALE", 1.0, "General scale factor"))
        # written out per channel (ezc3d can crash on files that leave them empty)
        _put_chunked(params, "ANALOG", "SCALE", np.ones(channels, dtype=np.float32))
        _put_chunked(params, "ANALOG", "OFFSET", np.zeros(channels, dtype=np.int16))

    first = max(int(trial.first_frame), 1)
    last = first + trial.n_frames - 1
    for name, frame in (("ACTUAL_START_FIELD", first), ("ACTUAL_END_FIELD", last)):
        words = np.array([frame & 0xFFFF, frame >> 16], dtype=np.int64)  # low word first
        params.put(make_parameter("TRIAL", name, words, "Frame number (low, high word)"))
    _set_events(params, trial.events)
    return params


def _put_chunked(params: C3DParameters, group: str, name: str, values: object) -> None:
    """NAME holds the first 255 entries, NAME2 the next 255, ... (labels, scales, offsets)."""
    items = list(values) if isinstance(values, list) else np.asarray(values)
    n = len(items)
    for k, start in enumerate(range(0, max(n, 1), CHUNK)):
        chunk = items[start : start + CHUNK]
        if isinstance(chunk, list):
            value: object = [str(v) for v in chunk]
        else:
            value = chunk
        key = name if k == 0 else f"{name}{k + 1}"
        params.put(make_parameter(group, key, value, ""))


def _replace_entries(params: C3DParameters, group: str, n: int, labels: list[str]) -> None:
    """LABELS from the trial; DESCRIPTIONS (and ANALOG:UNITS) kept when they still fit.

    A description or unit list whose length is not the number of points or channels
    (the trial was edited) is replaced by blank entries.
    """
    members = params.groups.get(group, {})
    kept = {name: _entries(members, name) for name in ("DESCRIPTIONS", "UNITS")}
    for name in list(members):
        if name.rstrip("0123456789") in _PER_ENTRY:
            del members[name]
    if n == 0 and group not in params.groups:
        return
    _put_chunked(params, group, "LABELS", list(labels))
    for name in ("DESCRIPTIONS", "UNITS") if group == "ANALOG" else ("DESCRIPTIONS",):
        texts = kept[name]
        _put_chunked(params, group, name, texts if len(texts) == n else [" "] * n)


def _entries(members: dict[str, C3DParameter], name: str) -> list[str]:
    """The strings of NAME, NAME2, ... (empty when absent or not characters)."""
    texts: list[str] = []
    k = 1
    while (param := members.get(name if k == 1 else f"{name}{k}")) is not None:
        if param.kind != -1 or not param.data:
            break
        texts += param.strings()
        k += 1
    return texts


def _set_events(params: C3DParameters, events: list[tuple[str, str, float]]) -> None:
    """The EVENT group's USED, LABELS, CONTEXTS and TIMES from the trial's events."""
    for name in ("USED", "LABELS", "CONTEXTS", "TIMES"):
        params.remove(f"EVENT:{name}")
    if not events and "EVENT" not in params.groups:
        return
    params.put(make_parameter("EVENT", "USED", len(events), "Number of events"))
    if events:
        params.put(make_parameter("EVENT", "LABELS", [e[0] or " " for e in events], "Labels"))
        params.put(make_parameter("EVENT", "CONTEXTS", [e[1] or " " for e in events], "Contexts"))
        times = np.array([[t // 60.0, t - 60.0 * (t // 60.0)] for _, _, t in events])
        params.put(
            make_parameter(
                "EVENT", "TIMES", times.T.astype(np.float32), "Event times (minutes, seconds)"
            )
        )


def _data_section(trial: Trial, per_frame: int, channels: int) -> np.ndarray:
    """The C3D data section as one float32 array, built without a loop over frames.

    Returns
    -------
    ndarray, shape (F, 4 M + per_frame * channels), little-endian float32, C-contiguous
        Row f is frame f as the file stores it: x, y, z and the residual word of each
        marker (0, 0, 0 and -1 when any coordinate is not finite; residual 0 otherwise),
        then the frame's analog samples, sample by sample, channel by channel.
    """
    n_frames, n_markers = trial.n_frames, trial.n_markers
    block = np.empty((n_frames, 4 * n_markers + per_frame * channels), dtype="<f4")
    pts = block[:, : 4 * n_markers].reshape(n_frames, n_markers, 4)  # a view into block
    finite = np.isfinite(trial.points)
    missing = ~(finite[:, :, 0] & finite[:, :, 1] & finite[:, :, 2])
    pts[:, :, :3] = trial.points  # rounded to float32
    pts[:, :, 3] = 0.0
    pts[missing] = (0.0, 0.0, 0.0, -1.0)
    if channels:
        block[:, 4 * n_markers :] = trial.analog.reshape(n_frames, per_frame * channels)
    return block
