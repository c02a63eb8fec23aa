"""Marker trajectories of a multi-device recording on the session time base.

``spotlab export REC --c3d OUT --calibration RIG.toml`` of a recording with a timer
stream (or with ``--sync``):

1. every frame of every stream gets its session time
   (:func:`spotlab.acquisition.timebase.session_timebase`, the timer's edges of the
   frame pulses; arrival stamps without a timer);
2. every ``image2d`` stream's readings (per marker and camera, NaN where unusable) are
   resampled at common session instants by the
   :class:`~spotlab.acquisition.synchroniser.Synchroniser`: each marker at its own slot
   time (frame time + (k + 1/2) slot, scaled by the stream's clock rate), cubic spline
   interpolation, never across a gap (lost frames, stalls, missing readings: NaN);
3. the cameras of all ``image2d`` streams are stacked in stream order (recording
   order): the calibration lists the cameras of the first stream, then those of the
   second, and so on (two 4-camera SELSPOT systems are one 8-camera rig). Marker ``m``
   of every stream is the same marker (its place in the stream's LED table);
4. every instant is triangulated (:func:`spotlab.processing.trajectories.reconstruct`).

The instants lie on the session grid ``k / rate`` (``rate``: the fastest stream's
nominal rate or ``--rate``), from the first instant at which every stream has begun to
the last at which none has ended, never before session time 0 (the timer's first
frame). The trial's ``first_frame`` is ``k + 1`` of its first instant, so that frame
``f`` is at session time ``(f - 1) / rate`` (C3D ``POINT:RATE`` and first frame; the
TRC ``Time`` column).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.acquisition.live.readings import pixels
from spotlab.acquisition.synchroniser import StreamInput, Synchroniser
from spotlab.acquisition.timebase import SessionTimebase, session_timebase
from spotlab.core.errors import SynchronisationError
from spotlab.core.streams import StreamSpec
from spotlab.geometry import Rig
from spotlab.processing.errors import InputError
from spotlab.processing.marker_observations import MarkerObservations
from spotlab.processing.progress import ProgressFactory
from spotlab.processing.session_times import (
    DecodedStreams,
    decode_streams,
    effective_wiring,
    read_streams,
)
from spotlab.processing.trajectories import (
    Reconstruction,
    load_rig,
    reconstruct,
    reconstruct_file,
)

__all__ = [
    "NO_TIMER_NOTE",
    "ImageStream",
    "OpenedRecording",
    "SynchronisedExport",
    "SynchronisedObservations",
    "export_synchronised",
    "has_timer",
    "image_streams",
    "open_recording",
    "reconstruct_recording",
    "synchronise_observations",
]

FloatArray = NDArray[np.float64]

#: Stream kind whose readings are triangulated.
IMAGE_KIND = "image2d"
#: What stderr says when a recording without a timer is reconstructed as before.
NO_TIMER_NOTE = (
    "no timer stream in the recording: the one stream is reconstructed by frame number at "
    "its nominal rate, not on session times (give --sync for host-arrival session times)"
)


@dataclass(frozen=True)
class ImageStream:
    """One ``image2d`` stream of a recording with its session times.

    Attributes
    ----------
    spec : StreamSpec
        The stream (name, nominal rate, slot period, markers, cameras).
    seq : ndarray of int64, shape (F,)
        Unwrapped sequence numbers.
    time_s : ndarray, shape (F,)
        Session time of each frame's first sample, s.
    uv : ndarray, shape (F, M, C, 2)
        Readings per frame, marker and camera (px or detector counts), NaN where
        unusable.
    clock_rate : float
        Session seconds per device second of the stream's clock.
    """

    spec: StreamSpec
    seq: NDArray[np.int64]
    time_s: FloatArray
    uv: FloatArray
    clock_rate: float = 1.0

    @property
    def name(self) -> str:
        """The stream's name."""
        return self.spec.name

    @property
    def n_cameras(self) -> int:
        """Cameras C of the stream."""
        return int(self.uv.shape[2])


