"""A rig of cameras and its calibration files (anipose / Pose2Sim TOML, OpenCV YAML)."""

from __future__ import annotations

import json
import os
import tomllib
from collections.abc import Iterable, Iterator
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from spotlab.core.errors import CalibrationError
from spotlab.geometry import _checks
from spotlab.geometry._checks import FloatArray
from spotlab.geometry.camera import Camera

__all__ = ["Rig"]

_PathLike = str | os.PathLike[str]


def _toml_array(values: Iterable[Any]) -> str:
    return "[ " + ", ".join(repr(float(v)) for v in values) + ",]"


class Rig:
    """An ordered set of cameras observing the same world frame.

    Parameters
    ----------
    cameras : iterable of Camera
        At least one camera.

    Raises
    ------
    CalibrationError
        When empty or when an item is not a :class:`Camera`.
    """

    __slots__ = ("cameras",)

    def __init__(self, cameras: Iterable[Camera]) -> None:
        cams = tuple(cameras)
        if not cams:
            raise CalibrationError("a Rig needs at least one camera")
        for i, cam in enumerate(cams):
            if not isinstance(cam, Camera):
                raise CalibrationError(f"Rig item {i} is a {type(cam).__name__}, not a Camera")
        self.cameras: tuple[Camera, ...] = cams

    def __len__(self) -> int:
        return len(self.cameras)

    def __iter__(self) -> Iterator[Camera]:
        return iter(self.cameras)

    def __getitem__(self, index: int) -> Camera:
        return self.cameras[index]

    def __repr__(self) -> str:
        return f"Rig({len(self.cameras)} cameras: {', '.join(map(repr, self.names))})"

    @property
    def names(self) -> list[str]:
        """Camera names, in rig order."""
        return [cam.name for cam in self.cameras]

    def project(self, X: Any) -> FloatArray:
        """Project world points into every camera.

        Parameters
        ----------
        X : array_like, shape (..., 3)
            World points (mm).

        Returns
        -------
        ndarray, shape (C, ..., 2)
            Pixel coordinates per camera; NaN behind a camera or for NaN input.
        """
        X = _checks.points(X, 3, "X (world points)")
        return np.stack([cam.project(X) for cam in self.cameras])

    def save(self, path: _PathLike) -> None:
        """Write the rig as an anipose / Pose2Sim calibration TOML file.

        One table ``[cam_<i>]`` per camera (``i`` zero-padded beyond 10 cameras, so
        that anipose's sorted reading keeps the rig order) with ``name``, ``size`` (width, height),
        ``matrix`` (K), ``distortions`` (k1, k2, p1, p2, k3), ``rotation`` (Rodrigues
        vector of ``R``, radians) and ``translation`` (``t``), then ``[metadata]``.
        Values are written as they are: spotlab works in mm, so ``translation`` is in
        mm (anipose files carry whatever unit their user calibrated in). Floats are
        written with ``repr`` so a load gives back the same numbers.
        """
        lines: list[str] = []
        # Zero-padded keys when there are more than 10 cameras: aniposelib's
        # CameraGroup.load sorts the table names as strings (cam_10 before cam_2).
        width = len(str(len(self.cameras) - 1))
        for i, cam in enumerate(self.cameras):
            rvec = Rotation.from_matrix(cam.R).as_rotvec()
            lines += [
                f"[cam_{i:0{width}d}]",
                f"name = {json.dumps(cam.name)}",
                f"size = [ {cam.size[0]}, {cam.size[1]},]",
                "matrix = [ " + " ".join(_toml_array(row) + "," for row in cam.K) + "]",
                f"distortions = {_toml_array(cam.dist)}",
                f"rotation = {_toml_array(rvec)}",
                f"translation = {_toml_array(cam.t)}",
                "",
            ]
        lines += ["[metadata]", 'written_by = "spotlab"', 'translation_unit = "mm"', ""]
        with open(path, "w", encoding="utf-8") as fh:
            fh.write("\n".join(lines))

    @classmethod
    def load(cls, path: _PathLike, *, sort_tables: bool = False) -> Rig:
        """Read an anipose / Pose2Sim calibration TOML file.

        Every top-level table except ``metadata`` is a camera, in file order (as
        Pose2Sim reads it), or with ``sort_tables=True`` in the order of the table names
        sorted as strings, as aniposelib's ``CameraGroup.load`` does (``cam_0, cam_1,
        cam_10, cam_11, cam_2, ...``: it differs from the file order beyond 10 cameras
        when the names are not zero-padded). A missing ``name`` defaults to the key.
        Pose2Sim's 4 distortion terms mean ``k3 = 0``. Values are kept as they are (no
        unit conversion): anipose and Pose2Sim translations are in the unit of the
        calibration object used (often m), spotlab's are in mm; convert with
        ``Camera(K, dist, R, t * 1000, size)``.

        Raises
        ------
        CalibrationError
            When the file is not TOML, has no camera, or a camera entry is invalid
            (the message names the table and the field).
        """
        try:
            with open(path, "rb") as fh:
                doc = tomllib.load(fh)
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise CalibrationError(f"{os.fspath(path)}: not a valid TOML file: {exc}") from None
        cams = []
        keys = sorted(doc) if sort_tables else list(doc)
        for key in keys:
            table = doc[key]
            if key == "metadata" or not isinstance(table, dict):
                continue
            try:
                if table.get("fisheye", False):
                    raise CalibrationError("fisheye cameras are not supported")
                rvec = _checks.finite_array(table["rotation"], (3,), "rotation")
                cams.append(
                    Camera(
                        table["matrix"],
                        table["distortions"],
                        Rotation.from_rotvec(rvec).as_matrix(),
                        table["translation"],
                        table["size"],
                        str(table.get("name", key)),
                    )
                )
            except KeyError as exc:
                raise CalibrationError(
                    f"{os.fspath(path)}: table [{key}] lacks the field {exc}"
                ) from None
            except CalibrationError as exc:
                raise CalibrationError(f"{os.fspath(path)}: table [{key}]: {exc}") from None
        if not cams:
            raise CalibrationError(f"{os.fspath(path)}: no camera table found")
        return cls(cams)

    def to_opencv_yaml(self, path: _PathLike) -> None:
        """Export the rig for OpenCV's ``cv::FileStorage`` (``%YAML:1.0``).

        Per camera ``camera_<i>``: ``name``, ``image_width``, ``image_height``,
        ``camera_matrix`` (3x3), ``distortion_coefficients`` (1x5), ``rotation_matrix``
        (3x3), ``rvec`` (3x1 Rodrigues) and ``tvec`` (3x1, mm), as ``!!opencv-matrix``
        nodes of doubles.
        """

        def matrix(key: str, arr: FloatArray) -> list[str]:
            rows, cols = arr.shape if arr.ndim == 2 else (arr.size, 1)
            data = ", ".join(repr(float(v)) for v in arr.ravel())
            return [
                f"   {key}: !!opencv-matrix",
                f"      rows: {rows}",
                f"      cols: {cols}",
                "      dt: d",
                f"      data: [ {data} ]",
            ]

        lines = ["%YAML:1.0", "---", f"camera_count: {len(self.cameras)}"]
        for i, cam in enumerate(self.cameras):
            lines += [
                f"camera_{i}:",
                f"   name: {json.dumps(cam.name)}",
                f"   image_width: {cam.size[0]}",
                f"   image_height: {cam.size[1]}",
            ]
            lines += matrix("camera_matrix", cam.K)
            lines += matrix("distortion_coefficients", cam.dist.reshape(1, 5))
            lines += matrix("rotation_matrix", cam.R)
            lines += matrix("rvec", Rotation.from_matrix(cam.R).as_rotvec())
            lines += matrix("tvec", cam.t)
        with open(path, "w", encoding="utf-8") as fh:
            fh.write("\n".join(lines) + "\n")
