"""Device drivers: one sub-package per family, found through a table.

``DRIVERS`` maps a family name to ``(module, class)``; the module is imported
only when the family is used, so an optional stack (pyusb, depthai) is needed
only by those who drive that hardware. Third-party families register through
the ``spotlab.drivers`` entry-point group (``name = "package.module:Class"``).
"""

from __future__ import annotations

import importlib
from importlib.metadata import entry_points

from spotlab.core.errors import ConfigurationError
from spotlab.drivers.base import DeviceInfo, Driver

DRIVERS: dict[str, tuple[str, str]] = {
    "selspot": ("spotlab.drivers.selspot", "SelspotDriver"),
    "timer": ("spotlab.drivers.timer", "TimerDriver"),
    "coda": ("spotlab.drivers.coda", "CodaDriver"),
    "centroid": ("spotlab.drivers.centroid", "CentroidDriver"),
    "lsl": ("spotlab.drivers.lsl", "LslInletDriver"),
    "oak": ("spotlab.drivers.oak", "OakDriver"),
    "qualisys": ("spotlab.drivers.qualisys", "QualisysDriver"),
    "natnet": ("spotlab.drivers.natnet", "NatNetDriver"),
    "wsx": ("spotlab.drivers.wsx", "WsxDriver"),
}


def available_families() -> list[str]:
    """Names of every family in the table and the entry-point group, sorted."""
    names = set(DRIVERS)
    names.update(ep.name for ep in entry_points(group="spotlab.drivers"))
    return sorted(names)


def load_driver(family: str) -> type[Driver]:
    """The driver class of a family, imported on first use.

    Raises
    ------
    ConfigurationError
        If no driver of that name exists, or its optional dependencies are missing.
    """
    if family in DRIVERS:
        module_name, class_name = DRIVERS[family]
        try:
            module = importlib.import_module(module_name)
        except ImportError as exc:
            raise ConfigurationError(
                f"driver {family!r} needs a package that is not installed: {exc.name}"
            ) from exc
        cls = getattr(module, class_name)
    else:
        matches = [ep for ep in entry_points(group="spotlab.drivers") if ep.name == family]
        if not matches:
            raise ConfigurationError(
                f"no driver named {family!r}; known: {', '.join(available_families())}"
            )
        cls = matches[0].load()
    if not (isinstance(cls, type) and issubclass(cls, Driver)):
        raise ConfigurationError(f"driver {family!r} does not derive from spotlab.drivers.Driver")
    return cls


__all__ = ["DRIVERS", "DeviceInfo", "Driver", "available_families", "load_driver"]
