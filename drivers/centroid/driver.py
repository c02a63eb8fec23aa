"""The CEN video-centroid hub driver (centroid.md §6): MCS-1 state machine, hub set-up.

:class:`CentroidDriver` resets, negotiates (CEN accepts 6 and 12 Mbaud too),
checks ``VER:0`` (``CEN``, enough cameras, blob cap, 1 MHz camera clocks), sends
``RATE``, ``CAMS``, ``EXPO``, ``THRS`` and ``BLOB`` and starts the stream;
recovery is :class:`Mcs1Driver`'s.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any, ClassVar

from spotlab.core.errors import ConfigurationError, ProtocolError
from spotlab.core.streams import StreamSpec
from spotlab.drivers.base import DeviceInfo
from spotlab.drivers.centroid.config import CEN_BAUD_CODES, CentroidConfig
from spotlab.drivers.centroid.protocol import (
    FAMILY_CODE,
    TICK_HZ,
    UNITS,
    VALUES,
    CentroidDecoder,
    CentroidVersion,
    parse_version,
)
from spotlab.drivers.mcs1.commands import Reply
from spotlab.drivers.mcs1.driver import Mcs1Driver


class CentroidDriver(Mcs1Driver):
    """Driver of a CEN video-centroid hub.

    Parameters
    ----------
    port : str or path-like
        Device path or pyserial URL (``sim://centroid?...``).
    name : str, optional
        Stream name; ``"centroid"`` by default.
    cameras : int, optional
        Enable cameras 0 .. cameras-1; or give ``camera_mask``.
    camera_mask : int, optional
        Enabled cameras as a bit mask.
    rate_hz : float, optional
        Frame rate in Hz.
    exposure_us, threshold, max_blobs : int, optional
        ``EXPO``, ``THRS`` and ``BLOB``.

    Settings not given (None) keep what the hub reports it has (``CONF:``, read once at
    :meth:`start`); a hub that does not know ``CONF:`` gets 8 cameras, 100 Hz, 500 µs,
    threshold 128 and 256 blobs.
    baud : int or "auto"
        Line rate while streaming (default 12 Mbaud).
    reply_timeout, reconnect_timeout : float
        As :class:`~spotlab.drivers.mcs1.driver.Mcs1Driver`.

    Raises
    ------
    ConfigurationError
        If the configuration is out of range.
    BandwidthError
        If frames without blobs do not fit ``baud`` or the longest frame is too long.
    """

    family = "centroid"
    family_code = FAMILY_CODE
    decoder_path = "spotlab.drivers.centroid:decoder_from_metadata"
    baud_codes: ClassVar[dict[int, int]] = CEN_BAUD_CODES
    config: CentroidConfig
    _decoder: CentroidDecoder

    def __init__(
        self,
        port: str | os.PathLike[str],
        *,
        name: str | None = None,
        cameras: int | None = None,
        camera_mask: int | None = None,
        rate_hz: float | None = None,
        exposure_us: int | None = None,
        threshold: int | None = None,
        max_blobs: int | None = None,
        baud: int | str = 12_000_000,
        reply_timeout: float = 1.0,
        reconnect_timeout: float | None = None,
    ) -> None:
        super().__init__(port, name=name)
        given = {
            "cameras": cameras, "camera_mask": camera_mask, "rate_hz": rate_hz,
            "exposure_us": exposure_us, "threshold": threshold, "max_blobs": max_blobs,
        }  # fmt: skip
        self._asked: dict[str, Any] = {k: v for k, v in given.items() if v is not None}
        self._fixed: dict[str, Any] = {"baud": baud}
        self.config = CentroidConfig.create(**self._asked, **self._fixed)
        #: What the hub said of itself (``VER:0``), once started.
        self.device: CentroidVersion | None = None
        self._setup(
            self.config,
            CentroidDecoder(self.config, stats=self.stats),
            reply_timeout,
            reconnect_timeout,
        )

    @property
    def spec(self) -> StreamSpec:
        """The stream: ``blobs2d``, camera columns, hub ticks in µs (layout: protocol.py)."""
        c = self.config
        return StreamSpec(
            name=self.name,
            kind="blobs2d",
            n_sensors=c.n_columns,
            n_markers=c.max_blobs + 1,
            rate_hz=c.rate_hz,
            tick_hz=float(TICK_HZ),
            slot_period_s=None,
            values=VALUES,
            units=UNITS,
            metadata={"config": c.to_dict(), "layout": "cen-blobs-v1"},
        )

    @property
    def decoder(self) -> CentroidDecoder:
        """The decoder fed by this driver (its ``stats`` are the driver's)."""
        return self._decoder

    # -- family hooks ----------------------------------------------------------------
    def _unasked(self) -> list[str]:
        keys = [k for k in ("rate_hz", "exposure_us", "threshold", "max_blobs")]
        if "cameras" not in self._asked and "camera_mask" not in self._asked:
            keys.append("camera_mask")
        return [k for k in keys if k not in self._asked]

    def _device_settings(self, fields: Mapping[str, str]) -> dict[str, Any]:
        verbs = {"RATE": "rate_hz", "CAMS": "camera_mask", "EXPO": "exposure_us",
                 "THRS": "threshold", "BLOB": "max_blobs"}  # fmt: skip
        try:
            out: dict[str, Any] = {key: int(fields[v]) for v, key in verbs.items() if v in fields}
        except ValueError:
            raise ProtocolError(f"{self.port}: CONF reply {fields} has a malformed value") from None
        if "rate_hz" in out:
            out["rate_hz"] = out["rate_hz"] / 1000
        if "cameras" in self._asked:
            out.pop("camera_mask", None)
        return out

    def _rebuild(self, device: Mapping[str, Any]) -> tuple[CentroidConfig, CentroidDecoder]:
        config = CentroidConfig.create(**{**device, **self._asked, **self._fixed})
        return config, CentroidDecoder(config, stats=self.stats)

    def _check_device(self, reply: Reply) -> None:
        self.device = parse_version(reply.text)
        c = self.config
        if self.device.cameras < c.n_columns or self.device.max_blobs < c.max_blobs:
            raise ConfigurationError(
                f"the hub on {self.port} ({reply.text}) has {self.device.cameras} cameras and "
                f"a cap of {self.device.max_blobs} blobs; asked for cameras {list(c.cameras)} "
                f"and {c.max_blobs} blobs"
            )
        if self.device.tick_hz != TICK_HZ:
            raise ConfigurationError(
                f"the hub on {self.port} stamps at {self.device.tick_hz} Hz, not {TICK_HZ}"
            )

    def _describe_load(self) -> str:
        c = self.config
        return f"{c.n_enabled} cameras at {c.rate_hz:g} Hz"

    @classmethod
    def _device_info(cls, port: str, text: str) -> DeviceInfo:
        version = parse_version(text)
        return DeviceInfo(
            family=cls.family,
            port=port,
            description=version.text,
            serial_number=version.serial_number,
            extra={"firmware": version.firmware, "cameras": version.cameras},
        )
