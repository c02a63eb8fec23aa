"""The time of every sample: frame time plus the marker's slot offset.

A time-multiplexed device (SELSPOT-style photodiode cameras) fires its LEDs one after
the other within a frame: LED ``k`` of the table (0-based, in the order the device
fires them, which is the marker axis of its frames) is sampled at

.. math:: t_{f,k} = T_f + (k + 1/2)\\,\\tau\\,r,

with :math:`T_f` the session time of frame ``f`` (its first slot's start, the time a
clock model gives for the frame's tick), :math:`\\tau` the slot period in device
seconds (``StreamSpec.slot_period_s``) and :math:`r` the clock's rate, session seconds
per device second (1 + drift; 200 ppm changes a 12.8 ms offset by 2.6 us). Devices
that sample all markers at once have every offset zero.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from spotlab.core.errors import SynchronisationError
from spotlab.core.streams import StreamSpec
from spotlab.core.units import NS_PER_S

F64 = npt.NDArray[np.float64]

__all__ = ["sample_offsets", "sample_times"]


def sample_offsets(spec: StreamSpec, clock_rate: float = 1.0) -> F64:
    """Time of each marker's sample after its frame's time, session seconds.

    Parameters
    ----------
    spec : StreamSpec
        The stream; ``slot_period_s`` set for time-multiplexed devices.
    clock_rate : float
        Session seconds per device second (``1 + drift``), > 0.

    Returns
    -------
    ndarray, shape (M,)
        ``(k + 1/2) * slot * clock_rate`` for time-multiplexed streams, zeros otherwise.

    Raises
    ------
    SynchronisationError
        If ``clock_rate`` is not finite and positive.
    """
    if not (np.isfinite(clock_rate) and clock_rate > 0):
        raise SynchronisationError(f"clock rate must be finite and positive, got {clock_rate}")
    return spec.sample_offsets_ns().astype(np.float64) / NS_PER_S * clock_rate


def sample_times(frame_times: npt.ArrayLike, spec: StreamSpec, clock_rate: float = 1.0) -> F64:
    """Session time of every sample of a stream.

    Parameters
    ----------
    frame_times : array_like, shape (F,)
        Session time of each frame (its first slot's start), s.
    spec : StreamSpec
        The stream.
    clock_rate : float
        Session seconds per device second, scales the slot offsets.

    Returns
    -------
    ndarray
        Shape (F, M) for time-multiplexed streams (``spec.slot_period_s`` set): frame
        time + (k + 1/2) * slot * clock_rate; shape (F,) otherwise (a copy of the frame
        times).

    Raises
    ------
    SynchronisationError
        If ``frame_times`` is not one-dimensional or not finite.

    Examples
    --------
    >>> import numpy as np
    >>> from spotlab.core import StreamSpec
    >>> spec = StreamSpec("s", "image2d", 4, 3, 75.0, 1e6, slot_period_s=100e-6)
    >>> sample_times(np.array([0.0, 0.01]), spec) * 1e6
    array([[   50.,   150.,   250.],
           [10050., 10150., 10250.]])
    """
    t = np.array(frame_times, dtype=np.float64)
    if t.ndim != 1 or not np.all(np.isfinite(t)):
        raise SynchronisationError(f"frame times must be finite, shape (F,), got shape {t.shape}")
    if spec.slot_period_s is None:
        return t
    return t[:, None] + sample_offsets(spec, clock_rate)[None, :]
