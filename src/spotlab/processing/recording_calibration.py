"""A rig from a wand dance: the calibration ``spotlab calibrate`` and the console share.

:func:`calibrate_observations` runs :func:`spotlab.calibration.wand_calibrate` on
observations already loaded, and for video-centroid recordings
(:class:`~spotlab.processing.blob_calibration_inputs.BlobCalibrationInputs`) what
follows it: a 2-marker wand's ends named again with the first rig and a second
adjustment, then the check that the reference object, triangulated with the rig the
wand scaled, has its published size. :func:`write_calibration` writes the rig with its
report (JSON) and figure (PNG). docs/calibration.md describes both paths.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from spotlab.calibration import WandCalibration, wand_calibrate, write_report_figure
from spotlab.geometry import Rig
from spotlab.processing.blob_calibration_inputs import BlobCalibrationInputs
from spotlab.processing.calibration_inputs import WandObservations
from spotlab.processing.errors import InputError
from spotlab.reconstruction import triangulate

__all__ = [
    "SCALE_MISMATCH",
    "Calibrated",
    "calibrate_observations",
    "check_scale",
    "write_calibration",
]

#: Largest relative difference between the reference object's size triangulated with
#: the calibrated rig (the wand sets the scale) and its published coordinates, for
#: video-centroid recordings.
SCALE_MISMATCH = 0.005


@dataclass(frozen=True)
class Calibrated:
    """A calibration and what it was computed from.

    Attributes
    ----------
    result : WandCalibration
        The rig, its report and residuals.
    observations : WandObservations
        The observations of the last adjustment (a 2-marker wand's renamed ends).
    found : BlobCalibrationInputs or None
        What was found among a video-centroid hub's blobs (None for other inputs).
    """

    result: WandCalibration
    observations: WandObservations
    found: BlobCalibrationInputs | None

    def report(self) -> dict[str, Any]:
        """The quality report, with ``finder`` for video-centroid recordings."""
        extra = {"finder": self.found.summary()} if self.found is not None else {}
        return {**self.result.report, **extra}


def check_scale(
    rig: Rig, obs: WandObservations, length: float, option: str = "--wand-length"
) -> None:
    """The reference object, triangulated with the rig the wand scaled, must have its size.

    The bundle adjustment holds the wand at ``length`` and the reference object at its
    coordinates; when the two disagree, the many wand frames win and the object's
    residuals take the difference. Its markers triangulated from their own images then
    measure the object at the scale the wand gave. ``option`` names the wand length in
    the message (``--wand-length``). InputError when it is off by more than
    :data:`SCALE_MISMATCH`.
    """
    X = triangulate(rig, obs.frame)
    ok = np.all(np.isfinite(X), axis=1)
    if ok.sum() < 2:
        return
    i, j = np.triu_indices(int(ok.sum()), 1)
    measured = np.linalg.norm(X[ok][i] - X[ok][j], axis=1).sum()
    published = np.linalg.norm(obs.frame_points[ok][i] - obs.frame_points[ok][j], axis=1).sum()
    scale = float(measured / published)
    if not abs(scale - 1.0) <= SCALE_MISMATCH:
        raise InputError(
            f"the wand length does not match the recordings: with {option} {length:g} mm "
            f"the reference object measures {100 * scale:.1f} % of its published size, as if "
            f"the wand were {length / scale:.0f} mm; check the wand's length and the "
            "reference object's coordinates"
        )


def calibrate_observations(
    obs: WandObservations,
    length: float,
    found: BlobCalibrationInputs | None = None,
    *,
    distortion: str = "auto",
    progress: Callable[[str], None] | None = None,
    length_option: str = "--wand-length",
) -> Calibrated:
    """Calibrate a rig from wand observations (as ``spotlab calibrate`` does).

    Parameters
    ----------
    obs : WandObservations
        Wand (F, C, 2, 2) and reference object (C, P, 2) image points, its markers
        (P, 3) mm, the image size; ``found.observations`` for video-centroid input.
    length : float
        The wand's length between its end markers, mm.
    found : BlobCalibrationInputs, optional
        Video-centroid input: a 2-marker wand's ends are named again with the first
        rig and adjusted once more; the reference object's size is checked.
    distortion : str
        Lens terms (``auto``, ``none``, ``radial``, ``full``).
    progress : callable, optional
        Takes one line per stage.
    length_option : str
        How messages name the wand length.

    Raises
    ------
    InputError
        The reference object's size does not match the wand length; see also
        :func:`~spotlab.calibration.wand_calibrate`.
    """

    def calibrate(o: WandObservations) -> WandCalibration:
        return wand_calibrate(
            o.wand, length, o.frame, o.frame_points, o.image_size, names=o.names,
            distortion=distortion, units=o.units, progress=progress,
        )  # fmt: skip

    result = calibrate(obs)
    if found is not None and found.markers == 2:
        # Two identical markers: name the ends again with this first rig, then adjust again.
        if progress is not None:
            progress("2-marker wand: naming its ends with the first calibration")
        found = found.relabel(result.rig, result.wand_ends)
        obs = found.observations
        result = calibrate(obs)
    if found is not None:
        check_scale(result.rig, obs, length, length_option)
    return Calibrated(result, obs, found)


def write_calibration(
    calibrated: Calibrated, out: Path, report_path: Path, figure_path: Path
) -> dict[str, Any]:
    """Write the figure, the report and the rig (in that order: a rig is written only
    with its report); returns the report."""
    result, obs = calibrated.result, calibrated.observations
    write_report_figure(
        result.rig, obs.wand, result.wand_residuals, result.inliers, result.report,
        figure_path, frame_points=obs.frame_points,
    )  # fmt: skip
    report = calibrated.report()
    report_path.write_text(json.dumps(report, indent=2) + "\n")
    result.rig.save(out)
    return report
