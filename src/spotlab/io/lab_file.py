"""A lab file: the devices of a lab, their settings, the timer's wiring, the rig and model.

The format (TOML) is described in docs/lab.md::

    rig = "rig.toml"            # optional, relative to the lab file
    model = "model.json"        # optional, relative to the lab file

    [[device]]
    family = "selspot"
    port = "/dev/ttyUSB0"
    name = "selspot0"           # optional stream name
    rate = 200                  # any other key is a setting of the family
    cameras = 2

    [wiring]                    # stream name -> timer input capturing its frame pulses
    selspot0 = 0

    [calibration]               # optional: the lab's wand and reference object
    wand_length = 500           # mm between the wand's end markers
    frame_points = "lframe.csv" # the reference object's X, Y, Z (mm), relative to the file
    wand_markers = [1, 2]       # SELSPOT-style systems: the wand's LED numbers
    frame_markers = [1, 2, 3, 4]  # ... and the reference object's

:func:`load_lab` checks the structure and the value types; which settings a
family takes is checked by the command that builds the drivers.
"""

from __future__ import annotations

import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from spotlab.core.errors import ConfigurationError

#: A setting's value as TOML gives it.
SettingValue = bool | int | float | str

TOP_KEYS = ("device", "wiring", "rig", "model", "calibration")
CALIBRATION_KEYS = ("wand_length", "frame_points", "wand_middle", "wand_markers", "frame_markers")
DEVICE_KEYS = ("family", "port", "name")


class LabFileError(ConfigurationError):
    """A lab file that cannot be read or holds something it may not; the message names
    the file and the key."""


@dataclass(frozen=True)
class LabDevice:
    """One device of a lab file.

    Attributes
    ----------
    family : str
        Driver family (``selspot``, ``timer``, ...).
    port : str
        Device path or pyserial URL.
    name : str or None
        Stream name, or None for the default (family and index).
    settings : dict of str to value
        The family's settings (``rate``, ``cameras``, ...), as written.
    where : str
        ``FILE: device[i]``, for messages.
    """

    family: str
    port: str
    name: str | None
    settings: dict[str, SettingValue]
    where: str


@dataclass(frozen=True)
class LabCalibration:
    """The ``[calibration]`` table: the lab's wand and reference object (docs/lab.md).

    Attributes
    ----------
    wand_length : float
        Distance between the wand's end markers, mm.
    frame_points : Path
        CSV of the reference object's markers, columns ``X``, ``Y``, ``Z`` in mm.
    wand_middle : float or None
        A 3-marker wand's middle marker, mm from end A (video-centroid hubs).
    wand_markers, frame_markers : tuple of int or None
        Marker (LED) numbers, 1-based, of the wand's ends and of the reference object's
        markers (SELSPOT-style systems, whose markers carry numbers).
    """

    wand_length: float
    frame_points: Path
    wand_middle: float | None = None
    wand_markers: tuple[int, ...] | None = None
    frame_markers: tuple[int, ...] | None = None


@dataclass(frozen=True)
class Lab:
    """A loaded lab file.

    Attributes
    ----------
    path : Path
        The file.
    devices : tuple of LabDevice
        In the file's order.
    wiring : dict of str to int
        Stream name -> timer input (0-7) capturing its frame pulses.
    rig, model : Path or None
        The current rig (TOML) and marker model (JSON), resolved against the file's folder.
    calibration : LabCalibration or None
        The lab's wand and reference object, for the console's calibration wizard.
    """

    path: Path
    devices: tuple[LabDevice, ...]
    wiring: dict[str, int] = field(default_factory=dict)
    rig: Path | None = None
    model: Path | None = None
    calibration: LabCalibration | None = None


def _fail(path: Path, key: str, message: str) -> LabFileError:
    return LabFileError(f"lab file {path}: {key}: {message}")


def _path(path: Path, key: str, value: object) -> Path | None:
    if value is None:
        return None
    if not isinstance(value, str) or not value:
        raise _fail(path, key, f"expected a file path (a string), got {value!r}")
    p = Path(value).expanduser()
    return p if p.is_absolute() else path.parent / p


