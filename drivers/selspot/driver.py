"""The SPX device state machine: bring-up, streaming, recovery, stop (selspot.md §6-7).

:class:`SelspotDriver` (the state machine is
:class:`~spotlab.drivers.mcs1.driver.Mcs1Driver`'s) opens the port at 9600
baud, resets the device (BREAK, else ``RESET:``) and waits for its banner,
moves to the streaming baud rate
(``COMM``, then ``VER:0`` within 1 s, else reset and try once more), configures
it (``CAMS``, ``LEDT``, ``SLOT``, ``RATE``, ``BGND``, ``AGC``: every reply
checked) and starts the stream. :meth:`recv` decodes what the port holds.

While streaming the driver watches for the faults of selspot.md §7 and recovers
by itself: a port that went away, the device's reset banner, or no valid frame
for ``max(0.5 s, 20 frame periods)``. It then reopens the port as often as
needed, resets, renegotiates, reconfigures and restarts, marks the discontinuity
in the decoder, counts a reconnect and a gap, and tells the taps
(``disconnected`` / ``device_reset``, then ``reconnected``).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterable, Mapping
from typing import Any, ClassVar

from spotlab.core.errors import ConfigurationError
from spotlab.core.streams import StreamSpec
from spotlab.drivers.mcs1.commands import Reply
from spotlab.drivers.mcs1.family import FamilyDriver
from spotlab.drivers.selspot.config import SelspotConfig
from spotlab.drivers.selspot.protocol import (
    FAMILY_CODE,
    UNITS,
    VALUES,
    DeviceVersion,
    SelspotDecoder,
)

log = logging.getLogger(__name__)


class SelspotDriver(FamilyDriver[SelspotConfig, SelspotDecoder, DeviceVersion]):
    """Driver of an SPX lateral-photodiode camera system.

    Parameters
    ----------
    port : str or path-like
        Device path (``/dev/ttyUSB0``) or pyserial URL (``socket://``, ``sim://``).
    name : str, optional
        Stream name; ``"selspot"`` by default.
    cameras : int, optional
        Number of cameras, 1-4.
    leds : int or sequence, optional
        LED count (ids 0..N-1 at 32 mA), list of ids, or list of
        ``(id, drive current in 1/4 mA)`` in firing order.
    rate_hz : float, optional
        Frame rate in Hz.
    slot_us : int, optional
        Slot period in µs, 50-1000.
    bgnd : int, optional
        Background differencing: 0 none, 1 dark sample per slot, 2 dark slot per frame.

    Of ``cameras``, ``leds``, ``rate_hz``, ``slot_us`` and ``bgnd``, those not given (None)
    keep what the device reports it has (``CONF:``, read once at :meth:`start`); a device
    without a LED table gets 8 LEDs, one that does not know ``CONF:`` the values of
    :meth:`SelspotConfig.create` (1 camera, 8 LEDs, 100 Hz, 100 µs, mode 1).
    agc : int or None
        AGC target intensity (AGC on), or ``None`` (AGC off).
    baud : int or "auto"
        Line rate while streaming; ``"auto"`` picks the slowest that carries the stream.
    reply_timeout : float
        Seconds to wait for each reply and for the reset banner.
    reconnect_timeout : float or None
        Give up recovering after this many seconds (``DeviceDisconnected``);
        ``None`` keeps trying for as long as ``recv`` is called.

    Raises
    ------
    ConfigurationError
        If the configuration is out of range or its slots do not fit the frame period.
    BandwidthError
        If the stream does not fit ``baud``.
    """

    family = "selspot"
    family_code = FAMILY_CODE
    decoder_path = "spotlab.drivers.selspot:decoder_from_metadata"
    config_class = SelspotConfig
    decoder_class = SelspotDecoder
    version_class = DeviceVersion
    device_keys = ("cameras", "leds", "rate_hz", "slot_us", "bgnd")
    conf_verbs: ClassVar[Mapping[str, str]] = {
        "CAMS": "cameras",
        "RATE": "rate_hz",
        "SLOT": "slot_us",
        "BGND": "bgnd",
    }
    stream_kind = "image2d"
    stream_tick_hz = 1e6
    values = VALUES
    units = UNITS
    info_fields = ("firmware", "max_cameras", "max_leds")

    def __init__(
        self,
        port: str | os.PathLike[str],
        *,
        name: str | None = None,
        cameras: int | None = None,
        leds: int | Iterable[int | tuple[int, int]] | None = None,
        rate_hz: float | None = None,
        slot_us: int | None = None,
        bgnd: int | None = None,
        agc: int | None = None,
        baud: int | str = 2_000_000,
        reply_timeout: float = 1.0,
        reconnect_timeout: float | None = None,
    ) -> None:
        given = {"cameras": cameras, "leds": leds, "rate_hz": rate_hz, "slot_us": slot_us,
                 "bgnd": bgnd}  # fmt: skip
        fixed = {"agc": agc, "baud": baud}
        super().__init__(port, name, given, fixed, reply_timeout, reconnect_timeout)

    # -- description ---------------------------------------------------------------
    @property
    def spec(self) -> StreamSpec:
        """The stream: ``image2d``, cameras x LEDs, x/y/intensity in detector counts."""
        c = self.config
        led_ids = [led for led, _ in c.leds]
        return self._spec(c.cameras, c.n_leds, c.slot_us * 1e-6, led_ids=led_ids)

    # -- family hooks ----------------------------------------------------------------
    def _conf_extras(self, fields: Mapping[str, str], out: dict[str, Any]) -> None:
        table = fields.get("LEDT", "")
        if table:
            out["leds"] = [
                (int(table[i : i + 2], 16), int(table[i + 2 : i + 4], 16))
                for i in range(0, len(table), 4)
            ]

    def _check_version(self, device: DeviceVersion, reply: Reply) -> None:
        c = self.config
        if device.max_cameras < c.cameras or device.max_leds < c.n_leds:
            raise ConfigurationError(
                f"the device on {self.port} ({reply.text}) supports at most "
                f"{device.max_cameras} cameras and {device.max_leds} LEDs; "
                f"configured {c.cameras} cameras and {c.n_leds} LEDs"
            )

    def _describe_load(self) -> str:
        c = self.config
        return f"{c.cameras} camera(s) x {c.n_leds} LEDs at {c.rate_hz:g} Hz"