@dataclass
class SynchronisedObservations:
    """Every camera of every image stream at common session instants.

    Attributes
    ----------
    times : ndarray, shape (T,)
        Session times of the instants, s (``(first_frame - 1 + j) / rate_hz``).
    uv : ndarray, shape (T, C, M, 2)
        Readings of the cameras of all streams, stacked in stream order; NaN where a
        stream has no value (outside its frames, in a gap, missing).
    rate_hz : float
        Rate of the instants, Hz.
    first_frame : int
        Number of the first instant on the session grid, counted from 1 at time 0.
    cameras : dict of str to int
        Cameras per stream, in stacking order.
    facts : dict
        JSON-safe figures per stream (frames, lost frames, time gaps, valid fraction).
    """

    times: FloatArray
    uv: FloatArray
    rate_hz: float
    first_frame: int
    cameras: dict[str, int]
    facts: dict[str, Any] = field(default_factory=dict)


def has_timer(decoded: DecodedStreams) -> bool:
    """Whether a decoded recording holds a timer stream."""
    return any(m.get("family") == "timer" for m in decoded.metadata.values())


def image_streams(
    decoded: DecodedStreams, timebase: SessionTimebase
) -> tuple[list[ImageStream], list[str]]:
    """The ``image2d`` streams of a decoded recording, with their session times.

    Returns
    -------
    streams : list of ImageStream
        In recording order; frames without a finite session time left out.
    notes : list of str
        Streams left out and why.
    """
    out: list[ImageStream] = []
    notes: list[str] = []
    for name, blocks in decoded.blocks.items():
        timing = timebase.streams.get(name)
        if timing is None or timing.spec is None:
            continue
        spec = timing.spec
        if spec.kind != IMAGE_KIND:
            if name != timebase.reference:
                notes.append(f"stream {name!r} ({spec.kind}) is not {IMAGE_KIND}: left out")
            continue
        data = np.concatenate([b.data for b in blocks]).astype(np.float64)
        flags = np.concatenate([b.flags for b in blocks])
        uv = pixels(spec, data, flags).transpose(0, 2, 1, 3)  # (F, M, C, 2)
        ok = np.isfinite(timing.time_s)
        if int(ok.sum()) < 2:
            notes.append(f"stream {name!r}: fewer than 2 frames with a session time: left out")
            continue
        out.append(ImageStream(spec, timing.seq[ok], timing.time_s[ok], uv[ok], timing.clock_rate))
    return out, notes