def _device(path: Path, index: int, table: object) -> LabDevice:
    where = f"device[{index}]"
    if not isinstance(table, dict):
        raise _fail(path, where, "expected a [[device]] table")
    for key in ("family", "port"):
        value = table.get(key)
        if not isinstance(value, str) or not value:
            raise _fail(path, f"{where}.{key}", f"expected a non-empty string, got {value!r}")
    name = table.get("name")
    if name is not None and (not isinstance(name, str) or not name):
        raise _fail(path, f"{where}.name", f"expected a non-empty string, got {name!r}")
    settings: dict[str, SettingValue] = {}
    for key, value in table.items():
        if key in DEVICE_KEYS:
            continue
        if not isinstance(value, bool | int | float | str):
            raise _fail(path, f"{where}.{key}", f"expected a number or a string, got {value!r}")
        settings[key] = value
    return LabDevice(table["family"], table["port"], name, settings, f"{path}: {where}")


def _length(path: Path, key: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not value > 0:
        raise _fail(path, key, f"expected a positive length in mm, got {value!r}")
    return float(value)


def _markers(path: Path, key: str, value: object) -> tuple[int, ...] | None:
    if value is None:
        return None
    if (
        not isinstance(value, list)
        or not value
        or not all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in value)
    ):
        raise _fail(path, key, f"expected a list of marker numbers (1, 2, ...), got {value!r}")
    return tuple(value)


def _calibration(path: Path, table: object) -> LabCalibration | None:
    if table is None:
        return None
    if not isinstance(table, dict):
        raise _fail(path, "calibration", "expected a [calibration] table")
    unknown = [k for k in table if k not in CALIBRATION_KEYS]
    if unknown:
        raise _fail(
            path, f"calibration.{unknown[0]}", f"unknown key ({', '.join(CALIBRATION_KEYS)})"
        )
    for key in ("wand_length", "frame_points"):
        if key not in table:
            raise _fail(path, f"calibration.{key}", "missing")
    points = _path(path, "calibration.frame_points", table["frame_points"])
    assert points is not None
    middle = table.get("wand_middle")
    return LabCalibration(
        _length(path, "calibration.wand_length", table["wand_length"]),
        points,
        None if middle is None else _length(path, "calibration.wand_middle", middle),
        _markers(path, "calibration.wand_markers", table.get("wand_markers")),
        _markers(path, "calibration.frame_markers", table.get("frame_markers")),
    )


def load_lab(path: str | os.PathLike[str]) -> Lab:
    """Read and check a lab file.

    Raises
    ------
    LabFileError
        If the file cannot be read, is not TOML, or a key is unknown, missing or of
        the wrong type; the message names the file and the key.
    """
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise LabFileError(f"lab file {p}: cannot read it: {exc.strerror or exc}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise LabFileError(f"lab file {p}: not TOML: {exc}") from None
    unknown = [k for k in data if k not in TOP_KEYS]
    if unknown:
        raise _fail(p, unknown[0], f"unknown key (a lab file holds {', '.join(TOP_KEYS)})")
    tables = data.get("device", [])
    if not isinstance(tables, list) or not tables:
        raise _fail(p, "device", "expected one or more [[device]] tables")
    devices = tuple(_device(p, i, t) for i, t in enumerate(tables))
    wiring_table = data.get("wiring", {})
    if not isinstance(wiring_table, dict):
        raise _fail(p, "wiring", "expected a [wiring] table of STREAM = INPUT")
    wiring: dict[str, int] = {}
    for stream, value in wiring_table.items():
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 7:
            raise _fail(p, f"wiring.{stream}", f"expected a timer input 0-7, got {value!r}")
        wiring[stream] = value
    return Lab(
        p,
        devices,
        wiring,
        _path(p, "rig", data.get("rig")),
        _path(p, "model", data.get("model")),
        _calibration(p, data.get("calibration")),
    )
