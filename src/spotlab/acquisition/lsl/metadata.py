"""LSL stream descriptions of spotlab streams, and spotlab specs of LSL streams.

An outlet describes its channels after the XDF "MoCap Meta Data" recommendation
(github.com/sccn/xdf/wiki/MoCap-Meta-Data): ``desc/channels/channel`` with
``label``, ``marker``, ``type`` and ``unit``; ``desc/acquisition`` with
``manufacturer`` and ``model``. 3-D positions have types ``PositionX/Y/Z``; the
wiki prefers metres, spotlab sends millimetres and says so in ``unit``. Raw
streams add ``sensor`` (camera) and use the value name as ``type``. The exact
spotlab :class:`StreamSpec` travels as JSON in ``desc/spotlab/spec``, so a spotlab
inlet rebuilds the frame shape (markers x sensors x values) exactly.
"""

from __future__ import annotations

import json
from typing import Any

from spotlab.acquisition.lsl._pylsl import pylsl_module
from spotlab.core.errors import ConfigurationError
from spotlab.core.streams import StreamSpec

#: LSL content type of 3-D marker positions (the XDF/LSL convention).
MOCAP_TYPE = "MoCap"
#: LSL content type spotlab gives raw device streams (no LSL convention covers them).
RAW_TYPE = "MoCapRaw"
#: Channel formats an outlet may use.
CHANNEL_FORMATS = ("float32", "double64")
_POSITION_TYPES = ("PositionX", "PositionY", "PositionZ")
_UNIT_NAMES = {"mm": "millimeters", "m": "meters", "px": "pixels", "s": "seconds"}


def marker_labels(spec: StreamSpec) -> list[str]:
    """Marker names: ``spec.metadata["marker_labels"]``, else ``led<id>``, else ``m<k>``."""
    labels = spec.metadata.get("marker_labels")
    if isinstance(labels, list) and len(labels) == spec.n_markers:
        return [str(x) for x in labels]
    ids = spec.metadata.get("led_ids")
    if isinstance(ids, list) and len(ids) == spec.n_markers:
        return [f"led{i}" for i in ids]
    return [f"m{k}" for k in range(spec.n_markers)]


def is_positions(spec: StreamSpec) -> bool:
    """Whether the stream holds 3-D positions: kind ``point3d`` with values x, y, z."""
    return spec.kind == "point3d" and tuple(spec.values) == ("x", "y", "z")


def stream_info(
    spec: StreamSpec,
    *,
    name: str | None = None,
    stream_type: str | None = None,
    source_id: str = "",
    channel_format: str = "float32",
) -> Any:
    """A ``pylsl.StreamInfo`` describing ``spec``, one channel per marker, sensor and value.

    Parameters
    ----------
    spec : StreamSpec
        The stream; channels are ``data[f].reshape(-1)`` (marker-major, then
        sensor, then value).
    name : str, optional
        LSL stream name (default ``spec.name``).
    stream_type : str, optional
        LSL content type (default ``MoCap`` for 3-D positions, ``MoCapRaw`` otherwise).
    source_id : str, optional
        LSL source id; set it so that inlets recover when the outlet restarts.
    channel_format : {"float32", "double64"}
        Sample format on the wire.

    Raises
    ------
    ConfigurationError
        If the stream has no channels or the format is unknown.
    """
    pylsl = pylsl_module()
    if channel_format not in CHANNEL_FORMATS:
        raise ConfigurationError(f"channel_format must be one of {CHANNEL_FORMATS}")
    n_values = max(len(spec.values), 1)
    n_channels = spec.n_markers * spec.n_sensors * n_values
    if n_channels == 0:
        raise ConfigurationError(f"stream {spec.name!r} has no channel to publish")
    positions = is_positions(spec)
    fmt = pylsl.cf_float32 if channel_format == "float32" else pylsl.cf_double64
    info = pylsl.StreamInfo(
        name or spec.name,
        stream_type or (MOCAP_TYPE if positions else RAW_TYPE),
        n_channels,
        spec.rate_hz,
        fmt,
        source_id,
    )
    desc = info.desc()
    channels = desc.append_child("channels")
    values = spec.values or ("value",)
    units = spec.units or ("",)
    for label in marker_labels(spec):
        for s in range(spec.n_sensors):
            for v, unit in zip(values, units, strict=True):
                ch = channels.append_child("channel")
                if positions:
                    ch.append_child_value("label", f"{label}_{v.upper()}")
                    ch.append_child_value("marker", label)
                    ch.append_child_value("type", _POSITION_TYPES["xyz".index(v)])
                else:
                    ch.append_child_value("label", f"{label}_s{s}_{v}")
                    ch.append_child_value("marker", label)
                    ch.append_child_value("sensor", str(s))
                    ch.append_child_value("type", v)
                ch.append_child_value("unit", _UNIT_NAMES.get(unit, unit))
    acquisition = desc.append_child("acquisition")
    acquisition.append_child_value("manufacturer", "spotlab")
    acquisition.append_child_value("model", str(spec.metadata.get("family", spec.kind)))
    acquisition.append_child_value("compensated_lag", "0")
    desc.append_child("spotlab").append_child_value("spec", json.dumps(spec.to_dict()))
    return info


