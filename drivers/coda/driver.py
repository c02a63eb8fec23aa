"""The CSX scanner driver (coda.md §7): the MCS-1 state machine with the scanner's set-up.

:class:`CodaDriver` resets, negotiates, checks ``VER:0`` (``CSX``, 16 000 counts
over 40°, and the mirror base when one is asked for), sends ``RATE``, ``OUT`` and
``MARK``, and starts the stream; recovery is :class:`Mcs1Driver`'s. The unit's
geometry goes into the stream's metadata (``geometry``), so that a recording
carries the base its 3-D was computed with.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

from spotlab.core.errors import ConfigurationError
from spotlab.core.streams import StreamSpec
from spotlab.drivers.coda.config import CodaConfig
from spotlab.drivers.coda.protocol import (
    COUNTS,
    FAMILY_CODE,
    TICK_HZ,
    UNITS,
    VALUES,
    CodaDecoder,
    CodaVersion,
)
from spotlab.drivers.mcs1.commands import Reply
from spotlab.drivers.mcs1.family import FamilyDriver

FOV_MDEG = 40_000
#: Part of the scan period the mirrors sweep before the frame is sent (coda.md §1).
SWEEP_FRACTION = 0.8


class CodaDriver(FamilyDriver[CodaConfig, CodaDecoder, CodaVersion]):
    """Driver of a CSX optomechanical scanner.

    Parameters
    ----------
    port : str or path-like
        Device path or pyserial URL (``sim://coda?...``).
    name : str, optional
        Stream name; ``"coda"`` by default.
    rate_hz : float, optional
        Scan rate in Hz (50-800).
    markers : int, str or sequence of str, optional
        The marker table: ``M`` (IDs 1..M), or colour codes (``"RO,GB"``).
    mode : str, optional
        ``3D``, ``RAW`` or ``BOTH``.

    ``rate_hz``, ``markers`` and ``mode`` not given (None) keep what the unit reports
    it has (``CONF:``, read once at :meth:`start`); a unit without a marker table and
    none given gets 8 markers, 300 Hz, ``BOTH``.
    base_mm : float, optional
        The mirror base the unit must report (mm), e.g. the recording's; refused
        with one line if it reports another.
    baud : int or "auto"
        Line rate while streaming.
    reply_timeout, reconnect_timeout : float
        As :class:`~spotlab.drivers.mcs1.driver.Mcs1Driver`.

    Raises
    ------
    ConfigurationError
        If the configuration is out of range (a colour code outside the table, ...).
    BandwidthError
        If the stream does not fit ``baud``.
    """

    family = "coda"
    family_code = FAMILY_CODE
    decoder_path = "spotlab.drivers.coda:decoder_from_metadata"
    config_class = CodaConfig
    decoder_class = CodaDecoder
    version_class = CodaVersion
    device_keys = ("rate_hz", "markers", "mode")
    conf_verbs: ClassVar[Mapping[str, str]] = {"RATE": "rate_hz"}
    stream_kind = "scan3"
    stream_tick_hz = float(TICK_HZ)
    values = VALUES
    units = UNITS
    info_fields = ("firmware", "base_um", "counts", "fov_mdeg")

    def __init__(
        self,
        port: str | os.PathLike[str],
        *,
        name: str | None = None,
        rate_hz: float | None = None,
        markers: int | str | Sequence[str] | None = None,
        mode: str | None = None,
        base_mm: float | None = None,
        baud: int | str = 2_000_000,
        reply_timeout: float = 1.0,
        reconnect_timeout: float | None = None,
    ) -> None:
        given = {"rate_hz": rate_hz, "markers": markers, "mode": mode}
        fixed = {"base_mm": base_mm, "baud": baud}
        #: The unit of the first connection: a reconnection must find the same geometry.
        self._first_unit: CodaVersion | None = None
        super().__init__(port, name, given, fixed, reply_timeout, reconnect_timeout)

    @property
    def spec(self) -> StreamSpec:
        """The stream: ``scan3``, ``2M + 4`` rows (table markers, then unidentified), µs ticks;
        ``frame_delay_s`` in its metadata: from the scan start to the frame's last byte
        (sweep and transmission)."""
        c = self.config
        # The frame leaves after the sweep (0.8 of the scan) and takes its bytes' time on
        # the line: the session time base pairs frames with their pulses knowing it.
        delay = SWEEP_FRACTION / c.rate_hz + c.frame_bytes * 10 / c.baud
        extra: dict[str, Any] = {"marker_ids": list(c.ids), "frame_delay_s": round(delay, 9)}
        if self.device is not None:
            extra["geometry"] = {
                "base_mm": self.device.base_um / 1000,
                "counts": self.device.counts,
                "fov_deg": self.device.fov_mdeg / 1000,
                "serial_number": self.device.serial_number,
            }
        return self._spec(1, 2 * c.n_markers + 4, layout="coda-records-v1", **extra)

    # -- family hooks ----------------------------------------------------------------
    def _conf_extras(self, fields: Mapping[str, str], out: dict[str, Any]) -> None:
        if "OUT" in fields:
            out["mode"] = fields["OUT"]
        if fields.get("MARK"):
            out["markers"] = tuple(fields["MARK"].split(","))

    def _check_version(self, device: CodaVersion, reply: Reply) -> None:
        if device.counts != COUNTS or device.fov_mdeg != FOV_MDEG:
            raise ConfigurationError(
                f"the scanner on {self.port} ({reply.text}) reads {device.counts} counts over "
                f"{device.fov_mdeg / 1000:g} degrees; this driver needs {COUNTS} over 40"
            )
        first = self._first_unit
        if first is not None and (first.base_um, first.serial_number) != (
            device.base_um,
            device.serial_number,
        ):
            raise ConfigurationError(
                f"the scanner on {self.port} came back as {device.serial_number} with a mirror "
                f"base of {device.base_um / 1000:g} mm; the recording holds "
                f"{first.serial_number} with {first.base_um / 1000:g} mm (another unit, or "
                f"another geometry than the recording's)"
            )
        self._first_unit = device
        want = self.config.base_um
        if want is not None and device.base_um != want:
            raise ConfigurationError(
                f"the scanner on {self.port} has a mirror base of {device.base_um / 1000:g} mm, "
                f"not the {want / 1000:g} mm asked for (another unit, or another geometry "
                f"than the recording's)"
            )

    def _describe_load(self) -> str:
        c = self.config
        return f"scanner frames of {c.n_markers} markers in {c.mode} mode at {c.rate_hz:g} Hz"
