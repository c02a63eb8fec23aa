"""CSX configuration, checked on the host before anything is sent (coda.md §3).

:class:`CodaConfig` holds what ``RATE``, ``OUT`` and ``MARK`` set and the baud
rate of the link, and checks the bandwidth condition the device checks at
``START:``: ``rate * (28 + (M + 4) R) * 10 <= 0.8 * baud``.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from spotlab.core.errors import BandwidthError, ConfigurationError
from spotlab.drivers.mcs1.commands import BAUD_CODES
from spotlab.drivers.mcs1.load import LineLoad

log = logging.getLogger(__name__)

MAX_MARKERS = 56
SPARE_SLOTS = 4
#: Bytes of a data frame besides the records: 12 framing + 16 prefix and scanner header.
FRAME_FIXED = 28
#: The eight band colours in code order (coda.md §2).
COLOURS = "ROYGCBVW"
#: Output modes by name -> header code.
MODES = {"3D": 1, "RAW": 2, "BOTH": 3}
#: (highest rate in mHz, markers served) of coda.md §1.
MARKER_LIMITS = ((100_000, 56), (200_000, 28), (400_000, 12), (800_000, 6))


def marker_id(code: str) -> int:
    """The marker ID (1-56) of a colour code such as ``"RO"``.

    Raises
    ------
    ConfigurationError
        If ``code`` is not one of the 56 codes of coda.md §2.
    """
    c = code.strip().upper()
    if len(c) != 2 or c[0] not in COLOURS or c[1] not in COLOURS or c[0] == c[1]:
        raise ConfigurationError(
            f"marker code {code!r} is not in the colour table: two different colours of "
            f"{' '.join(COLOURS)}, e.g. 'RO'"
        )
    i, j = COLOURS.index(c[0]), COLOURS.index(c[1])
    return 7 * i + (j if j < i else j - 1) + 1


def marker_code(marker: int) -> str:
    """The colour code of marker ID ``marker`` (1-56)."""
    if not 1 <= marker <= MAX_MARKERS:
        raise ConfigurationError(f"marker IDs are 1-{MAX_MARKERS}, got {marker}")
    i, r = divmod(marker - 1, 7)
    return COLOURS[i] + COLOURS[r if r < i else r + 1]


def marker_limit(rate_mhz: int) -> int:
    """Markers a scan rate serves before IDs alias (CODA cx1 figures, coda.md §1)."""
    for top, n in MARKER_LIMITS:
        if rate_mhz <= top:
            return n
    return MARKER_LIMITS[-1][1]


def record_bytes(mode: str) -> int:
    """Bytes of one marker record: 14 in ``3D`` or ``RAW`` mode, 26 in ``BOTH``."""
    return 26 if mode == "BOTH" else 14


@dataclass(frozen=True)
class CodaConfig(LineLoad):
    """What a CSX scanner is told before ``START:``.

    Parameters
    ----------
    rate_mhz : int
        Scan rate in millihertz, 50 000-800 000.
    markers : tuple of str
        The marker table: distinct colour codes, in flash-slot order.
    mode : str
        ``"3D"``, ``"RAW"`` or ``"BOTH"``.
    base_um : int or None
        The mirror base the unit must report (µm); None: any.
    baud : int
        Line rate while streaming.

    Raises
    ------
    ConfigurationError
        If a value is out of its range; the message names it.
    """

    rate_mhz: int = 300_000
    markers: tuple[str, ...] = ("RO",)
    mode: str = "BOTH"
    base_um: int | None = None
    baud: int = 2_000_000

    def __post_init__(self) -> None:
        if not 50_000 <= self.rate_mhz <= 800_000:
            raise ConfigurationError(
                f"the scan rate must be 50-800 Hz, got {self.rate_mhz / 1000:g} Hz"
            )
        if not 1 <= len(self.markers) <= MAX_MARKERS:
            raise ConfigurationError(f"the marker table needs 1-{MAX_MARKERS} markers")
        ids = [marker_id(c) for c in self.markers]
        if len(set(ids)) != len(ids):
            raise ConfigurationError(f"the marker table names a code twice: {self.markers}")
        if self.mode not in MODES:
            raise ConfigurationError(f"mode must be one of {sorted(MODES)}, got {self.mode!r}")
        if self.base_um is not None and self.base_um <= 0:
            raise ConfigurationError(f"the mirror base must be positive, got {self.base_um} µm")
        if self.baud not in BAUD_CODES:
            raise ConfigurationError(f"baud must be one of {sorted(BAUD_CODES)}, got {self.baud}")

    @classmethod
    def create(
        cls,
        *,
        rate_hz: float = 300.0,
        markers: int | str | Sequence[str] = 8,
        mode: str = "BOTH",
        base_mm: float | None = None,
        baud: int | str = 2_000_000,
    ) -> CodaConfig:
        """A checked configuration from user-facing values.

        Parameters
        ----------
        rate_hz : float
            Scan rate in Hz.
        markers : int, str or sequence of str
            A number ``M`` (the first ``M`` codes of the table, IDs 1..M), a
            comma-separated string of codes, or the codes.
        mode : str
            Output mode, ``3D``, ``RAW`` or ``BOTH`` (any case).
        base_mm : float, optional
            The mirror base the unit must have (mm); a unit reporting another is refused.
        baud : int or "auto"
            Line rate while streaming; ``"auto"`` picks the slowest that carries the stream.

        Raises
        ------
        ConfigurationError
            If a value is out of range.
        BandwidthError
            If the stream does not fit ``baud``.
        """
        if not math.isfinite(rate_hz):
            raise ConfigurationError(f"the scan rate must be a finite number, got {rate_hz}")
        if isinstance(markers, int):
            if not 1 <= markers <= MAX_MARKERS:
                raise ConfigurationError(f"markers must be 1-{MAX_MARKERS}, got {markers}")
            codes = tuple(marker_code(i) for i in range(1, markers + 1))
        elif isinstance(markers, str):
            codes = tuple(c.strip().upper() for c in markers.split(",") if c.strip())
        else:
            codes = tuple(str(c).strip().upper() for c in markers)
        if isinstance(baud, str) and baud != "auto":
            raise ConfigurationError(f"baud must be a rate in baud or 'auto', got {baud!r}")
        base = cls(
            rate_mhz=round(rate_hz * 1000),
            markers=codes,
            mode=str(mode).upper(),
            base_um=None if base_mm is None else round(float(base_mm) * 1000),
            baud=max(BAUD_CODES) if baud == "auto" else int(baud),
        )
        if baud == "auto":
            fits = [b for b in sorted(BAUD_CODES) if base.fits(b)]
            if fits:
                base = cls(**{**base.__dict__, "baud": fits[0]})
        base.bandwidth_check()
        if len(codes) > base.limit:
            log.warning(
                "%d markers at %g Hz: the scanner serves %d; markers beyond will alias "
                "(reported flagged, not under their ID)", len(codes), base.rate_hz, base.limit,
            )  # fmt: skip
        return base

    @property
    def n_markers(self) -> int:
        """Markers in the table ``M``."""
        return len(self.markers)

    @property
    def slots(self) -> int:
        """Record slots of a frame ``S = M + 4``."""
        return self.n_markers + SPARE_SLOTS

    @property
    def limit(self) -> int:
        """Markers the scan rate serves before aliasing."""
        return marker_limit(self.rate_mhz)

    @property
    def ids(self) -> tuple[int, ...]:
        """Marker IDs of the table, in table order."""
        return tuple(marker_id(c) for c in self.markers)

    @property
    def frame_bytes(self) -> int:
        """Bytes of a whole data frame, ``28 + (M + 4) R``."""
        return FRAME_FIXED + self.slots * record_bytes(self.mode)

    @property
    def payload_len(self) -> int:
        """Bytes of a data frame's payload."""
        return self.frame_bytes - 12

    def bandwidth_check(self) -> None:
        """Raise :class:`BandwidthError` unless the stream fits ``baud`` with 20 % to spare."""
        if self.fits(self.baud):
            return
        fitting = [b for b in sorted(BAUD_CODES) if self.fits(b)]
        advice = (
            f"use baud={fitting[0]} or faster"
            if fitting
            else "lower the rate, the markers or use OUT:3D"
        )
        raise BandwidthError(
            f"scanner frames of {self.n_markers} markers in {self.mode} mode at "
            f"{self.rate_hz:g} Hz need {self.line_bits_per_s / 1e6:.4g} Mbit/s plus 20 % "
            f"reserve, more than {self.baud} baud carries; {advice}"
        )

    def commands(self) -> list[tuple[str, str]]:
        """``(verb, args)`` to send, in order: ``RATE``, ``OUT``, ``MARK``."""
        return [("RATE", str(self.rate_mhz)), ("OUT", self.mode), ("MARK", ",".join(self.markers))]

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe form (recording metadata)."""
        return {
            "rate_mhz": self.rate_mhz,
            "markers": list(self.markers),
            "mode": self.mode,
            "base_um": self.base_um,
            "baud": self.baud,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> CodaConfig:
        """Inverse of :meth:`to_dict`; missing keys take their defaults.

        Raises
        ------
        ConfigurationError
            If a value is malformed or out of range.
        """
        try:
            kwargs: dict[str, Any] = {}
            for key in ("rate_mhz", "baud"):
                if key in d:
                    kwargs[key] = int(d[key])
            if "markers" in d:
                kwargs["markers"] = tuple(str(c) for c in d["markers"])
            if "mode" in d:
                kwargs["mode"] = str(d["mode"])
            if d.get("base_um") is not None:
                kwargs["base_um"] = int(d["base_um"])
        except (TypeError, ValueError) as exc:
            raise ConfigurationError(f"malformed CSX configuration {dict(d)!r}: {exc}") from exc
        return cls(**kwargs)
