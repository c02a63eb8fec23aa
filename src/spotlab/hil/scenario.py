"""Scenario files: a lab of simulators, its motion, faults, processing and pass criteria.

The format (TOML) is described in docs/hil.md; it is a lab file
(:mod:`spotlab.io.lab_file`) whose devices are simulators::

    name = "gait lab"
    duration = 8.0                  # seconds recorded
    seed = 1                        # simulators' seeds are seed, seed + 1, ... (--seed)

    [motion]                        # of the SELSPOT simulators
    kind = "gait"                   # a generated motion, or
    c3d = "shared:bmc/Gait.c3d"     # a C3D file (relative to the scenario, or shared:)

    [[device]]
    family = "selspot"
    name = "selspot0"               # stream name (criteria name it)
    transport = "pty"               # pty (serial families) or tcp
    rate = 200                      # any other key: a setting of the family (docs/lab.md)
    [device.sim]                    # the simulator: clock, faults, scene
    clock_drift_ppm = 200
    faults = "bitflip@2,drop@3"

    [processing]
    steps = ["timestamps", "reconstruction", "export"]

    [criteria]
    sync_error_us = { max = 50 }
    [criteria.selspot0]
    lost_frames = { max = 3 }

:func:`load_scenario` checks all of it before anything starts; every error names
the file, the line and the key (:class:`ScenarioError`).
"""

from __future__ import annotations

import os
import tomllib
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from spotlab.core.errors import ConfigurationError
from spotlab.hil.toml_lines import KeyPath, line_of

TOP_KEYS = ("name", "description", "duration", "seed", "motion", "device", "processing",
            "criteria", "rig", "model")  # fmt: skip
DEVICE_KEYS = ("family", "name", "transport", "sim")
FAMILIES = ("selspot", "timer", "centroid", "qualisys", "natnet")
SERIAL_FAMILIES = ("selspot", "timer", "centroid")
#: Simulator options (``spotlab sim --key-with-dashes``); lists repeat the option.
SIM_KEYS = (
    "seed", "faults", "clock_offset", "clock_drift_ppm", "clock_jitter", "clock_steps",
    "motion", "markers", "ghosts", "noise_blobs", "sunlight", "camera_off", "ring_phase",
    "wand_length", "reflectance", "natnet_version", "password", "inputs", "port", "seconds",
)  # fmt: skip
STEPS = ("calibration", "model", "timestamps", "reconstruction", "labelling", "export")
MOTIONS = ("wand", "cluster", "gait", "lframe")
#: Figures of a device that a processing step gives, the family and step each needs.
DEVICE_STEP_FIGURES = {
    "error_3d_rms_mm": ("selspot", "reconstruction"),
    "error_3d_max_mm": ("selspot", "reconstruction"),
    "labelled_fraction": ("centroid", "labelling"),
    "wrong_label_fraction": ("centroid", "labelling"),
    "label_error_rms_mm": ("centroid", "labelling"),
    "error_3d_rms_true_rig_mm": ("selspot", "calibration"),
    "error_3d_excess": ("selspot", "calibration"),
    "calibration_rms": ("selspot or centroid", "calibration"),
}
#: Figures of every device (docs/hil.md).
DEVICE_FIGURES = ("frames", "frames_sent", "frames_missing", "lost_frames", "crc_errors",
                  "resyncs", "duplicates", "gaps", "reconnects", "faults_injected",
                  "rate_hz", "latency_p50_ms", "latency_p99_ms", "latency_max_ms",
                  "startup_backlog_ms", "latency_p50_start_ms", "latency_p50_end_ms",
                  "latency_p99_start_ms", "latency_p99_end_ms",
                  "latency_p50_growth_ms", *DEVICE_STEP_FIGURES)  # fmt: skip
#: Figures of the run, and what each needs.
RUN_FIGURES = {
    "sync_error_us": "a timer with wired inputs and the 'timestamps' step",
    "sync_error_timed_us": "a timer with wired inputs and the 'timestamps' step",
    "error_3d_rms_mm": "a single device, a selspot, and the 'reconstruction' step",
    "error_3d_max_mm": "a single device, a selspot, and the 'reconstruction' step",
    "labelled_fraction": "a single device, a centroid hub, and the 'labelling' step",
    "wrong_label_fraction": "a single device, a centroid hub, and the 'labelling' step",
    "label_error_rms_mm": "a single device, a centroid hub, and the 'labelling' step",
    "record_exit_code": "",
    "record_rss_start_mb": "",
    "record_rss_end_mb": "",
    "record_rss_growth_mb": "",
    "record_rss_peak_mb": "",
}
BOUNDS = ("min", "max")


