"""A video-centroid recording + calibration + marker model -> labelled trajectories.

The blob path of ``spotlab reconstruct`` and ``spotlab export`` (the SELSPOT path is
:mod:`spotlab.processing.trajectories`). A recording of one ``blobs2d`` stream (a CEN hub,
docs/protocols/centroid.md) holds unidentified blobs per camera and frame; they are
decoded with the stream's driver, joined into
:class:`~spotlab.drivers.centroid.BlobFrames`, and identified frame by frame with
:class:`~spotlab.reconstruction.identification.Identifier` (cameras the hub flagged
offline or overflowing are left out of their frame). Markers take the names of the
marker model: from ``--model MODEL.json`` when given, else the one ``spotlab record
--model`` stored in the recording (session metadata key ``marker_model``).

Frames are placed on the hub's frame grid by their camera frame counters (triggers
since ``START:``, the numbering of the simulator's truth ``frame_no``): the trial starts
at the first recorded frame (C3D ``first_frame`` = its number + 1, C3D counting from 1)
and a frame lost on the link stays a gap (NaN) in its place. Marker positions are NaN
where a marker was not labelled: a flagged gap, never a guess. The recording is
identified forward and backward in time and the two joined
(:mod:`spotlab.processing.identification_passes`).
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.acquisition.replay import replay
from spotlab.core.errors import ReconstructionError, RecordingError
from spotlab.core.frames import FrameBlock
from spotlab.core.wire import StreamDecoder
from spotlab.drivers.centroid import BLOB_MERGED, BlobFrames, blobs_from_blocks
from spotlab.geometry import Rig
from spotlab.io import Trial
from spotlab.io.journal import JournalReader
from spotlab.processing.decoding import decoder_for, input_suffix
from spotlab.processing.errors import InputError
from spotlab.processing.identification_passes import (
    identify_both_ways,
    identify_pass,
)
from spotlab.processing.progress import ProgressSink
from spotlab.reconstruction.identification import BlobFrame, Identifier, MarkerModel

__all__ = [
    "BLOB_KIND",
    "MODEL_KEY",
    "BlobRecording",
    "BlobTrajectories",
    "identify_recording",
    "is_blob_recording",
    "load_model",
    "model_metadata",
    "read_blob_recording",
]

FloatArray = NDArray[np.float64]

#: Stream kind of a video-centroid recording.
BLOB_KIND = "blobs2d"
#: Session metadata key under which ``spotlab record --model`` stores the marker model.
MODEL_KEY = "marker_model"


@dataclass
class BlobRecording:
    """The decoded blobs of a one-stream ``blobs2d`` recording.

    Attributes
    ----------
    blobs : BlobFrames
        Every decoded frame, in recording order.
    frame_no : ndarray of int64, shape (F,)
        Hub frame number of each decoded frame (triggers since ``START:``).
    rate_hz : float
        Nominal frame rate of the stream.
    stream : str
        Stream name.
    model : dict or None
        The marker model stored in the recording (JSON layout of
        :meth:`MarkerModel.to_json`), if any.
    """

    blobs: BlobFrames
    frame_no: NDArray[np.int64]
    rate_hz: float
    stream: str
    model: dict[str, Any] | None


@dataclass
class BlobTrajectories:
    """Labelled trajectories of a blob recording and what happened on the way.

    Attributes
    ----------
    trial : Trial
        Points (F, M, 3) mm on the hub's frame grid from the first recorded frame, NaN
        where a marker was not labelled or the frame was lost; ``first_frame`` is the
        first frame's hub number + 1.
    summary : dict
        JSON-safe figures (see :func:`identify_recording`).
    ticks : ndarray of int64, shape (F,)
        Hub time stamp (µs) of each frame, -1 for a lost frame.
    """

    trial: Trial
    summary: dict[str, Any]
    ticks: NDArray[np.int64]


def _stream_kinds(path: Path) -> list[tuple[str, str | None]]:
    """``(family, spec kind)`` of every stream declared in a journal."""
    out = []
    for meta in JournalReader(path).streams.values():
        spec = meta.get("spec")
        kind = spec.get("kind") if isinstance(spec, dict) else None
        out.append((str(meta.get("family")), None if kind is None else str(kind)))
    return out


def is_blob_recording(path: Path) -> bool:
    """True when ``path`` is a recording (``.spj``) whose streams are all ``blobs2d``."""
    if input_suffix(path) != ".spj" or not path.is_file():
        return False
    try:
        kinds = _stream_kinds(path)
    except RecordingError:
        return False
    return bool(kinds) and all(kind == BLOB_KIND for _, kind in kinds)


def read_blob_recording(path: Path) -> BlobRecording:
    """Decode every frame of a recording of one video-centroid hub.

    Raises
    ------
    InputError
        For a file that is not a recording, several streams, another stream kind, no
        frames, or camera frame counters that go backwards (a restart).
    """
    metas: list[dict[str, Any]] = []

    def factory(metadata: dict[str, Any]) -> StreamDecoder:
        metas.append(metadata)
        return decoder_for(metadata)

    names: set[str] = set()
    blocks: list[FrameBlock] = []
    try:
        session = JournalReader(path).session
        for name, block in replay(path, factory):
            names.add(name)
            blocks.append(block)
    except RecordingError as exc:
        raise InputError(f"{path}: {exc}") from None
    if len(names) > 1:
        raise InputError(
            f"{path}: {len(names)} streams ({', '.join(sorted(names))}); the blob path reads "
            "recordings of one video-centroid hub"
        )
    specs = [m.get("spec") or {} for m in metas]
    if any(s.get("kind") != BLOB_KIND for s in specs):
        raise InputError(f"{path}: not a video-centroid ({BLOB_KIND}) recording")
    blobs = blobs_from_blocks(blocks)
    if blobs.n_frames == 0:
        raise InputError(f"{path}: the recording holds no frames")
    rate = float(specs[-1].get("rate_hz", np.nan))
    if not (np.isfinite(rate) and rate > 0):
        raise InputError(f"{path}: the recording does not state its frame rate")
    model = session.get(MODEL_KEY)
    return BlobRecording(
        blobs=blobs,
        frame_no=_frame_numbers(blobs, rate, path),
        rate_hz=rate,
        stream=next(iter(names)),
        model=model if isinstance(model, dict) else None,
    )


def _frame_numbers(blobs: BlobFrames, rate_hz: float, path: Path) -> NDArray[np.int64]:
    """Place of each decoded frame on the hub's frame grid.

    Within a stretch of streaming the cameras' frame counter (triggers since ``START:``)
    numbers the frames; where no camera delivered one, the hub tick (µs) from the
    nearest counted frame does. When the counter starts again (the driver restarted the
    stream after a link outage) the new stretch is placed after the previous one by the
    hub's tick, which runs on.

    Raises
    ------
    InputError
        When no camera delivered a counter, or the hub's tick went backwards too (the hub
        itself restarted).
    """
    counter = np.where(blobs.offline, -1, blobs.camera_frame).max(axis=1)
    known = counter >= 0
    if not known.any():
        raise InputError(f"{path}: no camera delivered a frame counter")
    ref = np.flatnonzero(known)
    near = ref[np.clip(np.searchsorted(ref, np.arange(known.size)), 0, ref.size - 1)]
    per_tick = rate_hz / 1e6  # frames per hub tick (µs)
    elapsed = np.rint((blobs.ticks - blobs.ticks[near]).astype(np.float64) * per_tick)
    number = np.where(known, counter, counter[near] + elapsed.astype(np.int64))
    restart = np.flatnonzero(np.diff(number) <= 0) + 1
    for k in restart:  # each restart: shift the rest after frame k - 1 by the tick
        step = round(float(blobs.ticks[k] - blobs.ticks[k - 1]) * per_tick)
        if step <= 0:
            raise InputError(
                f"{path}: the hub's clock went backwards at frame {k} (the hub restarted "
                "during the recording); split the recording at the restart"
            )
        number[k:] += number[k - 1] + step - number[k]
    return number.astype(np.int64)


def model_metadata(path: Path) -> dict[str, Any]:
    """A marker model file as the JSON-safe dictionary ``spotlab record --model`` stores.

    Raises
    ------
    InputError
        For a missing or malformed model file.
    """
    return _model_from_file(path).to_json()


def _model_from_file(path: Path) -> MarkerModel:
    if not path.is_file():
        raise InputError(f"{path}: no such marker model file")
    try:
        return MarkerModel.load(path)
    except ReconstructionError as exc:
        raise InputError(str(exc)) from None


def load_model(path: Path | None, recording: BlobRecording, source: Path) -> MarkerModel:
    """The marker model: from ``path`` when given, else the one stored in the recording.

    Raises
    ------
    InputError
        When neither gives one, or the one given is malformed.
    """
    if path is not None:
        return _model_from_file(path)
    if recording.model is None:
        raise InputError(
            f"{source}: no marker model to name the markers: give --model MODEL.json, or "
            "record with spotlab record --model MODEL.json"
        )
    with tempfile.TemporaryDirectory() as tmp:  # MarkerModel reads its JSON from a file
        file = Path(tmp) / "model.json"
        file.write_text(json.dumps(recording.model))
        try:
            return MarkerModel.load(file)
        except ReconstructionError as exc:
            raise InputError(f"{source}: its stored marker model is malformed ({exc})") from None


def _frames(blobs: BlobFrames) -> Iterator[tuple[BlobFrame, NDArray[np.bool_]]]:
    """Each frame's blobs (rig order) and its unusable cameras (offline, overflowing)."""
    C = blobs.n_cameras
    counts = blobs.counts
    unusable = blobs.offline | blobs.overflow
    merged = (blobs.flags & BLOB_MERGED) != 0
    cameras = np.arange(C)
    for f in range(blobs.n_frames):
        lo, hi = int(blobs.offsets[f * C]), int(blobs.offsets[(f + 1) * C])
        yield (
            BlobFrame(blobs.uv[lo:hi], np.repeat(cameras, counts[f]), merged[lo:hi]),
            unusable[f],
        )


