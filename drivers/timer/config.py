"""TMR configuration, checked on the host before anything is sent (timer.md §2).

:class:`TimerConfig` holds what ``RATE``, ``EDGS``, ``TCOD`` and ``ARM`` set and
the baud rate of the link, and checks the bandwidth condition the device
checks at ``START:``: ``rate * (44 + 12 E) * 10 <= 0.8 * baud``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from spotlab.core.errors import BandwidthError, ConfigurationError
from spotlab.drivers.mcs1.commands import BAUD_CODES
from spotlab.drivers.mcs1.load import LineLoad

MAX_INPUTS = 8
MAX_SLOTS = 64
#: Bytes of a data frame besides the records: 12 framing + 32 prefix and timer header.
FRAME_FIXED = 44
RECORD_BYTES = 12
#: ``ARM`` modes by name.
ARM_MODES = {"off": 0, "rising": 1, "falling": 2, "both": 3}
TIMECODE_RATES = ((24, False), (25, False), (30, False), (30, True))


@dataclass(frozen=True)
class TimerConfig(LineLoad):
    """What a TMR unit is told before ``START:``.

    Parameters
    ----------
    rate_mhz : int
        Timer frame rate in millihertz, 1 000-10 000 000.
    slots : int
        Edge record slots per frame ``E``, 1-64.
    arm : tuple of int
        ``ARM`` mode of inputs 0-7: 0 off, 1 rising, 2 falling, 3 both.
    timecode : tuple of (int, bool) or None
        ``(fps, drop_frame)``: (24, False), (25, False), (30, False) or (30, True);
        None for timecode off.
    baud : int
        Line rate while streaming; one of the ``COMM`` rates of mcs1.md §1.

    Raises
    ------
    ConfigurationError
        If a value is out of its range; the message names it.
    """

    rate_mhz: int = 100_000
    slots: int = 8
    arm: tuple[int, ...] = (1,) * MAX_INPUTS
    timecode: tuple[int, bool] | None = None
    baud: int = 2_000_000

    def __post_init__(self) -> None:
        if not 1_000 <= self.rate_mhz <= 10_000_000:
            raise ConfigurationError(
                f"the timer frame rate must be 1-10000 Hz, got {self.rate_mhz / 1000:g} Hz"
            )
        if not 1 <= self.slots <= MAX_SLOTS:
            raise ConfigurationError(f"edge slots must be 1-{MAX_SLOTS}, got {self.slots}")
        if len(self.arm) != MAX_INPUTS or any(m not in (0, 1, 2, 3) for m in self.arm):
            raise ConfigurationError(
                f"arm needs one mode 0-3 for each of the {MAX_INPUTS} inputs, got {self.arm}"
            )
        if self.timecode is not None and tuple(self.timecode) not in TIMECODE_RATES:
            raise ConfigurationError(
                f"timecode must be one of {TIMECODE_RATES} (fps, drop-frame), got {self.timecode}"
            )
        if self.baud not in BAUD_CODES:
            raise ConfigurationError(f"baud must be one of {sorted(BAUD_CODES)}, got {self.baud}")

    @classmethod
    def create(
        cls,
        *,
        rate_hz: float = 100.0,
        slots: int = 8,
        inputs: Mapping[int, str] | None = None,
        timecode: tuple[int, bool] | None = None,
        baud: int | str = 2_000_000,
    ) -> TimerConfig:
        """A checked configuration from user-facing values.

        Parameters
        ----------
        rate_hz : float
            Timer frame rate in Hz.
        slots : int
            Edge record slots per frame.
        inputs : mapping of int to str, optional
            Input number -> ``"rising"``, ``"falling"``, ``"both"`` or ``"off"``;
            inputs not named are off. Default: every input armed for rising edges.
        timecode : (int, bool), optional
            ``(fps, drop_frame)``, or None for no timecode.
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
            raise ConfigurationError(f"the frame rate must be a finite number, got {rate_hz}")
        arm = [1] * MAX_INPUTS
        if inputs is not None:
            arm = [0] * MAX_INPUTS
            for number, mode in inputs.items():
                if not 0 <= number < MAX_INPUTS:
                    raise ConfigurationError(f"inputs are 0-{MAX_INPUTS - 1}, got {number}")
                if mode not in ARM_MODES:
                    raise ConfigurationError(
                        f"input mode must be one of {sorted(ARM_MODES)}, got {mode!r}"
                    )
                arm[number] = ARM_MODES[mode]
        if isinstance(baud, str) and baud != "auto":
            raise ConfigurationError(f"baud must be a rate in baud or 'auto', got {baud!r}")
        base = cls(
            rate_mhz=round(rate_hz * 1000),
            slots=slots,
            arm=tuple(arm),
            timecode=None if timecode is None else (int(timecode[0]), bool(timecode[1])),
            baud=max(BAUD_CODES) if baud == "auto" else int(baud),
        )
        if baud == "auto":
            fits = [b for b in sorted(BAUD_CODES) if base.fits(b)]
            if fits:
                base = cls(**{**base.__dict__, "baud": fits[0]})
        base.bandwidth_check()
        return base

    @property
    def frame_bytes(self) -> int:
        """Bytes of a whole data frame, ``44 + 12 E``."""
        return FRAME_FIXED + RECORD_BYTES * self.slots

    @property
    def payload_len(self) -> int:
        """Bytes of a data frame's payload, ``32 + 12 E``."""
        return self.frame_bytes - 12

    def bandwidth_check(self) -> None:
        """Raise :class:`BandwidthError` unless the stream fits ``baud`` with 20 % to spare."""
        if self.fits(self.baud):
            return
        fitting = [b for b in sorted(BAUD_CODES) if self.fits(b)]
        advice = f"use baud={fitting[0]} or faster" if fitting else "lower the rate or the slots"
        raise BandwidthError(
            f"timer frames of {self.slots} edge slots at {self.rate_hz:g} Hz need "
            f"{self.line_bits_per_s / 1e6:.4g} Mbit/s plus 20 % reserve, more than "
            f"{self.baud} baud carries; {advice}"
        )

    def commands(self) -> list[tuple[str, str]]:
        """``(verb, args)`` of the configuration commands, in the order to send them."""
        tc = "0" if self.timecode is None else f"1,{self.timecode[0]},{int(self.timecode[1])}"
        return [
            ("RATE", str(self.rate_mhz)),
            ("EDGS", str(self.slots)),
            ("TCOD", tc),
            *[("ARM", f"{i},{mode}") for i, mode in enumerate(self.arm)],
        ]

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe form (recording metadata)."""
        return {
            "rate_mhz": self.rate_mhz,
            "slots": self.slots,
            "arm": list(self.arm),
            "timecode": None if self.timecode is None else list(self.timecode),
            "baud": self.baud,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> TimerConfig:
        """Inverse of :meth:`to_dict`; missing keys take their defaults.

        Raises
        ------
        ConfigurationError
            If a value is malformed or out of range.
        """
        try:
            kwargs: dict[str, Any] = {}
            for key in ("rate_mhz", "slots", "baud"):
                if key in d:
                    kwargs[key] = int(d[key])
            if "arm" in d:
                kwargs["arm"] = tuple(int(m) for m in d["arm"])
            if d.get("timecode") is not None:
                fps, df = d["timecode"]
                kwargs["timecode"] = (int(fps), bool(df))
        except (TypeError, ValueError) as exc:
            raise ConfigurationError(f"malformed TMR configuration {dict(d)!r}: {exc}") from exc
        return cls(**kwargs)