class ScenarioError(ConfigurationError):
    """A scenario that cannot be run as written; the message names file, line and key."""


@dataclass(frozen=True)
class SimDevice:
    """A simulated device of a scenario.

    Attributes
    ----------
    family, name, transport : str
        Family, stream name, ``pty`` or ``tcp``.
    settings : dict
        The family's settings as a lab file holds them (``rate``, ``cameras``, ...).
    sim : dict
        Simulator options (:data:`SIM_KEYS`).
    index : int
        Position in the file (``device[index]``).
    """

    family: str
    name: str
    transport: str
    settings: dict[str, Any]
    sim: dict[str, Any]
    index: int


@dataclass(frozen=True)
class Criterion:
    """A pass criterion: ``figure`` within ``[low, high]`` (either may be None)."""

    figure: str
    low: float | None
    high: float | None
    line: int

    def holds(self, value: float | None) -> bool:
        """Whether ``value`` is within the bounds (a missing value never is)."""
        if value is None:
            return False
        return (self.low is None or value >= self.low) and (self.high is None or value <= self.high)

    def describe(self) -> str:
        """``selspot0.lost_frames <= 3``."""
        parts = []
        if self.low is not None:
            parts.append(f">= {self.low:g}")
        if self.high is not None:
            parts.append(f"<= {self.high:g}")
        return f"{self.figure} {' and '.join(parts)}"


@dataclass(frozen=True)
class Scenario:
    """A loaded, checked scenario file."""

    path: Path
    name: str
    description: str
    duration_s: float
    seed: int
    devices: tuple[SimDevice, ...]
    motion: str | None
    steps: tuple[str, ...]
    criteria: tuple[Criterion, ...]
    wiring: dict[str, int] = field(default_factory=dict)
    rig: Path | None = None
    model: Path | None = None


class _Checker:
    """Error messages with the file, line and key."""

    def __init__(self, path: Path, text: str) -> None:
        self.path = path
        self.text = text

    def fail(self, key: KeyPath, message: str) -> ScenarioError:
        dotted = "".join(f"[{k}]" if isinstance(k, int) else f".{k}" for k in key).lstrip(".")
        return ScenarioError(f"{self.path}:{line_of(self.text, key)}: {dotted}: {message}")

    def line(self, key: KeyPath) -> int:
        return line_of(self.text, key)

    def unknown(self, table: Mapping[str, Any], known: Collection[str], key: KeyPath) -> None:
        for name in table:
            if name not in known:
                raise self.fail([*key, name], f"unknown key (known: {', '.join(known)})")

    def number(self, value: Any, key: KeyPath, positive: bool = False) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.fail(key, f"expected a number, got {value!r}")
        if positive and value <= 0:
            raise self.fail(key, f"must be positive, got {value!r}")
        return float(value)


def shared_data() -> Path:
    """The reference data: ``$SPOTLAB_SHARED_DATA``, else ``../shared/data`` from here."""
    env = os.environ.get("SPOTLAB_SHARED_DATA")
    return Path(env) if env else Path.cwd().parent / "shared" / "data"


def _motion(c: _Checker, table: Any) -> str | None:
    if table is None:
        return None
    if not isinstance(table, dict):
        raise c.fail(["motion"], "expected a [motion] table")
    c.unknown(table, ("kind", "c3d"), ["motion"])
    if ("kind" in table) == ("c3d" in table):
        raise c.fail(["motion"], "give either kind (a generated motion) or c3d (a file)")
    if "kind" in table:
        if table["kind"] not in MOTIONS:
            raise c.fail(["motion", "kind"], f"expected one of {', '.join(MOTIONS)}")
        return str(table["kind"])
    value = table["c3d"]
    if not isinstance(value, str) or not value:
        raise c.fail(["motion", "c3d"], "expected a file path")
    if value.startswith("shared:"):
        file = shared_data() / value.removeprefix("shared:")
    else:
        file = Path(value).expanduser()
        file = file if file.is_absolute() else c.path.parent / file
    if not file.is_file():
        raise c.fail(["motion", "c3d"], f"no such file: {file}")
    return str(file)


