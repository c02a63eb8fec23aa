"""Devices to record and their settings: ``--device FAMILY=PORT[,key=value...]`` and lab files.

Each family takes the settings of :data:`FAMILY_SETTINGS` (docs/lab.md lists them);
an unknown key is refused with one error naming it. A setting a device is not
given keeps what the device reports it has (the drivers read it with ``CONF:``).
The global ``--rate/--cameras/--leds/--baud`` options of ``spotlab record`` are
defaults for devices that do not say.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from spotlab.console.errors import CommandError
from spotlab.io.lab_file import LabDevice, SettingValue


def _int(value: SettingValue) -> int:
    if isinstance(value, bool):
        raise ValueError(value)
    if isinstance(value, float):
        if not value.is_integer():
            raise ValueError(value)
        return int(value)
    return int(value)


def _float(value: SettingValue) -> float:
    if isinstance(value, bool):
        raise ValueError(value)
    return float(value)


def _baud(value: SettingValue) -> int | str:
    return "auto" if value == "auto" else _int(value)


def _agc(value: SettingValue) -> int | None:
    return None if value == "off" else _int(value)


def _markers(value: SettingValue) -> int | str:
    """A number of markers, or colour codes joined by ``+`` (``RO+GB``; commas part settings)."""
    if isinstance(value, str) and not value.strip().isdigit():
        return value.replace("+", ",")
    return _int(value)


def _bool(value: SettingValue) -> bool:
    """``1/0``, ``on/off``, ``yes/no``, ``true/false``."""
    text = str(value).lower()
    if text in ("1", "on", "yes", "true"):
        return True
    if text in ("0", "off", "no", "false"):
        return False
    raise ValueError(value)


def _ports(value: SettingValue) -> str:
    """Markers per strober port, ``8+8+8`` (commas part settings)."""
    return str(value)


Converter = Callable[[SettingValue], Any]

#: Family -> setting key -> (driver keyword, converter, help text).
FAMILY_SETTINGS: dict[str, dict[str, tuple[str, Converter, str]]] = {
    "selspot": {
        "rate": ("rate_hz", _float, "frame rate in Hz"),
        "cameras": ("cameras", _int, "cameras, 1-4"),
        "leds": ("leds", _int, "LEDs (ids 0..N-1)"),
        "slot": ("slot_us", _int, "slot period in µs, 50-1000"),
        "bgnd": ("bgnd", _int, "background differencing, 0-2"),
        "agc": ("agc", _agc, "AGC target intensity 1-255, or 'off'"),
        "baud": ("baud", _baud, "line rate while streaming, or 'auto'"),
    },
    "timer": {
        "rate": ("rate_hz", _float, "timer frame rate in Hz"),
        "slots": ("slots", _int, "edge record slots per frame"),
        "baud": ("baud", _baud, "line rate while streaming, or 'auto'"),
    },
    "coda": {
        "rate": ("rate_hz", _float, "scan rate in Hz, 50-800"),
        "markers": ("markers", _markers, "markers: M (IDs 1..M) or colour codes, RO+GB+..."),
        "out": ("mode", str, "output: 3D, RAW or BOTH"),
        "base": ("base_mm", _float, "the mirror base (mm) the unit must report"),
        "baud": ("baud", _baud, "line rate while streaming, or 'auto'"),
    },
    "centroid": {
        "rate": ("rate_hz", _float, "frame rate in Hz"),
        "cameras": ("cameras", _int, "cameras 0..N-1 enabled"),
        "exposure": ("exposure_us", _int, "exposure in µs"),
        "threshold": ("threshold", _int, "threshold, 1-254"),
        "blobs": ("max_blobs", _int, "blobs per camera and frame at most"),
        "baud": ("baud", _baud, "line rate while streaming, or 'auto'"),
    },
    "qualisys": {
        "password": ("password", str, "QTM's real-time password (TakeControl)"),
        "udp": ("udp_port", _int, "have QTM send the frames by UDP to this local port (0: any)"),
    },
    "wsx": {
        "rate": ("rate_hz", _float, "frame rate in Hz, at most marker rate / (markers + 2)"),
        "markers": ("markers", _int, "markers, 1-512"),
        "marker_rate": ("marker_rate_hz", _float, "marker rate in Hz, 1500-4600"),
        "ports": ("ports", _ports, "markers per strober port, 8+8+8"),
        "duty": ("duty", _float, "duty cycle, 0.10-0.85"),
        "threshold": ("threshold", _int, "threshold, 1-255"),
        "gain": ("gain", _int, "gain, 1-1000"),
        "voltage": ("voltage_dv", _int, "LED voltage in 0.1 V, 70-120"),
        "raw": ("raw", _bool, "1: no interpolation, each marker at its own firing instant"),
    },
    "natnet": {
        "marker_set": ("marker_set", str, "marker set to record (default: the first)"),
        "multicast": (
            "multicast",
            str,
            "multicast group to join, or off (default: as the server info announces)",
        ),
    },
}

#: ``spotlab record`` option -> setting key, the defaults for devices that do not say.
GLOBAL_OPTIONS = ("rate", "cameras", "leds", "baud")


@dataclass
class DeviceRequest:
    """A device to record: family, port, stream name and the driver's keyword arguments."""

    family: str
    port: str
    name: str | None = None
    options: dict[str, Any] = field(default_factory=dict)


