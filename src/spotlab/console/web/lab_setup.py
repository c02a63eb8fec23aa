"""The lab the console acquires from: a lab file, or the simulated lab of ``--sim``.

``--sim`` writes a lab file of its own (``DATA/.sim/lab.toml``: the dot keeps it apart
from trial names) naming three in-process simulators (``sim://`` URLs): a SELSPOT-style
system of 2 cameras x 8 LEDs on a gait, a video-centroid hub of 2 cameras and a timer,
all at 100 Hz. Its rig is the SELSPOT simulator's true calibration, which the simulator
writes itself (``rig_out``) when its port is first opened; the console never imports
the simulators (pyserial loads their ``sim://`` handler by name).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import serial

from spotlab.console.device_settings import FAMILY_SETTINGS, requests_from_lab
from spotlab.console.errors import CommandError
from spotlab.drivers import Driver, load_driver
from spotlab.io.lab_file import Lab, load_lab
from spotlab.processing.errors import InputError

__all__ = ["LabPlan", "plan_lab", "settings_of", "sim_lab_file", "with_rate", "with_settings"]

#: Rate of every simulated device, Hz.
SIM_RATE_HZ = 100
#: pyserial's package of the simulators' ``sim://`` handler.
_SIM_HANDLERS = "spotlab.simulators.transports"


@dataclass(frozen=True)
class LabPlan:
    """The devices to acquire from.

    Attributes
    ----------
    lab : Lab
        The lab file, as read.
    simulated : bool
        Whether it is the simulated lab of ``--sim``.
    """

    lab: Lab
    simulated: bool

    def names(self) -> list[str]:
        """The stream name of each device of the lab, in the file's order: its ``name``,
        else its family (numbered from 0 when the family has several devices)."""
        requests = requests_from_lab(self.lab.devices, {})
        counts: dict[str, int] = {}
        for r in requests:
            counts[r.family] = counts.get(r.family, 0) + 1
        seen: dict[str, int] = {}
        names = []
        for r in requests:
            n = seen.get(r.family, 0)
            seen[r.family] = n + 1
            default = r.family if counts[r.family] == 1 else f"{r.family}{n}"
            names.append(r.name or default)
        return names

    def drivers(self) -> list[Driver]:
        """New driver objects for every device of the lab (not started)."""
        drivers: list[Driver] = [
            load_driver(r.family)(r.port, name=name, **r.options)
            for r, name in zip(requests_from_lab(self.lab.devices, {}), self.names(), strict=True)
        ]
        names = [d.name for d in drivers]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise InputError(f"stream name {twice[0]!r} is given to several devices")
        return drivers


def with_settings(plan: LabPlan, name: str, settings: object) -> LabPlan:
    """``plan`` with device ``name``'s settings changed (the lab file is not changed).

    Parameters
    ----------
    plan : LabPlan
    name : str
        A device of the lab.
    settings : mapping of str to int, float or str
        Settings of the device's family (:data:`FAMILY_SETTINGS`, the lab file's keys:
        ``rate``, ``leds``, ``exposure``, ...), checked as a lab file's are.

    Raises
    ------
    InputError
        For no such device, no setting, a key the family does not have, or a value the
        setting does not take.
    """
    names = plan.names()
    if name not in names:
        raise InputError(f"no device {name!r} in the lab (it has {', '.join(names)})")
    if not isinstance(settings, dict) or not settings:
        raise InputError('settings must be an object of at least one "setting": value')
    index = names.index(name)
    device = plan.lab.devices[index]
    known = FAMILY_SETTINGS.get(device.family, {})
    for key, value in settings.items():
        if key not in known:
            has = ", ".join(known) or "none"
            raise InputError(f"a {device.family} device has no setting {key!r} (it has {has})")
        if isinstance(value, bool) or not isinstance(value, int | float | str):
            raise InputError(f"setting {key!r} must be a number or a word, got {value!r}")
    changed = dataclasses.replace(device, settings={**device.settings, **settings})
    devices = (*plan.lab.devices[:index], changed, *plan.lab.devices[index + 1 :])
    new = LabPlan(dataclasses.replace(plan.lab, devices=devices), plan.simulated)
    try:
        requests_from_lab(new.lab.devices, {})
    except CommandError as exc:
        raise InputError(str(exc)) from None
    return new


def with_rate(plan: LabPlan, name: str, rate_hz: object) -> LabPlan:
    """``plan`` with device ``name`` set to ``rate_hz`` (Hz): :func:`with_settings` of
    ``rate`` (InputError also for a rate that is not a positive number)."""
    if isinstance(rate_hz, bool) or not isinstance(rate_hz, int | float) or not rate_hz > 0:
        raise InputError(f"rate_hz must be a positive number, got {rate_hz!r}")
    return with_settings(plan, name, {"rate": float(rate_hz)})


def settings_of(plan: LabPlan, name: str) -> dict[str, object]:
    """The settings device ``name`` is given (the lab file's, with what the console
    changed); a setting not given keeps what the device has."""
    index = plan.names().index(name)
    return dict(plan.lab.devices[index].settings)


def sim_lab_file(data: Path) -> Path:
    """Write the simulated lab's file under ``data/.sim`` and its true rig; the file's path."""
    folder = data / ".sim"
    folder.mkdir(parents=True, exist_ok=True)
    rig = folder / "rig.toml"
    selspot = f"sim://selspot?cameras=2&leds=8&rate={SIM_RATE_HZ}&seed=1&motion=gait&rig_out={rig}"
    centroid = f"sim://centroid?cameras=2&markers=6&rate={SIM_RATE_HZ}&seed=2"
    timer = f"sim://timer?rate={SIM_RATE_HZ}"
    path = folder / "lab.toml"
    path.write_text(
        "# The simulated lab of `spotlab console --sim` (written by the console).\n"
        'rig = "rig.toml"  # the SELSPOT simulator\'s true calibration\n\n'
        f'[[device]]\nfamily = "selspot"\nport = "{selspot}"\ncameras = 2\nleds = 8\n\n'
        f'[[device]]\nfamily = "centroid"\nport = "{centroid}"\n\n'
        f'[[device]]\nfamily = "timer"\nport = "{timer}"\n',
        encoding="utf-8",
    )
    if _SIM_HANDLERS not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append(_SIM_HANDLERS)
    # Opening the port builds the simulated device, which writes its true rig.
    serial.serial_for_url(selspot, timeout=0.1).close()
    return path


def plan_lab(lab_path: Path | None, sim: bool, data: Path) -> LabPlan:
    """The lab of ``--lab LAB.toml`` or ``--sim`` (InputError if neither or both)."""
    if sim and lab_path is not None:
        raise InputError("give --lab LAB.toml or --sim, not both")
    if sim:
        return LabPlan(load_lab(sim_lab_file(data)), True)
    if lab_path is None:
        raise InputError("give --lab LAB.toml (the devices to acquire from) or --sim")
    lab = load_lab(lab_path)
    if not lab.devices:
        raise InputError(f"lab file {lab_path}: it names no device")
    return LabPlan(lab, False)
