"""Session time and the LSL clock: one constant offset on the same host.

Session time in spotlab is seconds on the host monotonic clock
(``time.monotonic_ns() / 1e9``, the clock of ``FrameBlock.arrival_ns`` and of
the simulators' world clock), minus an optional origin. LSL stamps samples with
``pylsl.local_clock()``, liblsl's steady clock in seconds. Both tick at the same
rate on one host (on Linux both read ``CLOCK_MONOTONIC``, so the offset is
zero to within the reading), so one offset maps one onto the other:

    lsl_s = session_s + offset_s
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from spotlab.acquisition.lsl._pylsl import pylsl_module
from spotlab.core.errors import ConfigurationError

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class LslClock:
    """Map session seconds to LSL ``local_clock`` seconds and back.

    Attributes
    ----------
    offset_s : float
        ``local_clock() - session time`` in s.
    uncertainty_s : float
        Half the width of the bracket the offset was read in (s); 0 when given.
    """

    offset_s: float
    uncertainty_s: float = 0.0

    @classmethod
    def measure(cls, origin_ns: int = 0, reads: int = 16) -> LslClock:
        """Read the offset: ``local_clock()`` bracketed by two monotonic reads, narrowest kept.

        Parameters
        ----------
        origin_ns : int, optional
            Host monotonic time (ns) of session time zero (default 0: session
            time is the monotonic clock itself).
        reads : int, optional
            Brackets to try (default 16).

        Raises
        ------
        ConfigurationError
            If ``reads`` < 1 or pylsl is missing.
        """
        if reads < 1:
            raise ConfigurationError(f"reads must be at least 1, got {reads}")
        local_clock = pylsl_module().local_clock
        best = None
        for _ in range(reads):
            a = time.monotonic_ns()
            lsl = float(local_clock())
            b = time.monotonic_ns()
            if best is None or b - a < best[0]:
                best = (b - a, lsl, (a + b) // 2)
        assert best is not None
        width_ns, lsl, mid_ns = best
        return cls(offset_s=lsl - (mid_ns - origin_ns) / 1e9, uncertainty_s=width_ns / 2e9)

    def to_lsl(self, session_s: npt.ArrayLike) -> F64:
        """LSL ``local_clock`` seconds of session times (any shape)."""
        return np.asarray(session_s, dtype=np.float64) + self.offset_s

    def to_session(self, lsl_s: npt.ArrayLike) -> F64:
        """Session seconds of LSL ``local_clock`` times (any shape)."""
        return np.asarray(lsl_s, dtype=np.float64) - self.offset_s
