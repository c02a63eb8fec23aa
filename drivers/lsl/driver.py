"""An LSL stream as a spotlab device: a stream from another program or host joins a session."""

from __future__ import annotations

import os
import time
from typing import Any

import numpy as np

from spotlab.acquisition.lsl import LslClock, spec_from_info
from spotlab.acquisition.lsl._pylsl import pylsl_module
from spotlab.core.errors import ConfigurationError, DeviceDisconnected, DeviceError, DeviceNotFound
from spotlab.core.frames import F64, FrameBlock
from spotlab.core.streams import StreamSpec
from spotlab.drivers.base import Driver
from spotlab.drivers.lsl.wire import MAGIC, LslChunkDecoder, encode_chunk

#: Properties a port may name (``PROP=VALUE``); a bare port is a stream name.
PROPERTIES = ("name", "type", "source_id", "hostname", "uid", "session_id")
#: Largest number of samples taken in one ``recv``.
MAX_CHUNK = 4096


def parse_port(port: str) -> tuple[str, str]:
    """``(property, value)`` of a port: ``NAME``, ``name=NAME``, ``type=MoCap``, ...

    Raises
    ------
    ConfigurationError
        If the port is empty or names an unknown property.
    """
    prop, sep, value = port.partition("=")
    if not sep:
        prop, value = "name", port
    if not value or prop not in PROPERTIES:
        raise ConfigurationError(
            f"an LSL port is NAME or PROP=VALUE with PROP one of {PROPERTIES}, got {port!r}"
        )
    return prop, value


