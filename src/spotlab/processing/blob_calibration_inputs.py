"""Observations for ``spotlab calibrate`` from video-centroid (``blobs2d``) recordings.

A wand dance and a static recording of the reference object (an L-frame), both of one
CEN hub (docs/protocols/centroid.md), and the object's published marker coordinates
(CSV with columns ``X``, ``Y``, ``Z`` in mm, one row per marker):

- Blobs the hub flagged merged or at the image edge are not used, nor cameras it
  flagged offline or overflowing in a frame.
- The wand: ``--wand-middle MM`` names a 3-marker wand whose middle marker sits MM from
  end A; without it the recording decides (images of three blobs on one line
  outnumbering images of two: a 3-marker wand, with the middle's place the recording
  shows). The markers are found frame by frame by
  :func:`spotlab.calibration.wand_finder.find_wand`; an image that is ambiguous or
  misses a marker is dropped and counted; of two fitting candidates the clearly
  brighter is taken (a floor reflection is dimmer). A 2-marker wand's ends are named by
  image height at first, then again with the first calibration (:meth:`relabel`).
- The reference object: its markers are found in each camera's static blobs by
  :func:`spotlab.calibration.frame_finder.find_frame` and averaged over the recording.
- Cameras are the hub's, in its order: camera ``c`` (0-based on the wire) is ``cam{c+1}``.
- The image size is not on the wire: ``--image-size W H``, else the smallest of
  :data:`SENSOR_SIZES` that holds every blob of the wand dance (printed).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.calibration.frame_finder import FOUND, FrameImages, find_frame
from spotlab.calibration.wand_finder import (
    RATIO_TOLERANCE,
    WandImages,
    find_wand,
    survey_wand,
)
from spotlab.calibration.wand_relabel import relabel_two_ends
from spotlab.drivers.centroid import BLOB_MERGED, BlobFrames
from spotlab.geometry import Rig
from spotlab.processing.blob_trajectories import read_blob_recording
from spotlab.processing.calibration_inputs import WandObservations
from spotlab.processing.errors import InputError
from spotlab.processing.tables import column, read_table

__all__ = [
    "RATIO_MISMATCH",
    "SENSOR_SIZES",
    "BlobCalibrationInputs",
    "find_calibration_inputs",
    "load_blob_recordings",
]

FloatArray = NDArray[np.float64]

#: Common machine-vision sensor sizes (px), smallest first.
SENSOR_SIZES = (
    (640, 480), (752, 480), (1024, 768), (1280, 1024), (1440, 1080), (1920, 1080),
    (1920, 1200), (2048, 1088), (2048, 1536), (2048, 2048), (2560, 2048), (4096, 3072),
)  # fmt: skip
#: Largest difference between the middle ratio ``--wand-middle`` / ``--wand-length`` and
#: the one the recording shows (perspective moves single images by up to 0.05; their
#: median far less).
RATIO_MISMATCH = 0.03
#: The hub's blob flag "at the image edge" (docs/protocols/centroid.md).
_BLOB_EDGE = 0x02


@dataclass
class BlobCalibrationInputs:
    """The observations and how they were found.

    Attributes
    ----------
    observations : WandObservations
        ``wand`` (F, C, 2, 2) px, ``frame`` (C, P, 2) px, ``frame_points`` (P, 3) mm,
        ``image_size`` (2,) px.
    wand : WandImages
        Images used and dropped per camera.
    frame : FrameImages
        The reference object per camera.
    markers : int
        Markers on the wand (2 or 3).
    middle_ratio : float or None
        A 3-marker wand's middle marker from end A, in lengths.
    ratio_seen : float
        The middle ratio as the recording shows it (NaN for 2 markers).
    image_size_source : str
        ``"--image-size"`` or how it was chosen.
    wand_blobs : BlobFrames
        The wand recording's blobs.
    relabelled : bool
        A 2-marker wand's ends named again with a first calibration
        (:meth:`relabel`).
    """

    observations: WandObservations
    wand: WandImages
    frame: FrameImages
    markers: int
    middle_ratio: float | None
    ratio_seen: float
    image_size_source: str
    wand_blobs: BlobFrames
    relabelled: bool = False

    def relabel(self, rig: Rig, wand_ends: FloatArray) -> BlobCalibrationInputs:
        """A 2-marker wand's ends named by a first calibration's wand ends (F, 2, 3) mm
        (:func:`~spotlab.calibration.wand_relabel.relabel_two_ends`)."""
        blob_ok, image_ok = _usable(self.wand_blobs)
        wand = relabel_two_ends(
            self.wand_blobs.uv, self.wand_blobs.offsets, rig, wand_ends,
            usable_blob=blob_ok, usable_image=image_ok,
        )  # fmt: skip
        obs = replace(self.observations, wand=wand.ends)
        return replace(self, observations=obs, wand=wand, relabelled=True)

    def summary(self) -> dict[str, Any]:
        """JSON-safe figures: per camera the wand images used and dropped, the frame."""
        w, fr = self.wand, self.frame
        cams = []
        for c in range(w.used.size):
            cams.append(
                {
                    "name": f"cam{c + 1}",
                    "wand_used": int(w.used[c]),
                    "wand_ambiguous": int(w.ambiguous[c]),
                    "wand_missing": int(w.missing[c]),
                    "wand_unusable": int(w.unusable[c]),
                    "frame": fr.status[c],
                    "frame_static_blobs": int(fr.static_blobs[c]),
                }
            )
        return {
            "wand_markers": self.markers,
            "ends_relabelled": self.relabelled,
            "middle_ratio": self.middle_ratio,
            "middle_ratio_seen": None if np.isnan(self.ratio_seen) else self.ratio_seen,
            "image_size": [int(v) for v in self.observations.image_size],
            "image_size_source": self.image_size_source,
            "cameras": cams,
        }


def _usable(blobs: BlobFrames) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Blobs neither merged nor at the edge (N,), images neither offline nor overflowing."""
    blob_ok = (blobs.flags & (BLOB_MERGED | _BLOB_EDGE)) == 0
    return blob_ok, ~(blobs.offline | blobs.overflow)


