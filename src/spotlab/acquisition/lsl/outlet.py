"""LSL outlets of spotlab streams: raw frames and 3-D markers, stamped in session time."""

from __future__ import annotations

from collections.abc import Sequence
from types import TracebackType
from typing import Any

import numpy as np
import numpy.typing as npt

from spotlab.acquisition.lsl.clock import LslClock
from spotlab.acquisition.lsl.metadata import stream_info
from spotlab.core.errors import ConfigurationError
from spotlab.core.frames import FrameBlock
from spotlab.core.streams import StreamSpec

F64 = npt.NDArray[np.float64]


class LslOutlet:
    """One LSL outlet publishing one spotlab stream: one LSL sample per frame.

    Creating it opens liblsl's listening ports (TCP and UDP, 16572 and up): do
    so only when the user asked for LSL.

    Parameters
    ----------
    spec : StreamSpec
        The stream; a sample is the frame's ``data`` flattened (M x S x V channels).
    name : str, optional
        LSL stream name (default ``spec.name``).
    stream_type : str, optional
        LSL content type (default ``MoCap`` for 3-D positions, ``MoCapRaw`` otherwise).
    source_id : str, optional
        LSL source id (default ``"spotlab:" + name``): inlets recover across restarts.
    channel_format : {"float32", "double64"}
        Sample format on the wire (default float32).
    clock : LslClock, optional
        Session-time to LSL-time map (default: measured now, session time =
        host monotonic seconds).
    max_buffered_s : float, optional
        Seconds of samples the outlet keeps for slow inlets (default 360).

    Raises
    ------
    ConfigurationError
        If pylsl is missing, the stream has no channels or the format is unknown.
    """

    def __init__(
        self,
        spec: StreamSpec,
        *,
        name: str | None = None,
        stream_type: str | None = None,
        source_id: str | None = None,
        channel_format: str = "float32",
        clock: LslClock | None = None,
        max_buffered_s: float = 360.0,
    ) -> None:
        from spotlab.acquisition.lsl._pylsl import pylsl_module

        if not max_buffered_s > 0:
            raise ConfigurationError(f"max_buffered_s must be positive, got {max_buffered_s}")
        pylsl = pylsl_module()
        self.spec = spec
        self.name = name or spec.name
        self.clock = clock if clock is not None else LslClock.measure()
        info = stream_info(
            spec,
            name=self.name,
            stream_type=stream_type,
            source_id=source_id if source_id is not None else f"spotlab:{self.name}",
            channel_format=channel_format,
        )
        self.n_channels = int(info.channel_count())
        self.stream_type = str(info.type())
        self._dtype = np.float32 if channel_format == "float32" else np.float64
        self._outlet: Any = pylsl.StreamOutlet(info, 0, max(1, round(max_buffered_s)))
        self.samples_pushed = 0

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` was called."""
        return self._outlet is None

    def have_consumers(self) -> bool:
        """Whether an inlet is connected."""
        return self._outlet is not None and bool(self._outlet.have_consumers())

    def push(self, time_s: npt.ArrayLike, values: npt.ArrayLike) -> None:
        """Publish frames with their session times.

        Parameters
        ----------
        time_s : array_like of float, shape (F,)
            Session time of each frame in s (see :class:`LslClock`).
        values : array_like of float, shape (F, C) or (F, ...) with C values per frame
            One row per frame; NaN passes through (float formats carry it).

        Raises
        ------
        ConfigurationError
            If the outlet is closed, the shapes disagree, or a time is not finite.
        """
        if self._outlet is None:
            raise ConfigurationError(f"LSL outlet {self.name!r} is closed")
        t = np.atleast_1d(np.asarray(time_s, dtype=np.float64))
        x = np.asarray(values, dtype=np.float64)
        if t.ndim != 1 or x.ndim < 1 or x.shape[0] != t.shape[0]:
            raise ConfigurationError(
                f"LSL outlet {self.name!r}: {t.shape} times for values of shape {x.shape}"
            )
        if not len(t):
            return
        x = x.reshape(t.shape[0], -1)
        if x.shape[1] != self.n_channels:
            raise ConfigurationError(
                f"LSL outlet {self.name!r} has {self.n_channels} channels, got {x.shape[1]}"
            )
        if not np.isfinite(t).all():
            raise ConfigurationError(f"LSL outlet {self.name!r}: a frame time is NaN or infinite")
        stamps = self.clock.to_lsl(t)
        self._outlet.push_chunk(np.ascontiguousarray(x, dtype=self._dtype), stamps.tolist())
        self.samples_pushed += len(t)

    def push_block(self, block: FrameBlock, time_s: npt.ArrayLike | None = None) -> None:
        """Publish a block of frames.

        Parameters
        ----------
        block : FrameBlock
            Frames of this outlet's stream, data shape (F, M, S, V).
        time_s : array_like of float, shape (F,), optional
            Session times of the frames (from the stream's clock model). Without
            them the frames' host arrival times are used
            (``arrival_ns / 1e9``, the session clock at the arrival of each
            frame's last byte): later than the sample by the link latency.
        """
        t = block.arrival_ns / 1e9 if time_s is None else time_s
        self.push(t, block.data)

    def close(self) -> None:
        """Destroy the outlet (its ports close). Safe to call twice."""
        self._outlet = None  # pylsl destroys the outlet when the last reference goes

    def __enter__(self) -> LslOutlet:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def marker_spec(
    n_markers: int, rate_hz: float, name: str = "spotlab-markers", labels: Sequence[str] = ()
) -> StreamSpec:
    """The spec of a 3-D marker stream: ``point3d``, one sensor, x, y, z in mm.

    Raises
    ------
    ConfigurationError
        If ``n_markers`` < 1 or the labels do not match it.
    """
    if n_markers < 1:
        raise ConfigurationError(f"a marker stream needs at least one marker, got {n_markers}")
    if labels and len(labels) != n_markers:
        raise ConfigurationError(f"{len(labels)} marker labels for {n_markers} markers")
    meta: dict[str, Any] = {"marker_labels": list(labels)} if labels else {}
    return StreamSpec(
        name=name,
        kind="point3d",
        n_sensors=1,
        n_markers=n_markers,
        rate_hz=rate_hz,
        tick_hz=1e9,
        values=("x", "y", "z"),
        units=("mm", "mm", "mm"),
        metadata=meta,
    )


class MarkerOutlet(LslOutlet):
    """LSL outlet of 3-D marker positions (type ``MoCap``, channels ``<marker>_X/Y/Z`` in mm).

    Parameters
    ----------
    n_markers : int
        Markers per frame (M); 3 M channels.
    rate_hz : float
        Nominal frame rate in Hz.
    name : str, optional
        LSL stream name (default ``spotlab-markers``).
    labels : sequence of str, optional
        Marker names (default ``m0``, ``m1``, ...).
    **kwargs
        ``source_id``, ``channel_format``, ``clock``, ``max_buffered_s`` as for
        :class:`LslOutlet`.
    """

    def __init__(
        self,
        n_markers: int,
        rate_hz: float,
        *,
        name: str = "spotlab-markers",
        labels: Sequence[str] = (),
        **kwargs: Any,
    ) -> None:
        super().__init__(marker_spec(n_markers, rate_hz, name, labels), **kwargs)

    def push_markers(self, time_s: npt.ArrayLike, X: npt.ArrayLike) -> None:
        """Publish 3-D positions.

        Parameters
        ----------
        time_s : float or array_like of float, shape (F,)
            Session time of the frame(s) in s.
        X : array_like of float, shape (M, 3) or (F, M, 3)
            Positions in mm; NaN for a marker not seen.

        Raises
        ------
        ConfigurationError
            If the shapes do not match the outlet's markers or a time is not finite.
        """
        x = np.asarray(X, dtype=np.float64)
        m = self.spec.n_markers
        if x.shape == (m, 3):
            x = x[None]
        if x.ndim != 3 or x.shape[1:] != (m, 3):
            raise ConfigurationError(
                f"push_markers takes positions of shape ({m}, 3) or (F, {m}, 3), got {x.shape}"
            )
        self.push(np.atleast_1d(np.asarray(time_s, dtype=np.float64)), x)