class LslInletDriver(Driver):
    """An LSL inlet as a device: resolves a stream, pulls its samples as frame blocks.

    One LSL sample is one frame. ``seq`` counts the samples received since
    start; ``ticks`` are the sender's LSL timestamps in ns (``tick_hz`` = 1e9,
    no post-processing); ``arrival_ns`` is the host monotonic time when the
    chunk was pulled. The inlet's clock offset to the sender
    (``time_correction``, liblsl's NTP-style estimate) is read at start and at
    every pull, journalled with each chunk, and applied by :meth:`session_times`.

    Parameters
    ----------
    port : str
        The stream to resolve: ``NAME`` or ``PROP=VALUE`` (``type=MoCap``,
        ``source_id=...``, see :data:`PROPERTIES`).
    name : str, optional
        Stream name in the session (default ``"lsl"``).
    resolve_timeout : float, optional
        Seconds to look for the stream (default 2).
    time_correction_timeout : float, optional
        Seconds to wait for the first clock-offset estimate (default 2).
    max_buflen_s : float, optional
        Seconds liblsl buffers when ``recv`` is not called (default 360).
    clock : LslClock, optional
        Session-time to LSL-time map of this host (default: measured at start).

    Raises
    ------
    ConfigurationError
        If the port or a timeout is invalid.
    """

    family = "lsl"

    def __init__(
        self,
        port: str | os.PathLike[str],
        *,
        name: str | None = None,
        resolve_timeout: float = 2.0,
        time_correction_timeout: float = 2.0,
        max_buflen_s: float = 360.0,
        clock: LslClock | None = None,
    ) -> None:
        super().__init__(port, name=name)
        self.prop, self.value = parse_port(self.port)
        for label, v in (
            ("resolve_timeout", resolve_timeout),
            ("time_correction_timeout", time_correction_timeout),
            ("max_buflen_s", max_buflen_s),
        ):
            if not v > 0:
                raise ConfigurationError(f"{label} must be positive, got {v}")
        self.resolve_timeout = resolve_timeout
        self.time_correction_timeout = time_correction_timeout
        self.max_buflen_s = max_buflen_s
        self.clock = clock
        self._inlet: Any = None
        self._spec: StreamSpec | None = None
        self._decoder: LslChunkDecoder | None = None
        self._source: dict[str, Any] = {}
        self._streaming = False
        self._tc = float("nan")

    # -- description ---------------------------------------------------------------
    @property
    def spec(self) -> StreamSpec:
        """The stream, read from the sender's description at start."""
        if self._spec is None:
            raise DeviceError(f"{self.name}: the LSL stream is known only after start()")
        return self._spec

    @property
    def time_correction_s(self) -> float:
        """Latest offset (s) to add to the sender's timestamps to get this host's LSL clock."""
        return self._tc

    def session_times(self, block: FrameBlock) -> F64:
        """Session time (s) of each frame: sender stamp + time correction, on the host clock.

        Returns
        -------
        ndarray of float64, shape (F,)
        """
        if self.clock is None:
            raise DeviceError(f"{self.name}: session times are known only after start()")
        return self.clock.to_session(block.ticks / 1e9 + self.time_correction_s)

    def metadata(self) -> dict[str, Any]:
        """Spec, the sender's LSL identity, the clock offsets and the journal layout."""
        return {
            **super().metadata(),
            "lsl": dict(self._source),
            "time_correction_s": self.time_correction_s,
            "lsl_clock_offset_s": None if self.clock is None else self.clock.offset_s,
            "layout": MAGIC.decode(),
            "decoder": "spotlab.drivers.lsl:decoder_from_metadata",
        }

    # -- life cycle ----------------------------------------------------------------
    def _start(self) -> None:
        pylsl = pylsl_module()
        if self._inlet is None:
            found = pylsl.resolve_byprop(self.prop, self.value, 1, self.resolve_timeout)
            uids = {info.uid() for info in found}
            if not found:
                raise DeviceNotFound(
                    f"no LSL stream with {self.prop}={self.value!r} found within "
                    f"{self.resolve_timeout:g} s (is the sender running and reachable? "
                    "see docs/lsl.md on KnownPeers)"
                )
            if len(uids) > 1:
                ids = sorted(info.source_id() or info.uid() for info in found)
                raise DeviceNotFound(
                    f"{len(uids)} LSL streams match {self.prop}={self.value!r} ({ids}); "
                    "name one, for example with source_id=..."
                )
            inlet = pylsl.StreamInlet(found[0], max(1, round(self.max_buflen_s)))
            try:
                info = inlet.info(self.resolve_timeout)
                spec = spec_from_info(info, self.name)
            except BaseException:
                del inlet
                raise
            self._inlet = inlet
            self._spec = spec
            self._decoder = LslChunkDecoder(spec, self.stats)
            self._source = {
                k: getattr(info, k)() for k in ("name", "type", "source_id", "uid", "hostname")
            }
            self._source["nominal_srate"] = float(info.nominal_srate())
            self._source["channel_count"] = int(info.channel_count())
            self._tap_event("open", port=self.port, uid=self._source["uid"])
        if self.clock is None:
            self.clock = LslClock.measure()
        try:
            self._inlet.open_stream(self.resolve_timeout)
            tc = float(self._inlet.time_correction(self.time_correction_timeout))
        except (TimeoutError, pylsl.LostError) as exc:
            raise DeviceNotFound(
                f"LSL stream {self.value!r} did not answer within "
                f"{max(self.resolve_timeout, self.time_correction_timeout):g} s: {exc}"
            ) from exc
        self._tc = tc
        self._streaming = True
        self._tap_event("started", time_correction_s=tc, lsl_clock_offset_s=self.clock.offset_s)

    def _stop(self) -> None:
        self._streaming = False
        if self._inlet is not None:
            self._inlet.close_stream()
            self._tap_event("stopped")

    def _close(self) -> None:
        self._streaming = False
        if self._inlet is not None:
            self._inlet = None  # pylsl destroys the inlet when the last reference goes
            self._tap_event("close", port=self.port)

    # -- streaming -----------------------------------------------------------------
    def _recv_internal(self, timeout: float | None) -> FrameBlock | None:
        if not self._streaming or self._inlet is None or self._decoder is None:
            raise DeviceError(f"{self.name} ({self.port}) is not streaming: call start() first")
        pylsl = pylsl_module()
        try:
            # Wait for one sample, then take what else is there: no added latency.
            first, t0 = self._inlet.pull_sample(1e6 if timeout is None else timeout)
            if t0 is None:
                return None
            rest, ts = self._inlet.pull_chunk(0.0, MAX_CHUNK - 1)
        except pylsl.LostError as exc:
            raise DeviceDisconnected(f"LSL stream {self.value!r} was lost: {exc}") from exc
        arrival_ns = time.monotonic_ns()
        try:
            self._tc = float(self._inlet.time_correction(0.0))
        except TimeoutError:
            pass  # no new estimate yet: keep the last
        values = np.asarray([first, *rest], dtype=np.float64).reshape(1 + len(ts), -1)
        record = encode_chunk([t0, *ts], values, self._tc)
        self.stats.bytes += len(record)
        self._tap_rx(record, arrival_ns)
        return self._decoder.feed(record, arrival_ns)
