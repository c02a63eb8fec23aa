"""CEN configuration, checked on the host before anything is sent (centroid.md §2).

:class:`CentroidConfig` holds what ``RATE``, ``CAMS``, ``EXPO``, ``THRS`` and
``BLOB`` set and the baud rate, and checks what the hub checks at ``START:``:
the exposure fits the period, the longest frame fits the 16-bit length, and
frames without blobs fit the line with 20 % to spare. Blobs beyond that are the
hub FIFO's business (frames dropped and counted, never silently).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from spotlab.core.errors import BandwidthError, ConfigurationError
from spotlab.drivers.mcs1.commands import BAUD_CODES
from spotlab.drivers.mcs1.load import LineLoad

MAX_CAMERAS = 16
MAX_BLOBS = 1024
#: ``COMM`` codes of the CEN hub: MCS-1's and 10 (6 Mbaud), 11 (12 Mbaud), 12 (24 Mbaud).
CEN_BAUD_CODES: dict[int, int] = {
    **BAUD_CODES, 6_000_000: 10, 12_000_000: 11, 24_000_000: 12,
}  # fmt: skip
#: The line rate used unless another is asked for: the fastest (centroid.md §2).
DEFAULT_BAUD = 24_000_000
FRAME_FIXED = 32
CAMERA_BYTES = 20
BLOB_BYTES = 8
MAX_PAYLOAD = 0xFFFF
#: Blobs per camera and frame assumed for the line load the driver reports.
NOMINAL_BLOBS = 40


@dataclass(frozen=True)
class CentroidConfig(LineLoad):
    """What a CEN hub is told before ``START:``.

    Parameters
    ----------
    rate_mhz : int
        Frame rate in millihertz, 1 000-2 000 000.
    camera_mask : int
        Enabled cameras, bit ``c`` for camera ``c`` (1 to 2**16 - 1).
    exposure_us : int
        Exposure time, 20-10 000 µs, at most 90 % of the period.
    threshold : int
        Blob threshold, grey level 1-254.
    max_blobs : int
        Blob cap per camera and frame, 1-1024.
    baud : int
        Line rate while streaming, a key of :data:`CEN_BAUD_CODES`.
    """

    rate_mhz: int = 100_000
    camera_mask: int = 0xFF
    exposure_us: int = 500
    threshold: int = 128
    max_blobs: int = 256
    baud: int = DEFAULT_BAUD

    def __post_init__(self) -> None:
        checks = (
            (1_000 <= self.rate_mhz <= 2_000_000, f"rate must be 1-2000 Hz, got {self.rate_hz:g}"),
            (
                1 <= self.camera_mask < 1 << MAX_CAMERAS,
                f"camera mask must enable 1-{MAX_CAMERAS} cameras, got {self.camera_mask:#x}",
            ),
            (20 <= self.exposure_us <= 10_000, f"exposure must be 20-10000 µs: {self.exposure_us}"),
            (1 <= self.threshold <= 254, f"threshold must be 1-254, got {self.threshold}"),
            (1 <= self.max_blobs <= MAX_BLOBS, f"blob cap must be 1-{MAX_BLOBS}: {self.max_blobs}"),
            (self.baud in CEN_BAUD_CODES, f"baud {self.baud} is not in {sorted(CEN_BAUD_CODES)}"),
            (
                self.exposure_us * self.rate_mhz <= 900_000_000,
                f"an exposure of {self.exposure_us} µs does not fit 90 % of the "
                f"{1e6 / self.rate_hz:.0f} µs frame period",
            ),
        )  # fmt: skip
        for ok, message in checks:
            if not ok:
                raise ConfigurationError(message)
        if self.max_payload > MAX_PAYLOAD:
            raise BandwidthError(
                f"{self.n_enabled} cameras of up to {self.max_blobs} blobs make frames of up to "
                f"{self.max_payload} bytes, more than the 65535 a frame holds: lower max_blobs"
            )

    @classmethod
    def create(
        cls,
        *,
        cameras: int | None = None,
        camera_mask: int | None = None,
        rate_hz: float = 100.0,
        exposure_us: int = 500,
        threshold: int = 128,
        max_blobs: int = 256,
        baud: int | str = DEFAULT_BAUD,
    ) -> CentroidConfig:
        """A checked configuration; ``cameras`` C enables cameras 0 .. C-1 (default 8).

        Raises
        ------
        ConfigurationError
            If a value is out of range.
        BandwidthError
            If frames without blobs do not fit ``baud``, or the longest frame is too long.
        """
        if not math.isfinite(rate_hz):
            raise ConfigurationError(f"the frame rate must be a finite number, got {rate_hz}")
        if camera_mask is None:
            n = 8 if cameras is None else int(cameras)
            if not 1 <= n <= MAX_CAMERAS:
                raise ConfigurationError(f"cameras must be 1-{MAX_CAMERAS}, got {n}")
            camera_mask = (1 << n) - 1
        if isinstance(baud, str) and baud != "auto":
            raise ConfigurationError(f"baud must be a rate in baud or 'auto', got {baud!r}")
        base = cls(
            rate_mhz=round(rate_hz * 1000), camera_mask=int(camera_mask),
            exposure_us=int(exposure_us), threshold=int(threshold), max_blobs=int(max_blobs),
            baud=max(CEN_BAUD_CODES) if baud == "auto" else int(baud),
        )  # fmt: skip
        base.bandwidth_check()
        return base

    @property
    def cameras(self) -> tuple[int, ...]:
        """Indices of the enabled cameras, increasing."""
        return tuple(c for c in range(MAX_CAMERAS) if self.camera_mask >> c & 1)

    @property
    def n_enabled(self) -> int:
        """Enabled cameras."""
        return len(self.cameras)

    @property
    def n_columns(self) -> int:
        """Camera columns of a decoded block: the highest enabled camera + 1."""
        return self.cameras[-1] + 1

    @property
    def min_payload(self) -> int:
        """Payload bytes of a frame without blobs."""
        return FRAME_FIXED - 12 + CAMERA_BYTES * self.n_enabled

    @property
    def max_payload(self) -> int:
        """Payload bytes of a frame with every camera at its cap."""
        return self.min_payload + BLOB_BYTES * self.max_blobs * self.n_enabled

    @property
    def frame_bytes(self) -> int:
        """Bytes of a whole frame with :data:`NOMINAL_BLOBS` blobs per camera."""
        return (
            self.min_payload + 12 + BLOB_BYTES * min(NOMINAL_BLOBS, self.max_blobs) * self.n_enabled
        )

    @property
    def line_bits_per_s(self) -> float:
        """Bits per second at :data:`NOMINAL_BLOBS` blobs per camera (10 bit times a byte)."""
        return self.rate_mhz * self.frame_bytes * 10 / 1000

    def fits(self, baud: int) -> bool:
        """Whether frames without blobs fit ``baud`` with 20 % to spare (the ``START:`` check)."""
        return self.rate_mhz * (self.min_payload + 12) <= 80 * baud

    def bandwidth_check(self) -> None:
        """Raise :class:`BandwidthError` unless frames without blobs fit ``baud``."""
        if self.fits(self.baud):
            return
        raise BandwidthError(
            f"{self.n_enabled} cameras at {self.rate_hz:g} Hz need "
            f"{self.rate_mhz * (self.min_payload + 12) / 1e5:.4g} Mbit/s before any blob, "
            f"more than {self.baud} baud carries with 20 % reserve; use a faster baud"
        )

    def commands(self) -> list[tuple[str, str]]:
        """``(verb, args)`` of the configuration commands, in the order to send them."""
        return [
            ("RATE", str(self.rate_mhz)),
            ("CAMS", str(self.camera_mask)),
            ("EXPO", str(self.exposure_us)),
            ("THRS", str(self.threshold)),
            ("BLOB", str(self.max_blobs)),
        ]

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe form (recording metadata)."""
        return dict(self.__dict__)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> CentroidConfig:
        """Inverse of :meth:`to_dict`; missing keys take their defaults.

        Raises
        ------
        ConfigurationError
            If a value is malformed or out of range.
        """
        keys = ("rate_mhz", "camera_mask", "exposure_us", "threshold", "max_blobs", "baud")
        try:
            kwargs = {k: int(d[k]) for k in keys if k in d}
        except (TypeError, ValueError) as exc:
            raise ConfigurationError(f"malformed CEN configuration {dict(d)!r}: {exc}") from exc
        return cls(**kwargs)
