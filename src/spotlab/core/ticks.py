"""Unwrapping of device counters (ticks, sequence numbers) to int64.

Devices send counters of 16 or 32 bits that wrap. The host keeps the full
count: each new value is placed at the unwrapped value nearest to the
previous one that has the same residue modulo 2**bits, which is correct as
long as consecutive values are less than half a period apart.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt


def unwrap_counter(
    values: npt.ArrayLike, bits: int, previous: int | None = None
) -> npt.NDArray[np.int64]:
    """Unwrap a sequence of wrapping counter values to int64.

    Parameters
    ----------
    values : array_like of int, shape (N,)
        Raw counter values, each in ``[0, 2**bits)``.
    bits : int
        Width of the counter in bits (1 to 62).
    previous : int, optional
        The unwrapped value that came just before ``values[0]`` (from an
        earlier block). Without it the first value is taken as it is.

    Returns
    -------
    ndarray of int64, shape (N,)
        Unwrapped counter values.

    Raises
    ------
    ValueError
        If ``bits`` is out of range or a value does not fit in ``bits``.
    """
    if not 1 <= bits <= 62:
        raise ValueError(f"counter width must be 1 to 62 bits, got {bits}")
    raw = np.asarray(values, dtype=np.int64).reshape(-1)
    period = np.int64(1) << bits
    if raw.size and (raw.min() < 0 or raw.max() >= period):
        raise ValueError(f"counter value outside [0, 2**{bits})")
    if raw.size == 0:
        return raw.copy()
    half = period // 2
    if previous is None:
        start = raw[:1]
    else:
        start = np.array([previous], dtype=np.int64)
    chain = np.concatenate([start, raw])
    steps = np.diff(chain)
    # Bring every step into [-half, half): a wrap shows as a large negative jump.
    steps = (steps + half) % period - half
    base = raw[0] if previous is None else previous
    return np.asarray(base + np.cumsum(steps), dtype=np.int64)


class CounterUnwrapper:
    """Stateful unwrapper that carries the last value across blocks.

    Parameters
    ----------
    bits : int
        Width of the counter in bits.
    """

    def __init__(self, bits: int) -> None:
        self.bits = bits
        self.last: int | None = None

    def __call__(self, values: npt.ArrayLike) -> npt.NDArray[np.int64]:
        """Unwrap the next block of raw values, shape (N,) -> (N,) int64."""
        out = unwrap_counter(values, self.bits, self.last)
        if out.size:
            self.last = int(out[-1])
        return out

    def reset(self) -> None:
        """Forget the history (after a device reset, the counter restarts)."""
        self.last = None
