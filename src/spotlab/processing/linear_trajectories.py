"""Marker trajectories of a WSX recording (docs/protocols/wsx.md §7), no calibration file.

The recording carries the hub's factory calibration (every CCD's principal
distance, point, axis and pose) in its stream's metadata. Each marker is
reconstructed at its own firing instant (frame start + ``fire_ns``) from the
planes of its good readings (quality code 0) over all sensors, then brought to the
frame's instant (its start) by linear interpolation in time between its positions
in the frame before and this one (or this one and the next, when the one before is
missing) -- unless the set-up said ``NO_INTERPOLATION`` or ``raw`` is asked for.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.acquisition.replay import replay
from spotlab.core.errors import ReconstructionError, RecordingError
from spotlab.core.frames import FrameBlock
from spotlab.io import Trial
from spotlab.io.journal import JournalReader
from spotlab.processing.decoding import decoder_for, input_suffix
from spotlab.processing.errors import InputError
from spotlab.reconstruction.linear_sensors import (
    LinearSensorCalibration,
    markers_from_readings,
    register_sensors,
)

KIND = "linear1d"
F64 = NDArray[np.float64]


@dataclass
class LinearRecording:
    """One WSX stream's frames on its frame-number grid.

    Attributes
    ----------
    readings : ndarray, shape (F, M, C)
        Centroids (px), NaN where missing or not good (code != 0) or the frame lost.
    fire_ns : ndarray, shape (F, M)
        Firing instant of each marker after its frame's start (ns).
    start_ns : ndarray, shape (F,)
        Frame starts (device ns); NaN for lost frames.
    rate_hz : float
    calibration : LinearSensorCalibration
    interpolate : bool
        False when the set-up said ``NO_INTERPOLATION``.
    stream : str
    first_seq : int
        The ``seq`` of row 0.
    registration_rms : list of float or None
        When the hub's sensors were calibrated each in its own frame: the RMS (mm) of
        each sensor's registration to the first (the frame is then the first sensor's).
    """

    readings: F64
    fire_ns: F64
    start_ns: F64
    rate_hz: float
    calibration: LinearSensorCalibration
    interpolate: bool
    stream: str
    first_seq: int
    registration_rms: list[float] | None = None


def _is_wsx(meta: Any) -> bool:
    spec = meta.get("spec") if isinstance(meta, dict) else None
    return (
        isinstance(spec, dict)
        and spec.get("kind") == KIND
        and isinstance(spec.get("metadata"), dict)
        and "calibration" in spec["metadata"]
    )


def is_linear_recording(path: Path) -> bool:
    """True for a recording (``.spj``) whose streams are all calibrated linear-sensor hubs."""
    if input_suffix(path) != ".spj" or not path.is_file():
        return False
    try:
        streams = JournalReader(path).streams
    except RecordingError:
        return False
    return bool(streams) and all(_is_wsx(m) for m in streams.values())


def read_linear_recording(path: Path, stream: str | None = None) -> LinearRecording:
    """Decode every frame of one WSX stream.

    Raises
    ------
    InputError
        For several streams and no ``stream``, no frames, or no calibration.
    """
    blocks: list[FrameBlock] = []
    names: set[str] = set()
    try:
        declared = JournalReader(path).streams
        for name, block in replay(path, decoder_for):
            names.add(name)
            if (stream is None or name == stream) and len(block):
                blocks.append(block)
    except RecordingError as exc:
        raise InputError(f"{path}: {exc}") from None
    if stream is None and len(names) > 1:
        raise InputError(f"{path}: {len(names)} streams ({', '.join(sorted(names))}); name one")
    stream = stream if stream is not None else next(iter(names), "")
    if not blocks:
        raise InputError(f"{path}: no frames of a stream {stream!r}")
    spec = declared[stream]["spec"]
    meta = spec["metadata"]
    try:
        cal = LinearSensorCalibration.from_records(meta["calibration"])
    except ReconstructionError as exc:
        raise InputError(f"{path}: {exc}") from None
    seq = np.concatenate([b.seq for b in blocks])
    data = np.concatenate([b.data for b in blocks])
    flags = np.concatenate([b.flags for b in blocks])
    ticks = np.concatenate([b.ticks for b in blocks]).astype(np.float64)
    status = np.concatenate([b.status for b in blocks])
    if data.shape[2] != cal.n_ccds:
        raise InputError(f"{path}: {data.shape[2]} CCDs in the frames, {cal.n_ccds} calibrated")
    k = seq - seq[0]
    if np.any(np.diff(k) <= 0):
        raise InputError(f"{path}: frame numbers go back in the stream {stream!r}")
    n = int(k[-1]) + 1
    m, c = data.shape[1:3]
    readings = np.full((n, m, c), np.nan)
    readings[k] = np.where(flags == 0, data[..., 0], np.nan)
    fire = np.full((n, m), np.nan)
    fire[k] = data[:, :, 0, 2]
    start = np.full(n, np.nan)
    start[k] = ticks
    interpolate = bool(meta.get("interpolate", True)) and not np.any(status & 0x0001)
    registration = None
    if any(r.get("frame") == "sensor" for r in meta["calibration"]):
        try:
            reg = register_sensors(readings, cal)
        except ReconstructionError as exc:
            raise InputError(f"{path}: {exc}") from None
        cal, registration = reg.calibration, reg.rms
    return LinearRecording(
        readings, fire, start, float(spec["rate_hz"]), cal, interpolate, stream, int(seq[0]),
        registration,
    )  # fmt: skip


def to_frame_instants(points: F64, fire_ns: F64, start_ns: F64, rate_hz: float) -> F64:
    """Markers measured at ``start + fire`` brought to ``start`` (linear in time).

    Parameters
    ----------
    points : ndarray, shape (F, M, 3)
        Each marker at its own firing instant; NaN where missing.
    fire_ns : ndarray, shape (F, M)
    start_ns : ndarray, shape (F,)
    rate_hz : float
        Nominal frame rate: neighbours further apart than 1.5 periods (a restart) are
        not used.

    Returns
    -------
    ndarray, shape (F, M, 3)
        NaN where neither the frame before nor the one after gives a neighbour.
    """
    t = start_ns[:, None] + fire_ns  # (F, M)
    period = 1e9 / rate_hz
    out = np.full(points.shape, np.nan)
    for shift in (1, -1):  # the frame before first, then the one after
        a = np.full(points.shape, np.nan)
        ta = np.full(t.shape, np.nan)
        if shift == 1:
            a[1:], ta[1:] = points[:-1], t[:-1]
        else:
            a[:-1], ta[:-1] = points[1:], t[1:]
        dt = t - ta
        ok = np.isfinite(dt) & (np.abs(np.abs(dt) - period) < 0.5 * period)
        with np.errstate(invalid="ignore", divide="ignore"):
            w = (start_ns[:, None] - ta) / dt
        est = a + w[..., None] * (points - a)
        est = np.where(ok[..., None], est, np.nan)
        out = np.where(np.isfinite(out), out, est)
    return out


def linear_points(rec: LinearRecording, raw: bool = False) -> tuple[F64, F64]:
    """Markers (F, M, 3) mm at the frames' instants (or firing instants when raw) and the
    RMS distance of each from its planes (F, M) mm."""
    fit = markers_from_readings(rec.readings, rec.calibration)
    if raw or not rec.interpolate:
        return fit.points, fit.rms
    return to_frame_instants(fit.points, rec.fire_ns, rec.start_ns, rec.rate_hz), fit.rms


def linear_trial(rec: LinearRecording, raw: bool = False) -> tuple[Trial, dict[str, Any]]:
    """The trajectories of a WSX recording and a JSON-safe summary."""
    points, rms = linear_points(rec, raw)
    m = points.shape[1]
    labels = [f"M{j + 1:02d}" for j in range(m)]
    markers = []
    for j, label in enumerate(labels):
        seen = np.isfinite(points[:, j]).all(axis=1)
        r = rms[:, j][np.isfinite(rms[:, j])]
        markers.append({
            "label": label, "frames": int(seen.sum()),
            "plane_rms_mm": round(float(np.median(r)), 4) if r.size else None,
        })  # fmt: skip
    interpolated = rec.interpolate and not raw
    trial = Trial(
        points=points, labels=labels, point_rate=rec.rate_hz,
        metadata={"wsx": {"interpolated": interpolated, "ccds": rec.calibration.n_ccds}},
    )  # fmt: skip
    summary = {
        "stream": rec.stream, "frames": int(points.shape[0]), "ccds": rec.calibration.n_ccds,
        "interpolated": interpolated, "markers": markers,
        "registration_rms_mm": None if rec.registration_rms is None
        else [round(v, 4) for v in rec.registration_rms],
    }  # fmt: skip
    return trial, summary
