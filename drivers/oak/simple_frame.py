"""A plain frame record that satisfies :class:`~spotlab.drivers.oak.seam.OakFrameLike`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt


@dataclass(frozen=True)
class OakFrame:
    """One camera image with its times (fields: see ``OakFrameLike``)."""

    socket: str
    seq: int
    image: npt.NDArray[np.uint8]
    host_ns: int
    device_ns: int
    exposure_us: int
