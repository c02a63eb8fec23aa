"""The ``labelling`` step: a video-centroid recording identified and named by its marker
model (``spotlab reconstruct``'s path), scored against the hub simulator's truth.

C3D frame ``first_frame + i`` of the reconstruction is hub frame ``first_frame - 1 + i``
of the recording's first stream, ``i`` frame periods of the hub's clock after it (a
stream restarted after an outage goes on in the hub's time): :func:`truth_of_frames`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.processing.trajectories import reconstruct_file, write_trial

#: A reported marker farther than this from its own true position has the wrong label, mm.
WRONG_LABEL_MM = 20.0


def truth_of_frames(
    first_frame: int, n_frames: int, rate_hz: float, truth: Any
) -> NDArray[np.float64]:
    """True markers (F, M, 3) in mm at the C3D frames, NaN where the simulator took none.

    Parameters
    ----------
    first_frame, n_frames : int
        The trial's first C3D frame and its number of frames.
    rate_hz : float
        The hub's frame rate.
    truth : mapping
        The centroid simulator's truth (``np.load`` of its ``.npz``): ``stream``,
        ``frame_no``, ``hub_tick_us``, ``markers_mm``.
    """
    first = np.flatnonzero(
        (truth["stream"] == truth["stream"][0]) & (truth["frame_no"] == first_frame - 1)
    )[0]
    ticks = truth["hub_tick_us"].astype(np.float64)
    want = ticks[first] + np.arange(n_frames) * 1e6 / rate_hz
    k = np.clip(np.searchsorted(ticks, want), 1, ticks.size - 1)
    k = np.where(np.abs(ticks[k - 1] - want) < np.abs(ticks[k] - want), k - 1, k)
    out = truth["markers_mm"][k].astype(np.float64)
    out[np.abs(ticks[k] - want) > 0.25e6 / rate_hz] = np.nan
    return np.asarray(out)


def score_labelling(
    journal: Path, rig: Path, truth: Path, c3d: Path | None = None, model: Path | None = None
) -> dict[str, Any]:
    """Identify the markers of a centroid recording (``model``, by default the one it was
    recorded with), and score the labels against the truth.

    Returns
    -------
    dict
        ``labelled_fraction`` (marker-frames reported, of the frames decoded),
        ``wrong_label_fraction`` (reported ones beyond :data:`WRONG_LABEL_MM` of their
        own marker), ``label_error_rms_mm`` (RMS error of the others), ``labels_match``
        (the trial's labels are the truth's, in order).
    """
    result = reconstruct_file(journal, rig, model=model)
    if c3d is not None:
        write_trial(c3d, result.trial)
    trial = result.trial
    data = np.load(truth)
    true = truth_of_frames(trial.first_frame, trial.n_frames, float(trial.point_rate), data)
    err = np.linalg.norm(trial.points - true, axis=-1)
    decoded = np.isfinite(trial.points[..., 0]).any(axis=1)
    reported = np.isfinite(err)
    near = reported & (err < WRONG_LABEL_MM)
    n_reported = int(reported.sum())
    return {
        "labels_match": list(trial.labels) == [str(x) for x in data["labels"]],
        "labelled_fraction": float(reported[decoded].mean()) if decoded.any() else None,
        "wrong_label_fraction": float((reported & ~near).sum() / n_reported)
        if n_reported
        else None,
        "label_error_rms_mm": float(np.sqrt(np.mean(err[near] ** 2))) if near.any() else None,
        "frames_identified": int(decoded.sum()),
    }


__all__ = ["WRONG_LABEL_MM", "score_labelling", "truth_of_frames"]
