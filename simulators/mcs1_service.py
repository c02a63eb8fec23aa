"""What serving any MCS-1 simulator takes: its clock, its lab publisher, its URL, its pty.

A family's options dataclass (``SelspotSimOptions``, ``TimerSimOptions``,
``CentroidSimOptions``) turns into a device with the family's ``build_*``
function; the pieces every family builds the same way are here:
:func:`device_clock` and :func:`lab_publisher` for the device,
:func:`options_url` and :func:`parse_options_url` for its ``sim://FAMILY?...``
URL, :func:`serve_device_pty` to serve it on a pseudo-terminal.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import fields
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, TypeVar
from urllib.parse import parse_qsl, quote, urlsplit

from spotlab.simulators.clock import DeviceClock
from spotlab.simulators.lab import LabPublisher, lab_dir

if TYPE_CHECKING:
    from spotlab.simulators.mcs1_device import Mcs1Device
    from spotlab.simulators.transports.pty import PtyServer

_O = TypeVar("_O")

# Served devices are switched on this long before their port exists: their
# power-up banner is over by then, as with a device that was already running
# when the host opened its port (a host resets it to see the banner).
POWER_UP_LEAD_NS = 100_000_000
#: Width of the frame pulse a simulated device publishes to the lab.
FRAME_PULSE_WIDTH_S = 10e-6

# URL query names of the options (short names first, the field names work too).
_URL_NAMES = {
    "rate": "rate_hz",
    "clock_offset": "clock_offset_s",
    "clock_drift": "clock_drift_ppm",
    "clock_jitter": "clock_jitter_s",
    "reflectance": "floor_reflectance",
}
_URL_SHORT = {v: k for k, v in _URL_NAMES.items()}


class ClockOptions(Protocol):
    """The clock fields every family's options have."""

    clock_offset_s: float
    clock_drift_ppm: float
    clock_jitter_s: float
    seed: int


class LabOptions(Protocol):
    """The lab fields of a family whose frame pulses can be published."""

    lab_name: str
    lab: Path | None


def device_clock(
    options: ClockOptions,
    now_ns: int | None,
    steps: tuple[tuple[float, float], ...] = (),
) -> DeviceClock:
    """The device's clock, powered up at ``now_ns`` (None: now), with counter ``steps``."""
    return DeviceClock(
        offset_s=options.clock_offset_s,
        drift_ppm=options.clock_drift_ppm,
        jitter_s=options.clock_jitter_s,
        steps=steps,
        seed=options.seed,
        epoch_ns=now_ns,
    )


def lab_publisher(options: LabOptions, clock: DeviceClock) -> LabPublisher | None:
    """Where the device publishes its frame pulses; None without a ``lab_name``."""
    if not options.lab_name:
        return None
    return LabPublisher(lab_dir(options.lab), options.lab_name, clock, FRAME_PULSE_WIDTH_S)


def options_url(family: str, options: object, safe: str = "/@:,.-=") -> str:
    """``sim://FAMILY?...`` of a family's options (defaults left out).

    Parameters
    ----------
    family : str
        ``selspot``, ``timer``, ``centroid``.
    options : dataclass instance
        The options; their class's defaults are left out of the URL.
    safe : str
        Characters left unquoted in the values.
    """
    default = type(options)()
    parts = []
    for f in fields(options):  # type: ignore[arg-type]
        value = getattr(options, f.name)
        if value == getattr(default, f.name) or value is None:
            continue
        parts.append(f"{_URL_SHORT.get(f.name, f.name)}={quote(str(value), safe=safe)}")
    return f"sim://{family}" + ("?" + "&".join(parts) if parts else "")


def parse_options_url(url: str, family: str, cls: type[_O]) -> _O:
    """Options of class ``cls`` from the query of ``sim://FAMILY?...`` (not validated).

    Raises
    ------
    ValueError
        For another family, an unknown option or a value of the wrong type.
    """
    split = urlsplit(url)
    if split.scheme != "sim" or split.netloc != family:
        raise ValueError(f"not a simulated {family} URL: {url!r} (expected sim://{family}?...)")
    kinds = {f.name: f.type for f in fields(cls)}  # type: ignore[arg-type]
    values: dict[str, Any] = {}
    for key, text in parse_qsl(split.query, keep_blank_values=True):
        name = _URL_NAMES.get(key, key)
        if name not in kinds:
            raise ValueError(
                f"unknown option {key!r} in {url!r}; known: {', '.join(sorted(kinds))}"
            )
        kind = str(kinds[name])
        try:
            if kind == "int":
                values[name] = int(text)
            elif kind in ("float", "float | None"):
                values[name] = float(text)
            elif "Path" in kind:
                values[name] = Path(text) if text else None
            else:
                values[name] = text
        except ValueError:
            raise ValueError(f"option {key}={text!r} in {url!r} is not a valid {kind}") from None
    return cls(**values)


def serve_device_pty(build: Callable[[int], Mcs1Device[Any]], name: str) -> PtyServer:
    """Serve ``build(power-up ns)`` on a pseudo-terminal named ``name``; ``.path`` is the link.

    The device is powered up :data:`POWER_UP_LEAD_NS` before its port exists.
    """
    from spotlab.simulators.transports.pty import PtyServer

    server = PtyServer(build(time.monotonic_ns() - POWER_UP_LEAD_NS), name=name)
    server.start()
    return server