def parse_device_option(text: str) -> tuple[str, str, dict[str, str]]:
    """``FAMILY=PORT[,key=value...]`` -> (family, port, raw settings).

    A port that itself holds commas (a ``sim://`` URL) is not split there: only the
    trailing ``,key=value`` items whose key is a word are settings.

    Raises
    ------
    CommandError
        If ``text`` is not ``FAMILY=PORT[,key=value...]``.
    """
    family, sep, rest = text.partition("=")
    if not sep or not family or not rest:
        raise CommandError(f"--device takes FAMILY=PORT[,key=value...], got {text!r}")
    parts = rest.split(",")
    settings: dict[str, str] = {}
    while len(parts) > 1:
        key, eq, value = parts[-1].partition("=")
        if not eq or not key.isidentifier():
            break
        if key in settings:
            raise CommandError(f"--device {text!r}: setting {key!r} given twice")
        settings[key] = value
        parts.pop()
    port = ",".join(parts)
    if not port:
        raise CommandError(f"--device {text!r}: no PORT")
    return family, port, dict(reversed(settings.items()))


def _value(raw: str) -> SettingValue:
    """A command-line setting as TOML would give it (int, float or string)."""
    for kind in (int, float):
        try:
            return kind(raw)
        except ValueError:
            pass
    return raw


def device_options(
    family: str,
    settings: Mapping[str, SettingValue],
    where: str,
    defaults: Mapping[str, SettingValue] | None = None,
) -> tuple[str | None, dict[str, Any]]:
    """Stream name and driver keywords of one device's settings.

    Parameters
    ----------
    family : str
        The device's family.
    settings : mapping
        Its settings (``rate``, ``cameras``, ..., and ``name``).
    where : str
        What to name in messages (``--device selspot=...``, ``lab.toml: device[0]``).
    defaults : mapping, optional
        Global settings for keys the device does not give; keys the family does not
        take are left out.

    Raises
    ------
    CommandError
        If a key is unknown to the family or its value is malformed.
    """
    table = FAMILY_SETTINGS.get(family, {})
    name: str | None = None
    options: dict[str, Any] = {}
    merged = {k: v for k, v in (defaults or {}).items() if k in table}
    merged.update(settings)
    for key, value in merged.items():
        if key == "name":
            name = str(value)
            continue
        if key not in table:
            known = ", ".join(["name", *table]) if table else "name"
            raise CommandError(
                f"{where}: unknown setting {key!r} for a {family} device (it takes {known})"
            )
        keyword, convert, help_text = table[key]
        try:
            options[keyword] = convert(value)
        except (TypeError, ValueError):
            raise CommandError(
                f"{where}: setting {key}={value!r} is not valid ({help_text})"
            ) from None
    return name, options


def requests_from_options(
    items: Sequence[str], defaults: Mapping[str, SettingValue]
) -> list[DeviceRequest]:
    """Device requests of the ``--device`` options (global defaults applied)."""
    out = []
    for item in items:
        family, port, raw = parse_device_option(item)
        settings = {k: _value(v) for k, v in raw.items()}
        name, options = device_options(family, settings, f"--device {item}", defaults)
        out.append(DeviceRequest(family, port, name, options))
    return out


def requests_from_lab(
    devices: Sequence[LabDevice], defaults: Mapping[str, SettingValue]
) -> list[DeviceRequest]:
    """Device requests of a lab file's devices (command-line defaults applied)."""
    out = []
    for d in devices:
        settings: dict[str, SettingValue] = dict(d.settings)
        if d.name is not None:
            settings["name"] = d.name
        name, options = device_options(d.family, settings, d.where, defaults)
        out.append(DeviceRequest(d.family, d.port, name, options))
    return out