def identify_recording(
    rig: Rig,
    recording: BlobRecording,
    model: MarkerModel,
    *,
    rate_hz: float | None = None,
    progress: ProgressSink | None = None,
    both_directions: bool = True,
) -> BlobTrajectories:
    """Label the markers of every frame of ``recording``.

    Parameters
    ----------
    rig : Rig
        Calibration (mm, px) of the hub's cameras, in camera order.
    recording : BlobRecording
    model : MarkerModel
        Names and rigid clusters of the markers.
    rate_hz : float, optional
        Frame rate; overrides the recording's.
    progress : ProgressSink, optional
        Told every few hundred frames.
    both_directions : bool
        Identify backward in time too and fill what the forward pass left empty
        (:func:`~spotlab.processing.identification_passes.identify_both_ways`); False:
        forward only, as the live path labels.

    Returns
    -------
    BlobTrajectories
        The summary holds ``frames`` (on the grid), ``decoded_frames``,
        ``lost_frames``, ``markers``, ``cameras``, ``rate_hz``, ``method``
        (``identification``), ``labelled_fraction`` (marker-frames with a labelled point,
        over the decoded frames), ``markers_reconstructed``, ``rms_ray_px``,
        ``ghosts_rejected`` (reflection points), ``unlabelled_per_frame``,
        ``marker_gaps`` (gaps inside each marker's trajectory, summed),
        ``identification_restarts`` (gaps of more than ``MAX_LOST_FRAMES`` lost frames,
        after which identification starts afresh), ``filled_backward``,
        ``bridged`` and ``label_conflicts`` (marker-frames the backward pass added, those
        filled along a trajectory labelled as that marker before and after, and those
        dropped because the two passes disagreed), and per camera the
        frames it was ``offline``, ``overflow``, ``flooded`` (too many blobs) or had
        ``no_blobs``.

    Raises
    ------
    InputError
        When the rig's camera count differs from the recording's, or the identification
        finds that the calibration does not match the cameras.
    """
    blobs = recording.blobs
    C, F = blobs.n_cameras, blobs.n_frames
    if len(rig) != C:
        raise InputError(
            f"the recording has {C} cameras but the calibration has {len(rig)}: give the "
            "calibration of this hub's cameras"
        )
    rate = float(rate_hz if rate_hz is not None else recording.rate_hz)
    if not (np.isfinite(rate) and rate > 0):
        raise InputError(f"the frame rate must be a positive number of Hz, not {rate:g}")
    try:
        Identifier(rig, model)
    except ReconstructionError as exc:
        raise InputError(str(exc)) from None
    M = len(model.labels)
    first = int(recording.frame_no[0])
    row = recording.frame_no - first
    frames = list(_frames(blobs))
    # A frame with no usable blob is a gap, like a lost frame.
    usable = np.array([blobs.counts[f][~frames[f][1]].any() for f in range(F)], dtype=bool)
    counts: dict[str, int] = {}
    if both_directions:
        result, counts = identify_both_ways(
            rig, model, frames, usable, recording.frame_no, progress
        )
    else:
        result = identify_pass(rig, model, frames, usable, recording.frame_no, range(F), progress)
    if progress is not None:
        progress.close()
    points = np.full((int(row[-1]) + 1, M, 3), np.nan)
    points[row] = result.points
    residual = result.residual_px
    flagged = {"flooded": result.flooded, "no_blobs": result.no_blobs}
    ghosts, unlabelled, restarts = result.ghosts, result.unlabelled, result.restarts
    ticks = np.full(points.shape[0], -1, dtype=np.int64)
    ticks[row] = blobs.ticks
    seen = np.isfinite(points[row, :, 0])
    res = residual[np.isfinite(residual)]
    names = [cam.name or f"cam{c + 1}" for c, cam in enumerate(rig)]
    summary: dict[str, Any] = {
        "frames": int(points.shape[0]),
        "decoded_frames": F,
        "lost_frames": int(points.shape[0] - F),
        "first_frame_no": first,
        "markers": M,
        "cameras": C,
        "rate_hz": rate,
        "method": "identification",
        "labelled_fraction": round(float(seen.mean()), 6),
        "markers_reconstructed": int(seen.any(axis=0).sum()),
        "rms_ray_px": float(np.sqrt(np.mean(res**2))) if res.size else None,
        "ghosts_rejected": int(ghosts),
        "unlabelled_per_frame": round(unlabelled / F, 3),
        "marker_gaps": _gaps(np.isfinite(points[..., 0])),
        "identification_restarts": restarts,
        "filled_backward": counts.get("filled_backward", 0),
        "bridged": counts.get("bridged", 0),
        "label_conflicts": counts.get("label_conflicts", 0),
        "camera_frames": {
            name: {
                "offline": int(blobs.offline[:, c].sum()),
                "overflow": int(blobs.overflow[:, c].sum()),
                "flooded": int(flagged["flooded"][c]),
                "no_blobs": int(flagged["no_blobs"][c]),
            }
            for c, name in enumerate(names)
        },
        "units": "mm",
    }
    trial = Trial(
        points,
        list(model.labels),
        rate,
        first_frame=first + 1,
        metadata={"method": "identification", "stream": recording.stream},
    )
    return BlobTrajectories(trial, summary, ticks)


def _gaps(present: NDArray[np.bool_]) -> int:
    """Runs of missing frames inside the trajectories (F, M) (between first and last seen)."""
    p = present.astype(np.int8)
    starts = np.diff(p, axis=0) == -1  # seen -> missing
    ends = np.diff(p, axis=0) == 1  # missing -> seen
    # A gap is a fall that a later rise closes: count the rises after the first fall.
    falls = np.cumsum(starts, axis=0) > 0
    return int((ends & falls).sum())