def _image_size(blobs: BlobFrames, given: Sequence[int] | None) -> tuple[FloatArray, str]:
    if given is not None:
        if len(given) != 2 or min(given) <= 0:
            raise InputError(f"--image-size takes a positive width and height, got {given}")
        return np.asarray(given, dtype=np.float64), "--image-size"
    if blobs.uv.shape[0] == 0:
        raise InputError("the wand recording holds no blob: give --image-size W H")
    u, v = np.max(blobs.uv, axis=0)
    for w, h in SENSOR_SIZES:
        if u <= w - 1 and v <= h - 1:
            return np.array([w, h], dtype=np.float64), (
                "the smallest common sensor size holding every blob (give --image-size W H "
                "otherwise)"
            )
    raise InputError(f"blobs reach ({u:.0f}, {v:.0f}) px: give --image-size W H")


def _frame_points(path: Path) -> FloatArray:
    header, values = read_table(path)
    points = np.stack([column(header, values, a, path) for a in "XYZ"], axis=1)
    empty = np.flatnonzero(~np.isfinite(points).all(axis=1))
    if empty.size:
        raise InputError(f"{path}: row {empty[0] + 2} lacks a coordinate")
    if not 3 <= points.shape[0] <= 8:
        raise InputError(f"{path}: {points.shape[0]} markers; the reference object needs 3 to 8")
    return np.asarray(points)


def _wand_layout(
    blobs: BlobFrames, length: float, middle_mm: float | None, path: str
) -> tuple[int, float | None, float]:
    """Markers on the wand, its middle ratio (None for 2) and the ratio the images show."""
    blob_ok, image_ok = _usable(blobs)
    survey = survey_wand(
        blobs.uv, blobs.offsets, blobs.n_cameras, usable_blob=blob_ok, usable_image=image_ok
    )
    seen = survey.ratio_seen
    if middle_mm is None:
        if survey.three_in_line > survey.two:
            if not seen < 0.5 - RATIO_TOLERANCE:
                raise InputError(
                    f"{path}: the wand's middle marker sits at {seen:.2f} of its length, too "
                    "near the centre to tell its ends apart"
                )
            return 3, seen, seen
        return 2, None, seen
    if not 0 < middle_mm < length:
        raise InputError(
            f"--wand-middle {middle_mm:g} mm must lie between the wand's ends (0 and "
            f"--wand-length {length:g} mm)"
        )
    ratio = min(middle_mm, length - middle_mm) / length
    if np.isnan(seen) or survey.three_in_line < survey.two:
        raise InputError(
            f"{path}: --wand-middle names a 3-marker wand, but the cameras see two markers in "
            f"{survey.two} images and three on a line in {survey.three_in_line}"
        )
    if abs(ratio - seen) > RATIO_MISMATCH:
        raise InputError(
            f"the wand does not match the recording: --wand-middle {middle_mm:g} and "
            f"--wand-length {length:g} mm put the middle marker at {ratio:.3f} of the wand, "
            f"the recording shows it at {seen:.3f}; check the wand's dimensions"
        )
    if not ratio < 0.5 - RATIO_TOLERANCE:
        raise InputError(
            f"--wand-middle {middle_mm:g} mm is too near the centre of a {length:g} mm wand "
            "to tell its ends apart"
        )
    return 3, ratio, seen


