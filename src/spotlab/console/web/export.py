"""Export of a console trial to C3D or TRC, through the processing layer.

What it exports: the trajectories ``spotlab export TRIAL.spj --calibration RIG --c3d``
writes, with the lab file's rig (``processing.reconstruct_recording``): the ``image2d``
streams of the trial (SELSPOT-style PSD cameras) triangulated with that rig, on session
time when the trial holds a timer stream. Other streams (a video-centroid hub's blobs,
a timer) are not in the file; the notes the processing layer returns say so. A lab
without a rig cannot export (InputError naming the lab file). For ``--sim`` the rig is
the SELSPOT simulator's true calibration, written by the simulator.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from spotlab import processing
from spotlab.console.web.trials import TrialInfo, TrialStore
from spotlab.processing.errors import InputError
from spotlab.processing.trajectories import Reconstruction

__all__ = ["FORMATS", "export_trial"]

FORMATS = ("c3d", "trc")


def export_trial(
    store: TrialStore,
    info: TrialInfo,
    fmt: object,
    rig: Path | None,
    lab: Path,
    processed: Reconstruction | None = None,
) -> dict[str, Any]:
    """Write ``DATA/SUBJECT/SESSION/TRIAL.<fmt>``; what was written (JSON-safe).

    Parameters
    ----------
    store : TrialStore
        The data folder.
    info : TrialInfo
        The trial (state ``done`` or ``interrupted``).
    fmt : object
        ``"c3d"`` or ``"trc"`` (from the request body).
    rig : Path or None
        The lab's rig.
    lab : Path
        The lab file (named in the error when it has no rig).
    processed : Reconstruction, optional
        The trial's result of "Process" (:mod:`.processing_jobs`), written as it is;
        without it the trial is reconstructed here.

    Returns
    -------
    dict
        ``file`` (path in the data folder), ``frames``, ``markers``,
        ``reconstructed_fraction`` (or the ``labelled_fraction`` of an identified
        trial), ``notes``, ``processed`` (whether the result of "Process" was written).
    """
    if fmt not in FORMATS:
        raise InputError(f"format {fmt!r} is not one of {', '.join(FORMATS)}")
    if info.state == "recording":
        raise InputError(f"trial {info.id} is being recorded: stop it first")
    journal = store.journal(info.subject, info.session, info.trial)
    out = journal.with_suffix(f".{fmt}")
    if processed is not None:
        result = processed
    elif rig is not None:
        result = processing.reconstruct_recording(journal, rig)
    else:
        raise InputError(f"lab file {lab} names no rig: a trial is exported with one")
    processing.write_trial(out, result.trial)
    points = result.trial.points
    rel = str(out.relative_to(store.root))
    if rel not in info.exports:
        info.exports.append(rel)
        store.save(info)
    return {
        "file": rel,
        "frames": int(points.shape[0]),
        "markers": int(points.shape[1]),
        "reconstructed_fraction": float(
            result.summary.get(
                "reconstructed_fraction", result.summary.get("labelled_fraction", 0.0)
            )
        ),
        "notes": list(result.notes),
        "processed": processed is not None,
    }
