"""Description of a stream: what a device delivers, at which rate, in which units."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from spotlab.core.errors import ConfigurationError
from spotlab.core.units import NS_PER_S

StreamKind = Literal["image2d", "linear1d", "scan3", "point3d", "blobs2d", "timer"]
STREAM_KINDS: tuple[str, ...] = ("image2d", "linear1d", "scan3", "point3d", "blobs2d", "timer")


@dataclass(frozen=True)
class StreamSpec:
    """What one device stream delivers.

    Parameters
    ----------
    name : str
        Stream name, unique within a session (for example ``"selspot0"``).
    kind : str
        One of ``image2d``, ``linear1d``, ``scan3``, ``point3d``, ``blobs2d``, ``timer``.
    n_sensors : int
        Cameras or linear sensors (the ``S`` axis of a frame).
    n_markers : int
        Markers (LEDs) per frame (the ``M`` axis of a frame).
    rate_hz : float
        Nominal frame rate in Hz.
    tick_hz : float
        Rate of the device's timestamp counter, in ticks per second.
    slot_period_s : float or None
        For time-multiplexed devices, the time between two markers' samples
        in seconds; marker ``k`` is sampled at frame time + (k + 1/2) * slot.
        ``None`` when all markers are sampled at once.
    values : tuple of str
        Names of the values per marker and sensor (the ``V`` axis), such as
        ``("x", "y", "intensity")``.
    units : tuple of str
        Unit of each value, same length as ``values``.
    metadata : dict
        Device-specific configuration (LED table, drive currents, ...), JSON-safe.
    """

    name: str
    kind: StreamKind
    n_sensors: int
    n_markers: int
    rate_hz: float
    tick_hz: float
    slot_period_s: float | None = None
    values: tuple[str, ...] = ()
    units: tuple[str, ...] = ()
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.kind not in STREAM_KINDS:
            raise ConfigurationError(f"stream kind {self.kind!r} is not one of {STREAM_KINDS}")
        if self.n_sensors < 0 or self.n_markers < 0:
            raise ConfigurationError("a stream cannot have a negative number of sensors or markers")
        if not self.rate_hz > 0 or not self.tick_hz > 0:
            raise ConfigurationError("stream rate and tick rate must be positive")
        if len(self.values) != len(self.units):
            raise ConfigurationError("a stream needs one unit per value name")

    def sample_offsets_ns(self) -> npt.NDArray[np.int64]:
        """Time of each marker's sample after the frame time.

        Returns
        -------
        ndarray of int64, shape (M,)
            Offsets in nanoseconds: (k + 1/2) * slot for time-multiplexed
            devices, zeros otherwise.
        """
        if self.slot_period_s is None:
            return np.zeros(self.n_markers, dtype=np.int64)
        k = np.arange(self.n_markers, dtype=np.float64)
        return np.round((k + 0.5) * self.slot_period_s * NS_PER_S).astype(np.int64)

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe description (for recordings and ``--json`` output)."""
        return {
            "name": self.name,
            "kind": self.kind,
            "n_sensors": self.n_sensors,
            "n_markers": self.n_markers,
            "rate_hz": self.rate_hz,
            "tick_hz": self.tick_hz,
            "slot_period_s": self.slot_period_s,
            "values": list(self.values),
            "units": list(self.units),
            "metadata": self.metadata,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> StreamSpec:
        """Inverse of :meth:`to_dict`."""
        try:
            return cls(
                name=str(d["name"]),
                kind=d["kind"],
                n_sensors=int(d["n_sensors"]),
                n_markers=int(d["n_markers"]),
                rate_hz=float(d["rate_hz"]),
                tick_hz=float(d["tick_hz"]),
                slot_period_s=None if d.get("slot_period_s") is None else float(d["slot_period_s"]),
                values=tuple(d.get("values", ())),
                units=tuple(d.get("units", ())),
                metadata=dict(d.get("metadata", {})),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ConfigurationError(
                f"stream description is incomplete or malformed: {exc}"
            ) from exc
