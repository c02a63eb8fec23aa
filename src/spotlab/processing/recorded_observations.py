"""Detector readings of a SELSPOT-style (``selspot``) recording, for calibration and
reconstruction.

- Marker ``m`` (1-based) is the ``m``-th LED of the recording's LED table, the LED
  with id ``m - 1`` for the default table (``--leds N``).
- Image coordinates are the PSD's detector counts as recorded, 12-bit values
  0-4094 with the optical axis at 2048, +x right and +y down the detector. The image
  size is 4096 x 4096 counts: spotlab's image centre, ``(W/2, H/2)``, where the
  cold start puts the principal point, is then exactly the detector's centre 2048 (the
  range 0-4094 would suggest 4095, whose centre 2047.5 is half a count off).
- A reading is dropped (NaN) when the device flagged it not valid or saturated
  (saturation pulls it towards the centre), and when it sits on the detector's edge, 0
  or 4094 counts (clipped: the light fell further out).
- Frames lost on the link are not invented: :func:`frame_numbers` places each decoded
  frame on the recording's regular frame grid by its device time stamp, so that a
  trajectory keeps a gap (NaN) where a frame is missing.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.acquisition.live.readings import FLAG_SATURATED, PSD_MAX_COUNT, usable_counts
from spotlab.acquisition.replay import replay
from spotlab.core.wire import StreamDecoder
from spotlab.processing.decoding import decoder_for
from spotlab.processing.errors import InputError

__all__ = [
    "FLAG_SATURATED",
    "PSD_IMAGE_SIZE",
    "PSD_MAX_COUNT",
    "SelspotRecording",
    "frame_numbers",
    "read_selspot",
    "usable_counts",
]

FloatArray = NDArray[np.float64]

#: Image size of a lateral-photodiode camera in detector counts (12-bit coordinates):
#: its centre (2048, 2048) is the detector's.
PSD_IMAGE_SIZE = (4096, 4096)


@dataclass
class SelspotRecording:
    """Every decoded frame of a one-device selspot recording, in recording order.

    Attributes
    ----------
    data : ndarray, shape (F, M, C, 3)
        Detector x, y (counts) and intensity per frame, marker and camera; NaN where
        not valid.
    flags : ndarray of uint8, shape (F, M, C)
        SPX record flags.
    ticks : ndarray of int64, shape (F,)
        Unwrapped device time stamps (ticks).
    rate_hz, tick_hz : float
        Nominal frame rate and device tick rate of the stream.
    """

    data: FloatArray
    flags: NDArray[np.uint8]
    ticks: NDArray[np.int64]
    rate_hz: float
    tick_hz: float


def read_selspot(path: Path) -> SelspotRecording:
    """Decode every frame of a recording of one selspot device.

    Raises
    ------
    InputError
        For a recording of several devices, of another family, or without frames.
    """
    metas: list[dict[str, Any]] = []

    def factory(metadata: dict[str, Any]) -> StreamDecoder:
        metas.append(metadata)
        return decoder_for(metadata)

    names: set[str] = set()
    data, flags, ticks = [], [], []
    for name, block in replay(path, factory):
        names.add(name)
        data.append(block.data)
        flags.append(block.flags)
        ticks.append(block.ticks)
    if len(names) > 1:
        raise InputError(
            f"{path}: {len(names)} streams ({', '.join(sorted(names))}); spotlab reads "
            "recordings of one device here"
        )
    families = [m.get("family") for m in metas]
    if any(f != "selspot" for f in families):
        raise InputError(
            f"{path}: a {families[0]!r} recording; only selspot (PSD) recordings are read here"
        )
    if not data or sum(len(d) for d in data) == 0:
        raise InputError(f"{path}: the recording holds no frames")
    spec = metas[-1].get("spec") or {}
    return SelspotRecording(
        np.concatenate(data),
        np.concatenate(flags),
        np.concatenate(ticks).astype(np.int64),
        float(spec.get("rate_hz", np.nan)),
        float(spec.get("tick_hz", np.nan)),
    )


def frame_numbers(recording: SelspotRecording, path: Path) -> NDArray[np.intp]:
    """Place of each decoded frame on the regular frame grid (the first frame is 0).

    Raises
    ------
    InputError
        If the stream's rates are unknown or its time stamps go backwards (a device
        reset in the middle of the recording).
    """
    rate, tick_hz = recording.rate_hz, recording.tick_hz
    if not (np.isfinite(rate) and rate > 0 and np.isfinite(tick_hz) and tick_hz > 0):
        raise InputError(f"{path}: the recording does not state its frame and tick rates")
    elapsed = (recording.ticks - recording.ticks[0]).astype(np.float64) / tick_hz
    number = np.rint(elapsed * rate).astype(np.intp)
    if (np.diff(number) <= 0).any():
        raise InputError(
            f"{path}: device time stamps go backwards or repeat (a reset during the "
            "recording?); split the recording at the reset"
        )
    return number