def load_blob_recordings(
    wand_recording: Path,
    frame_recording: Path,
    frame_points_csv: Path,
    *,
    wand_length: float,
    wand_middle: float | None = None,
    image_size: Sequence[int] | None = None,
) -> BlobCalibrationInputs:
    """Wand and reference-object observations from video-centroid recordings.

    Parameters
    ----------
    wand_recording, frame_recording : Path
        Journals (``.spj``) of the wand dance and of the static reference object.
    frame_points_csv : Path
        The object's marker coordinates (mm): columns ``X``, ``Y``, ``Z``.
    wand_length : float
        Distance between the wand's end markers (mm).
    wand_middle : float, optional
        A 3-marker wand's middle marker, distance from end A (mm).
    image_size : (W, H), optional
        Image size (px) of every camera.

    Returns
    -------
    BlobCalibrationInputs

    Raises
    ------
    InputError
        Naming the cause: a recording of another kind or without frames, cameras that
        differ between the recordings, a points table that is not 3-8 rows of X, Y, Z,
        a wand whose middle ratio does not match the recording, a reference object found
        by fewer than two cameras.
    """
    if not wand_length > 0:
        raise InputError(f"--wand-length must be a positive length in mm, got {wand_length}")
    points = _frame_points(frame_points_csv)
    wand_rec = read_blob_recording(wand_recording).blobs
    frame_rec = read_blob_recording(frame_recording).blobs
    return find_calibration_inputs(
        wand_rec, frame_rec, points, wand_length=wand_length, wand_middle=wand_middle,
        image_size=image_size, names=(str(wand_recording), str(frame_recording),
                                      str(frame_points_csv)),
    )  # fmt: skip


def find_calibration_inputs(
    wand_rec: BlobFrames,
    frame_rec: BlobFrames,
    points: FloatArray,
    *,
    wand_length: float,
    wand_middle: float | None = None,
    image_size: Sequence[int] | None = None,
    names: tuple[str, str, str] = ("the wand recording", "the frame recording", "the points"),
) -> BlobCalibrationInputs:
    """The wand and the reference object found among decoded blobs.

    What :func:`load_blob_recordings` does once the journals are read: for blobs decoded
    otherwise (an in-process recording, a benchmark's scene).

    Parameters
    ----------
    wand_rec, frame_rec : BlobFrames
        Blobs of the wand dance and of the static reference object (one hub, C cameras).
    points : ndarray, shape (P, 3)
        The object's marker coordinates (mm), 3 <= P <= 8.
    wand_length, wand_middle, image_size
        As :func:`load_blob_recordings`.
    names : (str, str, str)
        How messages name the wand recording, the frame recording and the points.

    Returns
    -------
    BlobCalibrationInputs

    Raises
    ------
    InputError
        As :func:`load_blob_recordings`.
    """
    wand_name, frame_name, points_name = names
    if not wand_length > 0:
        raise InputError(f"--wand-length must be a positive length in mm, got {wand_length}")
    C = wand_rec.n_cameras
    if frame_rec.n_cameras != C:
        raise InputError(f"{frame_name}: {frame_rec.n_cameras} cameras, the wand recording has {C}")
    size, source = _image_size(wand_rec, image_size)
    markers, ratio, seen = _wand_layout(wand_rec, wand_length, wand_middle, wand_name)
    blob_ok, image_ok = _usable(wand_rec)
    wand = find_wand(
        wand_rec.uv, wand_rec.offsets, C, markers=markers, middle_ratio=ratio,
        usable_blob=blob_ok, usable_image=image_ok, peak=wand_rec.peak,
    )  # fmt: skip
    blob_ok, image_ok = _usable(frame_rec)
    frame = find_frame(
        frame_rec.uv, frame_rec.offsets, C, points, usable_blob=blob_ok, usable_image=image_ok,
        peak=frame_rec.peak,
    )  # fmt: skip
    found = [s == FOUND for s in frame.status]
    if sum(found) < 2:
        detail = ", ".join(f"cam{c + 1} {s}" for c, s in enumerate(frame.status))
        raise InputError(
            f"{frame_name}: the reference object's {points.shape[0]} markers were told "
            f"apart in {sum(found)} camera(s), 2 at least are needed ({detail}); is it the "
            f"object of {points_name}, standing still?"
        )
    obs = WandObservations(wand.ends, frame.uv, points, size)
    return BlobCalibrationInputs(obs, wand, frame, markers, ratio, seen, source, wand_rec)
