"""Observations + calibration -> marker trajectories -> C3D or TRC: the shared path of
``spotlab reconstruct`` and ``spotlab export``.

The rig's cameras are matched to the observation's by name when the observations name
their cameras, else by order. Frames are triangulated in chunks
(:func:`spotlab.reconstruction.triangulate_points`), their progress told to a sink the
caller gives (nothing here prints).
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import CalibrationError
from spotlab.geometry import Rig
from spotlab.io import Trial, write_c3d, write_trc
from spotlab.processing.blob_trajectories import (
    identify_recording,
    is_blob_recording,
    load_model,
    read_blob_recording,
)
from spotlab.processing.errors import InputError
from spotlab.processing.marker_observations import MarkerObservations, load_observations
from spotlab.processing.paths import check_output_paths
from spotlab.processing.progress import ProgressFactory, ProgressSink
from spotlab.reconstruction import METHODS, triangulate_points

__all__ = [
    "TRIAL_WRITERS",
    "Reconstruction",
    "check_outputs",
    "load_rig",
    "match_cameras",
    "reconstruct",
    "reconstruct_file",
    "write_trial",
]

FloatArray = NDArray[np.float64]

#: Trial file writers by suffix.
TRIAL_WRITERS = {".c3d": write_c3d, ".trc": write_trc}
#: Frames triangulated at once (progress is shown between chunks).
CHUNK_FRAMES = 500


@dataclass
class Reconstruction:
    """Trajectories and how well the rays met.

    Attributes
    ----------
    trial : Trial
        Marker trajectories (F, M, 3) in mm, NaN where fewer than two cameras saw a
        marker.
    summary : dict
        JSON-safe figures: frames, markers, rate, reconstructed fraction, RMS ray residual
        (px) overall and per camera, method, and facts of the input.
    ticks : ndarray of int64, shape (F,), or None
        Device time stamp of each frame of a recording (-1 for a lost frame).
    notes : list of str
        What the user should hear about, one line each, prefixed with its kind
        (``"note: ..."``, ``"warning: ..."``, ``"<stream>: ..."``); the command line
        prints them on stderr after ``spotlab: ``.
    """

    trial: Trial
    summary: dict[str, Any]
    ticks: NDArray[np.int64] | None = None
    notes: list[str] = field(default_factory=list)


def load_rig(path: Path) -> Rig:
    """Read a calibration (TOML, anipose / Pose2Sim layout); a bad file is a InputError."""
    if not path.is_file():
        raise InputError(f"{path}: no such calibration file")
    try:
        return Rig.load(path)
    except CalibrationError as exc:
        text = str(exc)
        raise InputError(text if str(path) in text else f"{path}: {text}") from None
    except (UnicodeDecodeError, ValueError) as exc:
        raise InputError(f"{path}: not a calibration file ({exc})") from None


def match_cameras(rig: Rig, n_cameras: int, names: Sequence[str] | None) -> Rig:
    """The rig's cameras in the order of the observation's ``n_cameras`` cameras.

    By name when ``names`` is given (the rig may hold more cameras), else by order (the
    counts must agree).

    Raises
    ------
    InputError
        For a camera name the rig lacks or a count that differs.
    """
    if names is not None:
        if len(names) != n_cameras:
            raise InputError(f"{len(names)} camera names for {n_cameras} cameras observed")
        index = {name: i for i, name in enumerate(rig.names)}
        missing = [n for n in names if n not in index]
        if missing:
            raise InputError(
                f"the calibration has no camera {', '.join(map(repr, missing))} "
                f"(it has {', '.join(rig.names)})"
            )
        return Rig([rig[index[n]] for n in names])
    if len(rig) != n_cameras:
        raise InputError(
            f"the observations have {n_cameras} cameras but the calibration has {len(rig)}"
        )
    return rig


def check_outputs(paths: Sequence[Path]) -> None:
    """Refuse an output whose suffix names no trial format, before any work is done."""
    for path in paths:
        if path.suffix.lower() not in TRIAL_WRITERS:
            raise InputError(
                f"{path}: unknown output format {path.suffix!r} ({', '.join(TRIAL_WRITERS)})"
            )
    check_output_paths(("output", path) for path in paths)


def write_trial(path: Path, trial: Trial, drop_groups: Collection[str] = ()) -> None:
    """Write ``trial`` as C3D or TRC, chosen by the suffix of ``path``.

    A C3D file gets every parameter group the trial's source file had, except those
    named in ``drop_groups`` (:func:`spotlab.io.write_c3d`); TRC has no groups.
    """
    check_outputs([path])
    if path.suffix.lower() == ".c3d":
        write_c3d(path, trial, drop=drop_groups)
    else:
        TRIAL_WRITERS[path.suffix.lower()](path, trial)


def reconstruct(
    rig: Rig,
    obs: MarkerObservations,
    *,
    method: str = "odle",
    rate_hz: float | None = None,
    labels: Sequence[str] | None = None,
    progress: ProgressSink | None = None,
) -> Reconstruction:
    """Triangulate every frame of ``obs`` with the matching cameras of ``rig``.

    Parameters
    ----------
    rig : Rig
        The calibration (in the units of the observations: px or detector counts).
    obs : MarkerObservations
        uv (F, C, M, 2).
    method : {"odle", "dlt", "midpoint"}
        Estimator of :func:`spotlab.reconstruction.triangulate_points`.
    rate_hz : float, optional
        Frame rate; overrides the observations' own.
    labels : sequence of str, optional
        Marker names (M); override the observations' own.
    progress : ProgressSink, optional
        Told per chunk of frames.

    Returns
    -------
    Reconstruction

    Raises
    ------
    InputError
        For an unknown rate, labels whose count differs from the markers', cameras that
        do not match the rig.
    ReconstructionError
        From the triangulation (for example ``midpoint`` with other than two views).
    """
    if method not in METHODS:
        raise InputError(f"unknown method {method!r} ({', '.join(METHODS)})")
    F, C, M, _ = obs.uv.shape
    rate = rate_hz if rate_hz is not None else obs.rate_hz
    if rate is None:
        raise InputError("the frame rate is not known: give --rate HZ")
    if not (np.isfinite(rate) and rate > 0):
        raise InputError(f"the frame rate must be a positive number of Hz, not {rate:g}")
    names = list(labels) if labels else obs.labels or [f"M{m + 1}" for m in range(M)]
    if len(names) != M:
        raise InputError(f"{len(names)} marker labels for {M} markers")
    cameras = match_cameras(rig, C, obs.camera_names)
    uv = obs.uv.transpose(1, 0, 2, 3)  # (C, F, M, 2)
    points = np.full((F, M, 3), np.nan)
    square = np.zeros(C)  # sum of squared ray errors of reconstructed points, per camera
    rays = np.zeros(C, dtype=np.int64)
    for start in range(0, F, CHUNK_FRAMES):
        stop = min(F, start + CHUNK_FRAMES)
        result = triangulate_points(cameras, uv[:, start:stop], cast(Any, method))
        points[start:stop] = result.points
        error = np.where(np.isfinite(result.points[..., 0]), result.ray_error, np.nan)
        square += np.nansum(error**2, axis=(1, 2))
        rays += np.isfinite(error).sum(axis=(1, 2))
        if progress is not None:
            progress.update(stop, f"{stop} of {F} frames")
    if progress is not None:
        progress.close()
    done = np.isfinite(points[..., 0])
    with np.errstate(invalid="ignore", divide="ignore"):
        per_camera = np.sqrt(square / rays)
    total = int(rays.sum())
    summary: dict[str, Any] = {
        "frames": F,
        "markers": M,
        "cameras": C,
        "rate_hz": float(rate),
        "method": method,
        "reconstructed_fraction": round(float(done.mean()), 6),
        "markers_reconstructed": int(done.any(axis=0).sum()),
        "rms_ray_px": float(np.sqrt(square.sum() / total)) if total else None,
        "rms_ray_px_per_camera": {
            cam.name or f"cam{c + 1}": (float(per_camera[c]) if rays[c] else None)
            for c, cam in enumerate(cameras)
        },
        **obs.facts,
    }
    trial = Trial(points, names, float(rate), metadata={"method": method})
    return Reconstruction(trial, summary, obs.ticks)


def reconstruct_file(
    observations: Path,
    calibration: Path,
    *,
    method: str = "odle",
    rate_hz: float | None = None,
    labels: Sequence[str] | None = None,
    model: Path | None = None,
    progress: ProgressFactory | None = None,
) -> Reconstruction:
    """:func:`reconstruct` from files: observations (npz, CSV, ``.spj``) and a calibration.

    A video-centroid (``blobs2d``) recording takes the blob path
    (:mod:`spotlab.processing.blob_trajectories`): its markers are identified and named by
    the marker model ``model`` (default: the one stored in the recording).

    ``progress`` makes the progress sink of the identification or triangulation (none
    by default).
    """
    rig = load_rig(calibration)
    if is_blob_recording(observations):
        if labels:
            raise InputError(
                f"{observations}: the markers of a video-centroid recording are named by "
                "its marker model (--model), not --labels"
            )
        blobs = read_blob_recording(observations)
        marker_model = load_model(model, blobs, observations)
        shown = progress("identifying", blobs.blobs.n_frames) if progress is not None else None
        found = identify_recording(rig, blobs, marker_model, rate_hz=rate_hz, progress=shown)
        summary = {"input": str(observations), "calibration": str(calibration), **found.summary}
        return Reconstruction(found.trial, summary, found.ticks)
    if model is not None:
        raise InputError(f"{observations}: --model applies to video-centroid recordings only")
    obs = load_observations(observations)
    sink = progress("reconstructing", obs.uv.shape[0]) if progress is not None else None
    result = reconstruct(rig, obs, method=method, rate_hz=rate_hz, labels=labels, progress=sink)
    result.summary = {
        "input": str(observations),
        "calibration": str(calibration),
        **result.summary,
    }
    return result
