"""Session times of a recording: decode it, find the timer, build the time base, write CSV.

The first step of the processing of a recording; ``spotlab export --timestamps`` and
``spotlab replay`` use it (:func:`spotlab.acquisition.timebase.session_timebase` does the
numerics).
"""

from __future__ import annotations

import csv
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spotlab.acquisition._replay_engine import Walk
from spotlab.acquisition.timebase import (
    DeviceFrames,
    SessionTimebase,
    TimerFrames,
    session_timebase,
)
from spotlab.core.errors import RecordingError
from spotlab.core.frames import FrameBlock
from spotlab.core.streams import StreamSpec
from spotlab.drivers.timer import extract_edges
from spotlab.io.journal import JournalReader, is_journal
from spotlab.processing.decoding import decoder_for
from spotlab.processing.errors import InputError

TIMER_FAMILY = "timer"
#: Session metadata key of the timer's input wiring (stream name -> input), written by
#: ``spotlab record --lab/--wiring``.
WIRING_KEY = "timer_wiring"


@dataclass(frozen=True)
class DecodedStreams:
    """Every decoded block of every stream of a recording, by stream name.

    Attributes
    ----------
    blocks : dict of str to list of FrameBlock
        In recording order.
    metadata : dict of str to dict
        The stream's metadata (family, spec, ...), as last announced.
    """

    blocks: dict[str, list[FrameBlock]]
    metadata: dict[str, dict[str, object]]


def decode_streams(path: str | os.PathLike[str]) -> DecodedStreams:
    """Decode every block of every stream of a recording (damaged blocks skipped), the
    streams in the journal's order (the order the devices were given).

    Raises
    ------
    InputError
        If the recording holds no decoded frames.
    """
    blocks: dict[str, list[FrameBlock]] = {}
    meta: dict[str, dict[str, object]] = {}
    index: dict[str, int] = {}
    for kind, state, block in Walk(Path(path), decoder_for, strict=False).steps():
        if kind == "block" and block is not None:
            blocks.setdefault(state.name, []).append(block)
            meta[state.name] = state.metadata
            index[state.name] = state.index
    if not blocks:
        raise InputError(f"{path}: the recording holds no decoded frames")
    # In the journal's stream order (the order the devices were given), not the order
    # their first frames came in: a rig's cameras follow the former.
    order = sorted(blocks, key=index.__getitem__)
    return DecodedStreams({n: blocks[n] for n in order}, {n: meta[n] for n in order})


def read_streams(
    path: str | os.PathLike[str], decoded: DecodedStreams | None = None
) -> tuple[list[DeviceFrames], TimerFrames | None, dict[str, StreamSpec]]:
    """Decode every stream of a recording into frame arrays (timer edges apart).

    ``decoded``: the recording already decoded by :func:`decode_streams` (not again).

    Raises
    ------
    InputError
        If the recording holds no decoded frames, or several timer streams.
    """
    decoded = decode_streams(path) if decoded is None else decoded
    blocks, meta = decoded.blocks, decoded.metadata
    devices: list[DeviceFrames] = []
    timers: list[TimerFrames] = []
    specs: dict[str, StreamSpec] = {}
    for name, bl in blocks.items():
        spec_d = meta[name].get("spec")
        if not isinstance(spec_d, dict):
            raise InputError(f"{path}: stream {name!r} has no spec in its metadata")
        spec = StreamSpec.from_dict(spec_d)
        specs[name] = spec
        seq, ticks, arrival = (
            np.concatenate([getattr(b, f) for b in bl]) for f in ("seq", "ticks", "arrival_ns")
        )
        if meta[name].get("family") == TIMER_FAMILY:
            edges = extract_edges(bl)
            timers.append(
                TimerFrames(
                    name, seq, ticks, arrival,
                    edges.input, edges.edge_index, edges.tick, edges.rising,
                )
            )  # fmt: skip
        else:
            devices.append(DeviceFrames(name, seq, ticks, arrival, spec))
    if len(timers) > 1:
        raise InputError(
            f"{path}: several timer streams ({', '.join(t.name for t in timers)}); "
            "one timer is the session's reference"
        )
    return devices, (timers[0] if timers else None), specs


def recorded_wiring(path: str | os.PathLike[str]) -> dict[str, int]:
    """The timer wiring stored in a recording's session metadata (empty if none)."""
    try:
        session = JournalReader(path).session
    except RecordingError as exc:
        raise InputError(str(exc)) from None
    stored = session.get(WIRING_KEY)
    if not isinstance(stored, dict):
        return {}
    return {
        str(k): int(v) for k, v in stored.items() if isinstance(v, int) and not isinstance(v, bool)
    }


def recorded_rig(path: str | os.PathLike[str]) -> Path | None:
    """The rig of the lab file a recording was made with (``spotlab record --lab``), or
    None when it names none or is not a recording."""
    if not is_journal(path):
        return None
    try:
        lab = JournalReader(path).session.get("lab")
    except RecordingError:
        return None
    rig = lab.get("rig") if isinstance(lab, dict) else None
    return Path(rig) if isinstance(rig, str) and rig else None


def calibration_for(path: str | os.PathLike[str], given: Path | None) -> Path:
    """``--calibration`` when given, else the rig the recording's lab file names.

    Raises
    ------
    InputError
        When neither gives one.
    """
    rig = given if given is not None else recorded_rig(path)
    if rig is None:
        raise InputError(
            f"{path}: reconstructing it needs --calibration RIG.toml (the recording names "
            "no rig: it was not made with a lab file that has one)"
        )
    return rig


def effective_wiring(
    path: str | os.PathLike[str], given: Mapping[str, int] | None
) -> dict[str, int] | None:
    """``--wiring`` when given, else the recording's stored wiring, else None (found from
    the edges)."""
    if given:
        return dict(given)
    return recorded_wiring(path) or None


def recording_timebase(
    path: str | os.PathLike[str], wiring: Mapping[str, int] | None = None
) -> SessionTimebase:
    """The session time base of a recording (see :func:`session_timebase`); without
    ``wiring``, the wiring the recording stores (:func:`recorded_wiring`) is used."""
    devices, timer, _ = read_streams(path)
    return session_timebase(devices, timer, effective_wiring(path, wiring))


def write_timestamps(path: Path, timebase: SessionTimebase) -> int:
    """Write one row per frame: stream, seq, time_s, device_ticks, method. Returns rows."""
    rows = 0
    with open(path, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(["stream", "seq", "time_s", "device_ticks", "method"])
        for s in timebase.streams.values():
            for seq, t, tick, m in zip(
                s.seq.tolist(), s.time_s.tolist(), s.ticks.tolist(), s.method.tolist(), strict=True
            ):
                out.writerow([s.name, seq, "nan" if not np.isfinite(t) else f"{t:.9f}", tick, m])
                rows += 1
    return rows
