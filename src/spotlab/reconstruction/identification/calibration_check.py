"""Whether the calibration matches the cameras, judged from the blobs the identifier uses.

Over every window of frames, each camera's blobs are counted as offered (usable) and as
confirmed (used by a point other cameras see too). A camera that saw markers but whose
blobs the others hardly ever confirm is where the calibration does not match: cameras
swapped, moved, or another rig. Labels made from the remaining cameras would hide it,
so :class:`CalibrationCheck` raises a :class:`CalibrationError` naming the camera.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from spotlab.core.errors import CalibrationError
from spotlab.geometry import Rig

__all__ = ["CalibrationCheck"]

IntArray = NDArray[np.intp]

#: Share of a busy camera's blobs that other cameras must confirm.
MIN_CONFIRMED = 0.2
#: Blobs per frame of the window a camera must offer to be judged (it saw markers).
BUSY_PER_FRAME = 5


class CalibrationCheck:
    """Counts of offered and confirmed blobs per camera over windows of frames.

    Parameters
    ----------
    rig : Rig
        The calibration; its cameras' names go into the error.
    frames : int
        Window (frames); 0 turns the check off.
    """

    def __init__(self, rig: Rig, frames: int) -> None:
        self.rig, self.frames = rig, frames
        C = len(rig)
        self._offered, self._confirmed, self._count = np.zeros(C), np.zeros(C), 0

    def __call__(
        self, camera: IntArray, usable: NDArray[np.bool_], used: NDArray[np.bool_]
    ) -> None:
        """Count one frame's blobs: ``camera`` (N,) of each, ``usable`` (N,) offered,
        ``used`` (N,) confirmed.

        Raises
        ------
        CalibrationError
            At the end of a window, for busy cameras with under 20 % confirmed.
        """
        if self.frames <= 0:
            return
        C = len(self.rig)
        self._offered += np.bincount(camera[usable], minlength=C)
        self._confirmed += np.bincount(camera[usable & used], minlength=C)
        self._count += 1
        if self._count < self.frames:
            return
        offered, confirmed = self._offered, self._confirmed
        self._offered, self._confirmed, self._count = np.zeros(C), np.zeros(C), 0
        busy = offered >= BUSY_PER_FRAME * self.frames  # cameras that saw markers
        with np.errstate(invalid="ignore", divide="ignore"):
            share = confirmed / offered
        bad = np.flatnonzero(busy & (share < MIN_CONFIRMED))
        if bad.size:
            names = [self.rig[int(c)].name or f"camera {c}" for c in bad]
            raise CalibrationError(
                "the calibration does not match the cameras: "
                + ", ".join(
                    f"{n} ({100 * share[c]:.0f} % of blobs confirmed)"
                    for n, c in zip(names, bad, strict=True)
                )
                + f" over {self.frames} frames (cameras swapped, moved, or another rig?)"
            )