def _channels(info: Any) -> list[dict[str, str]]:
    out: list[dict[str, str]] = []
    ch = info.desc().child("channels").child("channel")
    while not ch.empty():
        out.append({k: ch.child_value(k) for k in ("label", "marker", "type", "unit")})
        ch = ch.next_sibling()
    return out


def spec_from_info(info: Any, name: str) -> StreamSpec:
    """The spotlab spec of a resolved LSL stream (full info, with its ``desc``).

    A spotlab outlet's spec is taken from ``desc/spotlab/spec``. Other MoCap
    streams whose channels are ``PositionX/Y/Z`` triples become ``point3d``
    (M = channels / 3, one sensor, values x, y, z). Anything else becomes one
    marker with one value per channel (kind ``linear1d``, S = channels). Ticks
    are LSL timestamps in ns (``tick_hz`` = 1e9).

    Raises
    ------
    ConfigurationError
        If the stream carries strings or has no nominal rate (irregular streams
        are not frame streams).
    """
    pylsl = pylsl_module()
    if info.channel_format() == pylsl.cf_string:
        raise ConfigurationError(
            f"LSL stream {info.name()!r} carries strings (an event marker stream); "
            "only numeric streams can join a session"
        )
    rate = float(info.nominal_srate())
    if not rate > 0:
        raise ConfigurationError(
            f"LSL stream {info.name()!r} has an irregular rate; only streams with a nominal "
            "rate can join a session"
        )
    n = int(info.channel_count())
    lsl = {"lsl_name": info.name(), "lsl_type": info.type(), "channels": n}
    text = info.desc().child("spotlab").child_value("spec")
    if text:
        try:
            d = json.loads(text)
            spec = StreamSpec.from_dict({**d, "name": name, "tick_hz": 1e9})
        except (ValueError, TypeError) as exc:
            raise ConfigurationError(
                f"LSL stream {info.name()!r} has a malformed spotlab spec: {exc}"
            ) from exc
        if spec.n_markers * spec.n_sensors * max(len(spec.values), 1) == n:
            return StreamSpec.from_dict(
                {**spec.to_dict(), "metadata": {**spec.metadata, "lsl": lsl}}
            )
    channels = _channels(info)
    types = tuple(c["type"] for c in channels)
    if n % 3 == 0 and len(types) == n and types == _POSITION_TYPES * (n // 3):
        labels = [c["marker"] or f"m{k}" for k, c in enumerate(channels[::3])]
        unit = {"millimeters": "mm", "meters": "m"}.get(channels[0]["unit"], channels[0]["unit"])
        return StreamSpec(
            name=name,
            kind="point3d",
            n_sensors=1,
            n_markers=n // 3,
            rate_hz=rate,
            tick_hz=1e9,
            values=("x", "y", "z"),
            units=(unit, unit, unit),
            metadata={"marker_labels": labels, "lsl": lsl},
        )
    return StreamSpec(
        name=name,
        kind="linear1d",
        n_sensors=n,
        n_markers=1,
        rate_hz=rate,
        tick_hz=1e9,
        values=("value",),
        units=("",),
        metadata={"channel_labels": [c["label"] for c in channels], "lsl": lsl},
    )