def _device(
    c: _Checker, index: int, table: Any, settings_of: Mapping[str, Collection[str]] | None
) -> SimDevice:
    key: list[str | int] = ["device", index]
    if not isinstance(table, dict):
        raise c.fail(key, "expected a [[device]] table")
    family = table.get("family")
    if family not in FAMILIES:
        raise c.fail([*key, "family"], f"expected one of {', '.join(FAMILIES)}, got {family!r}")
    name = table.get("name")
    if not isinstance(name, str) or not name.isidentifier():
        raise c.fail([*key, "name"], f"expected a stream name (a word), got {name!r}")
    transport = table.get("transport", "pty" if family in SERIAL_FAMILIES else "tcp")
    if transport not in ("pty", "tcp"):
        raise c.fail([*key, "transport"], f"expected pty or tcp, got {transport!r}")
    if transport == "pty" and family not in SERIAL_FAMILIES:
        raise c.fail([*key, "transport"], f"a {family} server speaks TCP only")
    settings = {k: v for k, v in table.items() if k not in DEVICE_KEYS}
    known = settings_of.get(family) if settings_of is not None else None
    for k, v in settings.items():
        if known is not None and k not in known:
            raise c.fail([*key, k], f"unknown key for a {family} device (known: "
                                    f"{', '.join([*DEVICE_KEYS, *known])})")  # fmt: skip
        if not isinstance(v, bool | int | float | str):
            raise c.fail([*key, k], f"expected a number or a string, got {v!r}")
    sim = table.get("sim", {})
    if not isinstance(sim, dict):
        raise c.fail([*key, "sim"], "expected a [device.sim] table")
    c.unknown(sim, SIM_KEYS, [*key, "sim"])
    if "inputs" in sim and family != "timer":
        raise c.fail([*key, "sim", "inputs"], "only a timer has inputs")
    if "port" in sim and transport != "tcp":
        raise c.fail([*key, "sim", "port"], "only a tcp simulator has a port")
    return SimDevice(family, name, transport, settings, dict(sim), index)


def _wiring(c: _Checker, devices: tuple[SimDevice, ...]) -> dict[str, int]:
    names = {d.name for d in devices}
    wiring: dict[str, int] = {}
    for d in devices:
        inputs = d.sim.get("inputs", {})
        key: list[str | int] = ["device", d.index, "sim", "inputs"]
        if not isinstance(inputs, dict):
            raise c.fail(key, "expected a table of input number = device name")
        for number, source in inputs.items():
            if not number.isdigit() or not 0 <= int(number) <= 7:
                raise c.fail([*key, number], "a timer input is a number 0-7")
            if source not in names or source == d.name:
                raise c.fail([*key, number], f"no other device named {source!r}")
            wiring[str(source)] = int(number)
    return wiring


def _criteria(
    c: _Checker,
    table: Any,
    scenario_devices: tuple[SimDevice, ...],
    steps: tuple[str, ...],
    wiring: Mapping[str, int],
) -> tuple[Criterion, ...]:
    if table is None:
        return ()
    if not isinstance(table, dict):
        raise c.fail(["criteria"], "expected a [criteria] table")
    devices = {d.name: d for d in scenario_devices}
    out: list[Criterion] = []

    def bound(figure: str, value: Any, key: list[str | int]) -> None:
        if not isinstance(value, dict) or not value:
            raise c.fail(key, "expected { max = N } and/or { min = N }")
        c.unknown(value, BOUNDS, key)
        low = c.number(value["min"], [*key, "min"]) if "min" in value else None
        high = c.number(value["max"], [*key, "max"]) if "max" in value else None
        out.append(Criterion(figure, low, high, c.line(key)))

    for name, value in table.items():
        key: list[str | int] = ["criteria", name]
        if name in devices:
            if not isinstance(value, dict):
                raise c.fail(key, "expected a table of figure = { max = N }")
            for figure, limits in value.items():
                if figure not in DEVICE_FIGURES:
                    raise c.fail([*key, figure], "no such figure of a device (known: "
                                                 f"{', '.join(DEVICE_FIGURES)})")  # fmt: skip
                if figure in DEVICE_STEP_FIGURES:
                    family, step = DEVICE_STEP_FIGURES[figure]
                    if devices[name].family not in family.split(" or ") or step not in steps:
                        raise c.fail([*key, figure], f"this figure needs a {family} device "
                                                     f"and the {step!r} step")  # fmt: skip
                bound(f"{name}.{figure}", limits, [*key, figure])
        elif name in RUN_FIGURES:
            need = _missing_for(name, scenario_devices, steps, wiring)
            if need:
                raise c.fail(key, f"this figure needs {need}")
            bound(name, value, key)
        else:
            known = ", ".join([*RUN_FIGURES, *devices])
            raise c.fail(key, f"no such figure or device (known: {known})")
    return tuple(out)


