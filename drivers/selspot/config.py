"""SPX configuration, checked on the host before anything is sent (selspot.md §2).

:class:`SelspotConfig` holds what the ``CAMS``, ``LEDT``, ``SLOT``, ``RATE``,
``BGND`` and ``AGC`` commands set and the baud rate of the link. It checks the
ranges of §2 when built, and offers the two checks the device makes at
``START:`` so that a user hears about them before opening a port:

* :meth:`SelspotConfig.timing_check` — the frame period holds every slot,
  ``1/rate >= (N + 1 + b) * slot``;
* :meth:`SelspotConfig.bandwidth_check` — the line carries the stream with 20 %
  to spare, ``rate * (28 + 5 N C) * 10 <= 0.8 * baud``.

Both are done in integers (rate in mHz, slot in µs), exactly as the spec states them.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from spotlab.core.errors import BandwidthError, ConfigurationError
from spotlab.drivers.mcs1.commands import BAUD_CODES
from spotlab.drivers.mcs1.load import LineLoad

MAX_CAMERAS = 4
MAX_LEDS = 128
#: Drive current given to LEDs listed by count or id only: 0x80 = 32 mA.
DEFAULT_CURRENT = 0x80
DEFAULT_AGC_TARGET = 160
#: Bytes of a data frame besides the records: 12 framing + 12 prefix + 4 SPX header.
FRAME_FIXED = 28
RECORD_BYTES = 5
BGND_MODES = {0: "none", 1: "dark sample in every slot", 2: "one dark slot per frame"}


def led_table(leds: int | Iterable[int | Sequence[int]]) -> tuple[tuple[int, int], ...]:
    """An LED table from a count, a list of ids, or a list of ``(id, current)`` pairs.

    Parameters
    ----------
    leds : int or iterable
        ``N`` gives LEDs 0 to N-1; ids alone get :data:`DEFAULT_CURRENT`.

    Returns
    -------
    tuple of (int, int)
        ``(id, drive current step)`` in firing order (current in 1/4 mA steps).

    Raises
    ------
    ConfigurationError
        If an entry is neither an int nor a pair of ints.
    """
    if isinstance(leds, int):
        if isinstance(leds, bool):
            raise ConfigurationError(f"leds must be a count or a list, not {leds!r}")
        return tuple((i, DEFAULT_CURRENT) for i in range(leds))
    table = []
    for entry in leds:
        if isinstance(entry, int) and not isinstance(entry, bool):
            table.append((entry, DEFAULT_CURRENT))
        elif (
            isinstance(entry, Sequence)
            and len(entry) == 2
            and all(isinstance(v, int) and not isinstance(v, bool) for v in entry)
        ):
            table.append((int(entry[0]), int(entry[1])))
        else:
            raise ConfigurationError(
                f"LED table entry {entry!r} is neither an id nor an (id, current) pair"
            )
    return tuple(table)


@dataclass(frozen=True)
class SelspotConfig(LineLoad):
    """What an SPX system is told before ``START:``.

    Parameters
    ----------
    cameras : int
        Number of cameras, 1-4.
    leds : tuple of (int, int)
        LED table in firing order: ``(id 0-127, drive current 0-255 in 1/4 mA)``,
        1-128 entries, ids unique.
    slot_us : int
        Slot period in µs, 50-1000.
    rate_mhz : int
        Frame rate in millihertz, 1 000-10 000 000.
    bgnd : int
        Background differencing: 0 none, 1 a dark sample per slot, 2 a dark slot per frame.
    agc_target : int or None
        AGC target intensity 1-255, or ``None`` for AGC off.
    baud : int
        Line rate while streaming; one of the ``COMM`` rates of mcs1.md §1.

    Raises
    ------
    ConfigurationError
        If any value is out of its range; the message names it and the range.
    """

    cameras: int = 1
    leds: tuple[tuple[int, int], ...] = tuple((i, DEFAULT_CURRENT) for i in range(8))
    slot_us: int = 100
    rate_mhz: int = 100_000
    bgnd: int = 1
    agc_target: int | None = None
    baud: int = 2_000_000

    def __post_init__(self) -> None:
        def need(ok: bool, message: str) -> None:
            if not ok:
                raise ConfigurationError(message)

        need(
            1 <= self.cameras <= MAX_CAMERAS, f"cameras must be 1-{MAX_CAMERAS}, got {self.cameras}"
        )
        need(
            1 <= len(self.leds) <= MAX_LEDS,
            f"the LED table needs 1-{MAX_LEDS} entries, got {len(self.leds)}",
        )
        ids = [led for led, _ in self.leds]
        bad_ids = [led for led in ids if not 0 <= led <= 0x7F]
        need(not bad_ids, f"LED ids must be 0-127, got {bad_ids}")
        twice = sorted({led for led in ids if ids.count(led) > 1})
        need(not twice, f"LED ids must be unique in the table; listed twice: {twice}")
        bad_currents = [cur for _, cur in self.leds if not 0 <= cur <= 0xFF]
        need(
            not bad_currents, f"LED drive currents must be 0-255 (1/4 mA steps), got {bad_currents}"
        )
        need(50 <= self.slot_us <= 1000, f"slot_us must be 50-1000 µs, got {self.slot_us}")
        need(
            1_000 <= self.rate_mhz <= 10_000_000,
            f"the frame rate must be 1-10000 Hz, got {self.rate_mhz / 1000:g} Hz",
        )
        need(self.bgnd in BGND_MODES, f"bgnd must be 0, 1 or 2, got {self.bgnd}")
        need(
            self.agc_target is None or 1 <= self.agc_target <= 255,
            f"the AGC target intensity must be 1-255, got {self.agc_target}",
        )
        need(
            self.baud in BAUD_CODES,
            f"baud must be one of {sorted(BAUD_CODES)}, got {self.baud}",
        )

    @classmethod
    def create(
        cls,
        *,
        cameras: int = 1,
        leds: int | Iterable[int | Sequence[int]] = 8,
        rate_hz: float = 100.0,
        slot_us: int = 100,
        bgnd: int = 1,
        agc: int | None = None,
        baud: int | str = 2_000_000,
    ) -> SelspotConfig:
        """A checked configuration from user-facing values.

        Parameters
        ----------
        cameras : int
            Number of cameras, 1-4.
        leds : int or iterable
            LED count, list of ids, or list of ``(id, current)`` (see :func:`led_table`).
        rate_hz : float
            Frame rate in Hz (sent in mHz, rounded to the nearest).
        slot_us : int
            Slot period in µs.
        bgnd : int
            Background differencing mode, 0-2.
        agc : int or None
            AGC target intensity (AGC on), or ``None`` (AGC off).
        baud : int or "auto"
            Line rate while streaming; ``"auto"`` picks the slowest rate that
            passes the bandwidth check.

        Raises
        ------
        ConfigurationError
            If a value is out of range or the timing check fails.
        BandwidthError
            If the stream does not fit ``baud`` (or any rate, for ``"auto"``).
        """
        if isinstance(baud, str) and baud != "auto":
            raise ConfigurationError(f"baud must be a rate in baud or 'auto', got {baud!r}")
        if not math.isfinite(rate_hz):
            raise ConfigurationError(f"the frame rate must be a finite number, got {rate_hz}")
        base = cls(
            cameras=cameras,
            leds=led_table(leds),
            slot_us=slot_us,
            rate_mhz=round(rate_hz * 1000),
            bgnd=bgnd,
            agc_target=agc,
            baud=max(BAUD_CODES) if baud == "auto" else int(baud),
        )
        base.timing_check()
        if baud == "auto":
            base.bandwidth_check(max(BAUD_CODES))
            fits = [b for b in sorted(BAUD_CODES) if base.fits(b)]
            base = cls(**{**base.__dict__, "baud": fits[0]})
        base.bandwidth_check()
        return base

    # -- derived figures -----------------------------------------------------------
    @property
    def n_leds(self) -> int:
        """LEDs in the table (``N``)."""
        return len(self.leds)

    @property
    def payload_len(self) -> int:
        """Bytes of a data frame's payload, ``16 + 5 N C``."""
        return FRAME_FIXED - 12 + RECORD_BYTES * self.n_leds * self.cameras

    @property
    def frame_bytes(self) -> int:
        """Bytes of a whole data frame, ``28 + 5 N C``."""
        return FRAME_FIXED + RECORD_BYTES * self.n_leds * self.cameras

    # -- the START: checks -----------------------------------------------------------
    def timing_check(self) -> None:
        """Check that one frame period holds every slot (``START:`` check 2).

        Raises
        ------
        ConfigurationError
            If ``1/rate < (N + 1 + b) * slot``; the message gives the highest rate
            and the longest slot that would fit.
        """
        slots = self.n_leds + 1 + (1 if self.bgnd == 2 else 0)
        # 1/rate >= slots * slot, with 1/rate = 1e9 / rate_mhz µs.
        if slots * self.slot_us * self.rate_mhz <= 1_000_000_000:
            return
        max_rate = 1e6 / (slots * self.slot_us)
        max_slot = 1_000_000_000 // (slots * self.rate_mhz)
        raise ConfigurationError(
            f"a frame at {self.rate_hz:g} Hz lasts {1e6 / self.rate_hz:.0f} µs, too short for "
            f"{slots} slots of {self.slot_us} µs ({self.n_leds} LEDs + 1"
            + (" + 1 dark slot" if self.bgnd == 2 else "")
            + f"); lower the rate to {max_rate:g} Hz or less"
            + (f", or shorten the slot to {max_slot} µs or less" if max_slot >= 50 else "")
        )

    def bandwidth_check(self, baud: int | None = None) -> None:
        """Check that the stream fits the line with 20 % to spare (``START:`` check 3).

        Parameters
        ----------
        baud : int, optional
            Line rate to check; the configuration's ``baud`` by default.

        Raises
        ------
        BandwidthError
            If ``rate * (28 + 5 N C) * 10 > 0.8 * baud``; the message gives the
            bit rate needed, the slowest line rate that would carry it (or that
            none does) and the highest frame rate ``baud`` carries.
        """
        baud = self.baud if baud is None else baud
        if self.fits(baud):
            return
        need = self.line_bits_per_s
        fitting = [b for b in sorted(BAUD_CODES) if self.fits(b)]
        max_rate = 80 * baud // self.frame_bytes / 1000
        advice = (
            f"use baud={fitting[0]} or faster"
            if fitting
            else f"no MCS-1 rate carries it (fastest {max(BAUD_CODES)} baud)"
        )
        raise BandwidthError(
            f"{self.cameras} camera(s) x {self.n_leds} LEDs at {self.rate_hz:g} Hz need "
            f"{need / 1e6:.4g} Mbit/s ({self.frame_bytes}-byte frames) plus 20 % reserve, "
            f"more than {baud} baud carries; {advice}, or lower the rate to "
            f"{max_rate:g} Hz or less"
        )

    # -- wire form -------------------------------------------------------------------
    def commands(self) -> list[tuple[str, str]]:
        """``(verb, args)`` of the configuration commands, in the order to send them."""
        agc_on, target = (
            (0, DEFAULT_AGC_TARGET) if self.agc_target is None else (1, self.agc_target)
        )
        return [
            ("CAMS", str(self.cameras)),
            ("LEDT", "".join(f"{led:02X}{cur:02X}" for led, cur in self.leds)),
            ("SLOT", str(self.slot_us)),
            ("RATE", str(self.rate_mhz)),
            ("BGND", str(self.bgnd)),
            ("AGC", f"{agc_on},{target}"),
        ]

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe form (recording metadata)."""
        return {
            "cameras": self.cameras,
            "leds": [[led, cur] for led, cur in self.leds],
            "slot_us": self.slot_us,
            "rate_mhz": self.rate_mhz,
            "bgnd": self.bgnd,
            "agc_target": self.agc_target,
            "baud": self.baud,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> SelspotConfig:
        """Inverse of :meth:`to_dict`; missing keys take their defaults.

        Raises
        ------
        ConfigurationError
            If a value is malformed or out of range.
        """
        try:
            kwargs: dict[str, Any] = {}
            for key in ("cameras", "slot_us", "rate_mhz", "bgnd", "baud"):
                if key in d:
                    kwargs[key] = int(d[key])
            if "leds" in d:
                kwargs["leds"] = led_table(d["leds"])
            if d.get("agc_target") is not None:
                kwargs["agc_target"] = int(d["agc_target"])
        except (TypeError, ValueError) as exc:
            if isinstance(exc, ConfigurationError):
                raise
            raise ConfigurationError(f"malformed SPX configuration {dict(d)!r}: {exc}") from exc
        return cls(**kwargs)
