"""Clock models of the streams of an XDF file (Lab Streaming Layer recordings).

An XDF stream carries, besides its samples, clock-offset measurements made by the
recorder: at remote (stream) clock time ``clock_times[i]`` the recorder's clock read
``clock_times[i] + clock_values[i]``. The stream's clock is mapped to the recorder's
by fitting our :class:`~spotlab.acquisition.clocks.model.ClockModel` to those pairs,
with the stream's seconds as ticks of 1 ns (``tick_hz = 1e9``): a reset of the stream's
clock (ticks going backwards) becomes a new epoch and a "reset" event.

pyxdf (``load_xdf(..., synchronize_clocks=True)``) does the same job differently: it
cuts segments where the clock times go backwards or both times and values jump by
more than thresholds (``_detect_clock_resets``), fits each by a Huber regression
solved by ADMM with the residuals scaled by 1e-4 s, and assigns each sample to the
segment whose clock times it is nearest; here segments come from the changepoint test
of :mod:`~spotlab.acquisition.clocks.steps`, each is fitted by Huber re-weighted least
squares (threshold 1.5 robust SDs), and samples fall in epochs where their own time
stamps go backwards.

pyxdf is an optional dependency (extra ``lsl``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from spotlab.acquisition.clocks.model import ClockModel, ClockSegment
from spotlab.acquisition.clocks.pairs import MIN_PAIRS, fit_pairs
from spotlab.core.errors import ClockError, RecordingError

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

#: Ticks per second of an XDF stream clock seen as a counter.
XDF_TICK_HZ = 1e9


def seconds_to_ticks(seconds: npt.ArrayLike) -> I64:
    """Stream seconds as int64 ns ticks (exact for |t| < 2**53 ns, about 104 days)."""
    return np.asarray(np.round(np.asarray(seconds, dtype=np.float64) * XDF_TICK_HZ), np.int64)


@dataclass(frozen=True)
class XdfStreamClock:
    """One XDF stream, its clock model and its time stamps mapped by it.

    Attributes
    ----------
    name : str
        Stream name from the header.
    stream_id : int
        Stream id in the file.
    time_stamps : ndarray of float64, shape (N,)
        Recorded time stamps, stream clock, s.
    model : ClockModel or None
        Fitted to the clock offsets (None when the stream has none).
    synchronized : ndarray of float64, shape (N,)
        Time stamps on the recorder's clock, s (the recorded ones when no model).
    """

    name: str
    stream_id: int
    time_stamps: F64
    model: ClockModel | None
    synchronized: F64


def fit_xdf_offsets(
    clock_times: npt.ArrayLike,
    clock_values: npt.ArrayLike,
    *,
    k: float = 8.0,
    min_step_s: float = 1e-3,
) -> ClockModel:
    """Clock model of one stream from its XDF clock offsets.

    Parameters
    ----------
    clock_times : array_like, shape (M,)
        Stream-clock times of the offset measurements, s.
    clock_values : array_like, shape (M,)
        Offsets (recorder clock minus stream clock), s.
    k : float
        Step threshold in jitters.
    min_step_s : float
        Smallest step reported, s: LSL offsets wander by tens of microseconds (they
        are probe exchanges over a network stack), which is drift, not a step.

    Returns
    -------
    ClockModel
        ``tick_hz = 1e9`` (ns), ``method="xdf"``; clock resets as "reset" events. One
        or two measurements give one segment through them (rate 1 for one, as pyxdf).

    Raises
    ------
    ClockError
        No measurement, fewer than 3 after a reset, NaN.
    """
    times = np.asarray(clock_times, dtype=np.float64)
    values = np.asarray(clock_values, dtype=np.float64)
    if times.shape != values.shape:
        raise ClockError(f"clock times and values differ in shape: {times.shape}, {values.shape}")
    if not (np.all(np.isfinite(times)) and np.all(np.isfinite(values))):
        raise ClockError("XDF clock offsets hold NaN or infinite values")
    if times.size == 0:
        raise ClockError("the stream has no clock offsets")
    if times.size < MIN_PAIRS:
        ticks = seconds_to_ticks(times)
        rate = 1.0 / XDF_TICK_HZ
        if times.size == 2 and ticks[1] > ticks[0]:
            rate = float((times[1] + values[1] - times[0] - values[0]) / (ticks[1] - ticks[0]))
        seg = ClockSegment(
            epoch=0,
            tick_start=int(ticks.min()),
            tick_end=int(ticks.max()),
            origin=int(ticks[0]),
            offset_s=float(times[0] + values[0]),
            rate=rate,
            n=times.size,
        )
        return ClockModel(XDF_TICK_HZ, [seg], method="xdf")
    return fit_pairs(
        seconds_to_ticks(times),
        times + values,
        XDF_TICK_HZ,
        allow_resets=True,
        k=k,
        window=8,
        min_step_s=min_step_s,
        increasing_reference=False,
        wrap_bits=(),
        method="xdf",
    )


def load_xdf_clocks(path: str | Path, *, k: float = 8.0) -> list[XdfStreamClock]:
    """Read an XDF file with pyxdf and fit a clock model to each stream's offsets.

    Parameters
    ----------
    path : str or Path
        XDF file.
    k : float
        Step threshold in jitters.

    Returns
    -------
    list of XdfStreamClock
        One per stream, in file order.

    Raises
    ------
    RecordingError
        pyxdf missing, or the file cannot be read.
    ClockError
        Clock offsets that cannot be fitted.
    """
    try:
        import pyxdf
    except ImportError as exc:
        raise RecordingError("reading XDF needs pyxdf: pip install 'spotlab[lsl]'") from exc
    path = Path(path)
    try:
        with path.open("rb") as fh:
            magic = fh.read(4)
    except OSError as exc:
        raise RecordingError(f"cannot read XDF file {path}: {exc}") from exc
    if magic != b"XDF:":
        # checked here: pyxdf leaves the file open when it refuses one
        raise RecordingError(f"cannot read XDF file {path}: it does not start with 'XDF:'")
    try:
        streams, _ = pyxdf.load_xdf(str(path), synchronize_clocks=False, dejitter_timestamps=False)
    except (OSError, ValueError, KeyError) as exc:
        raise RecordingError(f"cannot read XDF file {path}: {exc}") from exc
    out = []
    for stream in streams:
        out.append(_stream_clock(stream, k))
    return out


def _stream_clock(stream: dict[str, Any], k: float) -> XdfStreamClock:
    info = stream["info"]
    name = str(info["name"][0]) if info.get("name") else ""
    stream_id = int(info.get("stream_id", -1))
    stamps = np.asarray(stream["time_stamps"], dtype=np.float64).reshape(-1)
    times = np.asarray(stream.get("clock_times", []), dtype=np.float64)
    values = np.asarray(stream.get("clock_values", []), dtype=np.float64)
    if times.size == 0:
        return XdfStreamClock(name, stream_id, stamps, None, stamps.copy())
    model = fit_xdf_offsets(times, values, k=k)
    if stamps.size == 0:
        return XdfStreamClock(name, stream_id, stamps, model, stamps.copy())
    ticks = seconds_to_ticks(stamps)
    epochs = model.epochs_of(ticks)
    if int(epochs[-1]) > model.segments[-1].epoch:
        raise ClockError(
            f"stream {name!r}: its time stamps go backwards more often than its clock resets"
        )
    return XdfStreamClock(name, stream_id, stamps, model, model(ticks, epochs))