def _missing_for(
    figure: str, devices: tuple[SimDevice, ...], steps: tuple[str, ...], wiring: Mapping[str, int]
) -> str:
    """What ``figure`` needs that the scenario lacks ("" when nothing)."""
    if figure.startswith("sync_error") and (not wiring or "timestamps" not in steps):
        return RUN_FIGURES[figure]
    alone = len(devices) == 1 and devices[0].family == "selspot"
    if figure.startswith("error_3d") and (not alone or "reconstruction" not in steps):
        return RUN_FIGURES[figure]
    hub = len(devices) == 1 and devices[0].family == "centroid"
    if "label" in figure and (not hub or "labelling" not in steps):
        return RUN_FIGURES[figure]
    return ""


def load_scenario(
    path: str | os.PathLike[str], settings_of: Mapping[str, Collection[str]] | None = None
) -> Scenario:
    """Read and check a scenario file.

    Parameters
    ----------
    path : path-like
        The TOML file.
    settings_of : mapping, optional
        Family -> the settings its devices take (the command line's table); unchecked
        when None.

    Raises
    ------
    ScenarioError
        Naming the file, the line and the key.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ScenarioError(f"{p}: cannot read it: {exc.strerror or exc}") from None
    c = _Checker(p, text)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{p}: not TOML: {exc}") from None
    c.unknown(data, TOP_KEYS, [])
    name = data.get("name", p.stem)
    if not isinstance(name, str) or not name:
        raise c.fail(["name"], "expected a non-empty string")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise c.fail(["description"], "expected a string")
    if "duration" not in data:
        raise c.fail([], "duration: missing (seconds recorded)")
    duration = c.number(data["duration"], ["duration"], positive=True)
    seed = data.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise c.fail(["seed"], f"expected an integer, got {seed!r}")
    tables = data.get("device")
    if not isinstance(tables, list) or not tables:
        raise c.fail(["device"], "expected one or more [[device]] tables")
    devices = tuple(_device(c, i, t, settings_of) for i, t in enumerate(tables))
    seen: set[str] = set()
    for d in devices:
        if d.name in seen:
            raise c.fail(["device", d.index, "name"], f"{d.name!r} names two devices")
        seen.add(d.name)
    wiring = _wiring(c, devices)
    processing = data.get("processing", {})
    if not isinstance(processing, dict):
        raise c.fail(["processing"], "expected a [processing] table")
    c.unknown(processing, ("steps",), ["processing"])
    steps = processing.get("steps", [])
    if not isinstance(steps, list) or any(s not in STEPS for s in steps):
        raise c.fail(["processing", "steps"], f"expected a list of {', '.join(STEPS)}")
    if "export" in steps and not {"reconstruction", "labelling"} & set(steps):
        raise c.fail(["processing", "steps"], "'export' writes the reconstruction: add it")
    families = {d.family for d in devices}
    for step, need in (
        ("labelling", {"centroid"}),
        ("reconstruction", {"selspot"}),
        ("calibration", {"selspot", "centroid"}),
        ("model", {"centroid"}),
    ):
        if step in steps and not need & families:
            kinds = " or ".join(sorted(need))
            raise c.fail(["processing", "steps"],
                         f"{step!r} takes a single {kinds} device or more: none here")  # fmt: skip
    if "model" in steps and "calibration" not in steps:
        raise c.fail(["processing", "steps"], "'model' learns with the rig: add 'calibration'")
    criteria = _criteria(c, data.get("criteria"), devices, tuple(steps), wiring)
    rig = _lab_path(c, "rig", data.get("rig"))
    model = _lab_path(c, "model", data.get("model"))
    return Scenario(p, name, description, duration, seed, devices, _motion(c, data.get("motion")),
                    tuple(steps), criteria, wiring, rig, model)  # fmt: skip


def _lab_path(c: _Checker, key: str, value: Any) -> Path | None:
    if value is None:
        return None
    if not isinstance(value, str) or not value:
        raise c.fail([key], "expected a file path")
    file = Path(value).expanduser()
    return file if file.is_absolute() else c.path.parent / file


__all__ = [
    "DEVICE_FIGURES",
    "RUN_FIGURES",
    "Criterion",
    "Scenario",
    "ScenarioError",
    "SimDevice",
    "load_scenario",
    "shared_data",
]
