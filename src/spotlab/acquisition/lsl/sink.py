"""A session sink that publishes device streams as LSL outlets."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence

import numpy as np
import numpy.typing as npt

from spotlab.acquisition.interfaces import Device, SinkBase
from spotlab.acquisition.lsl.clock import LslClock
from spotlab.acquisition.lsl.outlet import LslOutlet
from spotlab.core.errors import ConfigurationError
from spotlab.core.frames import FrameBlock

#: ``time_of(stream, block)``: session time in s of each frame of a block, shape (F,).
TimeOf = Callable[[str, FrameBlock], npt.NDArray[np.float64]]


class LslOutletSink(SinkBase):
    """Publish chosen streams of a session on LSL, one outlet per stream.

    Outlets are created at ``on_start`` (when the devices' specs are known) and
    destroyed at ``stop``; nothing listens before or after. A ``point3d``
    stream with values x, y, z is published as 3-D markers (type ``MoCap``),
    any other as a raw stream (type ``MoCapRaw``); see :mod:`.metadata`.

    Parameters
    ----------
    streams : iterable of str, optional
        Streams to publish (default: every device of the session).
    time_of : callable, optional
        ``time_of(stream, block) -> (F,)`` session times of the frames, for
        example a clock model's ticks-to-session map. Default: host arrival
        time of each frame (``arrival_ns / 1e9``).
    prefix : str, optional
        Put before each stream name to make the LSL name (default ``"spotlab-"``).
    channel_format : {"float32", "double64"}
        Sample format on the wire (default float32).
    clock : LslClock, optional
        Session-time to LSL-time map shared by the outlets (default: measured
        at ``on_start``).
    name : str, optional
        Sink name in the session's statistics (default ``"lsl"``).
    """

    def __init__(
        self,
        streams: Iterable[str] | None = None,
        *,
        time_of: TimeOf | None = None,
        prefix: str = "spotlab-",
        channel_format: str = "float32",
        clock: LslClock | None = None,
        name: str = "lsl",
    ) -> None:
        self.streams = None if streams is None else list(streams)
        self.time_of = time_of
        self.prefix = prefix
        self.channel_format = channel_format
        self.clock = clock
        self.name = name
        self.outlets: dict[str, LslOutlet] = {}

    def on_start(self, devices: Sequence[Device]) -> None:
        """Create an outlet per chosen device.

        Raises
        ------
        ConfigurationError
            If a chosen stream is not a device of the session, or pylsl is missing.
        """
        names = [d.name for d in devices]
        wanted = names if self.streams is None else self.streams
        missing = sorted(set(wanted) - set(names))
        if missing:
            raise ConfigurationError(
                f"LSL outlets asked for streams that are not in the session: {missing}; "
                f"the session has {names}"
            )
        clock = self.clock if self.clock is not None else LslClock.measure()
        try:
            for device in devices:
                if device.name in wanted:
                    self.outlets[device.name] = LslOutlet(
                        device.spec,
                        name=self.prefix + device.name,
                        channel_format=self.channel_format,
                        clock=clock,
                    )
        except BaseException:
            self.stop()
            raise

    def on_block(self, stream: str, block: FrameBlock) -> None:
        """Push the block's frames to the stream's outlet (if it has one)."""
        outlet = self.outlets.get(stream)
        if outlet is None:
            return
        times = None if self.time_of is None else self.time_of(stream, block)
        outlet.push_block(block, times)

    def stop(self) -> None:
        """Destroy every outlet."""
        for outlet in self.outlets.values():
            outlet.close()
        self.outlets.clear()