def synchronise_observations(
    streams: list[ImageStream],
    *,
    rate_hz: float | None = None,
    slot_correction: bool = True,
) -> SynchronisedObservations:
    """Resample every stream's readings at common session instants and stack the cameras.

    Parameters
    ----------
    streams : list of ImageStream
        At least one; marker counts may differ (missing markers are NaN).
    rate_hz : float, optional
        Rate of the instants; the fastest stream's nominal rate when omitted.
    slot_correction : bool
        Each marker at its slot time (true), or every marker at its frame's time (for
        comparison only: biases moving markers by speed times slot offset).

    Returns
    -------
    SynchronisedObservations

    Raises
    ------
    InputError
        No stream, a rate that is not positive, streams that do not overlap in session
        time after 0, or frames the synchroniser refuses (naming the stream).
    """
    if not streams:
        raise InputError(f"the recording holds no {IMAGE_KIND} stream to reconstruct")
    rate = max(s.spec.rate_hz for s in streams) if rate_hz is None else float(rate_hz)
    if not (np.isfinite(rate) and rate > 0):
        raise InputError(f"--rate must be a positive number of Hz, not {rate_hz}")
    try:
        sync = Synchroniser(
            [StreamInput(s.spec, s.seq, s.time_s, s.uv, s.clock_rate) for s in streams],
            slot_correction=slot_correction,
        )
        span = sync.instants(rate)
    except SynchronisationError as exc:
        raise InputError(str(exc)) from None
    # on the session grid k / rate, from session time 0 on
    k0 = max(int(np.ceil(span[0] * rate - 1e-9)), 0)
    k1 = int(np.floor(span[-1] * rate + 1e-9))
    if k1 < k0:
        raise InputError(
            "the streams hold no common instant after session time 0 "
            f"(their overlap ends at {span[-1]:.6f} s)"
        )
    times = np.arange(k0, k1 + 1) / rate
    result = sync.resample(times)
    n_markers = max(s.spec.n_markers for s in streams)
    parts = []
    facts: dict[str, Any] = {}
    for s in streams:
        r = result.streams[s.name]
        values = np.full((times.size, s.n_cameras, n_markers, 2), np.nan)
        values[:, :, : s.spec.n_markers] = r.values.transpose(0, 2, 1, 3)
        parts.append(values)
        st = result.stats[s.name]
        facts[s.name] = {
            "frames": st.n_frames,
            "cameras": s.n_cameras,
            "lost_frames": st.lost_frames,
            "time_gaps": st.time_gaps,
            "rate_hz": round(st.rate_hz, 6),
            "clock_rate": s.clock_rate,
            "valid_fraction": round(st.valid_fraction, 6),
        }
    return SynchronisedObservations(
        times=times,
        uv=np.concatenate(parts, axis=1),
        rate_hz=rate,
        first_frame=k0 + 1,
        cameras={s.name: s.n_cameras for s in streams},
        facts=facts,
    )


@dataclass(frozen=True)
class OpenedRecording:
    """A decoded recording with the session time of every frame of every stream.

    Attributes
    ----------
    path : Path
        The ``.spj`` recording.
    decoded : DecodedStreams
        Every decoded block of every stream.
    timebase : SessionTimebase
        The session time (s) of every frame of every stream, the clock report.
    streams : list of ImageStream
        The ``image2d`` streams with their readings on session time, in recording order.
    notes : list of str
        What the user should hear about: the time base's notes, then streams left out
        and why.
    """

    path: Path
    decoded: DecodedStreams
    timebase: SessionTimebase
    streams: list[ImageStream]
    notes: list[str]


def open_recording(
    recording: Path,
    *,
    wiring: Mapping[str, int] | None = None,
    decoded: DecodedStreams | None = None,
) -> OpenedRecording:
    """Decode a recording and put every frame of every stream on session time.

    Parameters
    ----------
    recording : Path
        The ``.spj`` recording.
    wiring : mapping of str to int, optional
        Timer input of each stream's frame pulses (the recording's stored wiring, else
        found from the timer's edges, when omitted).
    decoded : DecodedStreams, optional
        The recording already decoded (by :func:`decode_streams`).

    Returns
    -------
    OpenedRecording

    Raises
    ------
    InputError
        A recording without decoded frames, with several timer streams, or whose streams
        cannot be put on one time base.
    """
    decoded = decode_streams(recording) if decoded is None else decoded
    devices, timer, _ = read_streams(recording, decoded)
    try:
        timebase = session_timebase(devices, timer, effective_wiring(recording, wiring))
    except SynchronisationError as exc:
        raise InputError(f"{recording}: {exc}") from None
    streams, notes = image_streams(decoded, timebase)
    return OpenedRecording(recording, decoded, timebase, streams, [*timebase.notes, *notes])


def check_rig(rig: Rig, cameras: Mapping[str, int]) -> None:
    """The rig must hold exactly the stacked cameras of every stream.

    Raises
    ------
    InputError
        Naming the cameras per stream and the rig's count.
    """
    total = sum(cameras.values())
    if len(rig) != total:
        per = ", ".join(f"{name}: {n}" for name, n in cameras.items())
        raise InputError(
            f"the calibration has {len(rig)} cameras but the {IMAGE_KIND} streams have "
            f"{total} ({per}); list the cameras of each stream, in stream order"
        )


