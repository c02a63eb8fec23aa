"""The CEN video-centroid hub driver (centroid.md §6): MCS-1 state machine, hub set-up.

:class:`CentroidDriver` resets, negotiates (CEN accepts 6, 12 and 24 Mbaud too),
checks ``VER:0`` (``CEN``, enough cameras, blob cap, 1 MHz camera clocks), sends
``RATE``, ``CAMS``, ``EXPO``, ``THRS`` and ``BLOB`` and starts the stream;
recovery is :class:`Mcs1Driver`'s.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any, ClassVar

from spotlab.core.errors import ConfigurationError
from spotlab.core.streams import StreamSpec
from spotlab.drivers.centroid.config import CEN_BAUD_CODES, DEFAULT_BAUD, CentroidConfig
from spotlab.drivers.centroid.protocol import (
    FAMILY_CODE,
    TICK_HZ,
    UNITS,
    VALUES,
    CentroidDecoder,
    CentroidVersion,
)
from spotlab.drivers.mcs1.commands import Reply
from spotlab.drivers.mcs1.family import FamilyDriver


class CentroidDriver(FamilyDriver[CentroidConfig, CentroidDecoder, CentroidVersion]):
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
        Line rate while streaming (default 24 Mbaud, the fastest).
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
    config_class = CentroidConfig
    decoder_class = CentroidDecoder
    version_class = CentroidVersion
    device_keys = ("rate_hz", "exposure_us", "threshold", "max_blobs", "camera_mask")
    conf_verbs: ClassVar[Mapping[str, str]] = {
        "RATE": "rate_hz", "CAMS": "camera_mask", "EXPO": "exposure_us",
        "THRS": "threshold", "BLOB": "max_blobs",
    }  # fmt: skip
    stream_kind = "blobs2d"
    stream_tick_hz = float(TICK_HZ)
    values = VALUES
    units = UNITS
    info_fields = ("firmware", "cameras")

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
        baud: int | str = DEFAULT_BAUD,
        reply_timeout: float = 1.0,
        reconnect_timeout: float | None = None,
    ) -> None:
        given = {
            "cameras": cameras, "camera_mask": camera_mask, "rate_hz": rate_hz,
            "exposure_us": exposure_us, "threshold": threshold, "max_blobs": max_blobs,
        }  # fmt: skip
        fixed = {"baud": baud}
        super().__init__(port, name, given, fixed, reply_timeout, reconnect_timeout)

    @property
    def spec(self) -> StreamSpec:
        """The stream: ``blobs2d``, camera columns, hub ticks in µs (layout: protocol.py)."""
        c = self.config
        return self._spec(c.n_columns, c.max_blobs + 1, layout="cen-blobs-v1")

    # -- family hooks ----------------------------------------------------------------
    def _unasked(self) -> list[str]:
        # Cameras given as a count give the mask too.
        cameras_given = "cameras" in self._asked
        return [k for k in super()._unasked() if not (k == "camera_mask" and cameras_given)]

    def _conf_extras(self, fields: Mapping[str, str], out: dict[str, Any]) -> None:
        if "cameras" in self._asked:
            out.pop("camera_mask", None)

    def _check_version(self, device: CentroidVersion, reply: Reply) -> None:
        c = self.config
        if device.cameras < c.n_columns or device.max_blobs < c.max_blobs:
            raise ConfigurationError(
                f"the hub on {self.port} ({reply.text}) has {device.cameras} cameras and "
                f"a cap of {device.max_blobs} blobs; asked for cameras {list(c.cameras)} "
                f"and {c.max_blobs} blobs"
            )
        if device.tick_hz != TICK_HZ:
            raise ConfigurationError(
                f"the hub on {self.port} stamps at {device.tick_hz} Hz, not {TICK_HZ}"
            )

    def _describe_load(self) -> str:
        c = self.config
        return f"{c.n_enabled} cameras at {c.rate_hz:g} Hz"