@dataclass
class SynchronisedExport:
    """A reconstruction on the session time base and what was noted on the way."""

    result: Reconstruction
    timebase: SessionTimebase
    notes: list[str]


def export_synchronised(
    recording: Path,
    calibration: Path,
    *,
    wiring: Mapping[str, int] | None = None,
    rate_hz: float | None = None,
    slot_correction: bool = True,
    method: str = "odle",
    decoded: DecodedStreams | None = None,
    progress: ProgressFactory | None = None,
) -> SynchronisedExport:
    """Reconstruct every ``image2d`` stream of a recording at common session instants.

    Parameters
    ----------
    recording, calibration : Path
        The ``.spj`` recording; the rig (TOML) with the cameras of every stream in
        stream order.
    wiring : mapping of str to int, optional
        Timer input of each stream's frame pulses (found from the recording otherwise).
    rate_hz : float, optional
        Rate of the instants (the fastest stream's nominal rate by default).
    slot_correction : bool
        See :func:`synchronise_observations`.
    method : str
        Triangulation estimator.
    decoded : DecodedStreams, optional
        The recording already decoded.
    progress : ProgressFactory, optional
        Makes the progress sink of the triangulation (none by default).

    Returns
    -------
    SynchronisedExport
        The trial's ``first_frame`` and ``point_rate`` place it on the session time
        (frame ``f`` at ``(f - 1) / rate`` s); its metadata holds ``session_start_s``.

    Raises
    ------
    InputError
        Unreadable inputs, no image stream, a rig whose camera count differs.
    """
    rig = load_rig(calibration)
    opened = open_recording(recording, wiring=wiring, decoded=decoded)
    timebase = opened.timebase
    obs = synchronise_observations(opened.streams, rate_hz=rate_hz, slot_correction=slot_correction)
    check_rig(rig, obs.cameras)
    facts: dict[str, Any] = {
        "session_reference": timebase.reference,
        "session_start_s": float(obs.times[0]),
        "first_frame": obs.first_frame,
        "slot_correction": slot_correction,
        "streams": obs.facts,
    }
    markers = MarkerObservations(obs.uv, obs.rate_hz, facts=facts)
    sink = progress("reconstructing", obs.times.size) if progress is not None else None
    result = reconstruct(rig, markers, method=method, progress=sink)
    result.trial.first_frame = obs.first_frame
    result.trial.metadata["session_start_s"] = float(obs.times[0])
    result.trial.metadata["session_reference"] = timebase.reference
    return SynchronisedExport(result, timebase, opened.notes)


def reconstruct_recording(
    recording: Path,
    calibration: Path,
    *,
    sync: bool = False,
    wiring: Mapping[str, int] | None = None,
    rate_hz: float | None = None,
    slot_correction: bool = True,
    progress: ProgressFactory | None = None,
) -> Reconstruction:
    """``spotlab export REC.spj --calibration``: on session times when the recording holds
    a timer stream or ``sync`` is set (:func:`export_synchronised`), else the one stream
    by frame number at its nominal rate (:func:`reconstruct_file`).

    What the user should hear about is in the result's ``notes`` (the command line
    prints them on stderr): for a recording without a timer, that it was reconstructed
    by frame number; else the warnings of the time base and the notes of each stream.
    """
    decoded = decode_streams(recording)
    if not (sync or has_timer(decoded)):
        result = reconstruct_file(recording, calibration, rate_hz=rate_hz, progress=progress)
        result.notes.append(f"note: {NO_TIMER_NOTE}")
        return result
    done = export_synchronised(
        recording,
        calibration,
        wiring=wiring,
        rate_hz=rate_hz,
        slot_correction=slot_correction,
        decoded=decoded,
        progress=progress,
    )
    done.result.notes += [f"warning: {note}" for note in done.notes]
    done.result.notes += [
        f"{timing.name}: {note}"
        for timing in done.timebase.streams.values()
        for note in timing.notes
    ]
    return done.result
