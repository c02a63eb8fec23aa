"""Reading a running MCS-1 stream: frames kept, replies picked out, a dead link spotted.

:class:`StreamReader` reads the port while the device streams and feeds what
arrives to the family's decoder. Decoded frames wait in a stash until ``recv``
takes them. A reply comes in an event frame, queued behind the data frames
already in the device's FIFO (:meth:`StreamReader.await_reply`), and a reply
nobody asked for is logged (:meth:`StreamReader.log_events`).
:meth:`StreamReader.fault` tells when the link counts as gone: no valid frame
for ``max(0.5 s, 20 frame periods)`` while the line is silent or carries bytes
that hold no frame (selspot.md §7).

:class:`~spotlab.drivers.mcs1.driver.Mcs1Driver` owns one reader. It passes the
decoder to each call, because it swaps the decoder when it adopts the device's
own configuration (``CONF:``).
"""

from __future__ import annotations

import logging
import time

from spotlab.core.errors import DeviceTimeout, ProtocolError
from spotlab.core.frames import FrameBlock
from spotlab.drivers.mcs1.commands import Reply, parse_reply
from spotlab.drivers.mcs1.contracts import Mcs1Config, Mcs1Decoder
from spotlab.drivers.mcs1.link import SerialLink

log = logging.getLogger(__name__)

#: Silence (no byte at all) after which a streaming device counts as gone (s): a device
#: at 50 Hz and up sends every 20 ms; a busy host may not read for a few hundred ms.
SILENCE_S = 0.5
#: Bytes (at least) that may arrive without a valid frame before the link counts as garbage
#: (one longest MCS-1 frame).
MIN_FRAME_WINDOW = 1 << 16
#: A reply behind data frames is awaited at most this many reply timeouts in all.
REPLY_BEHIND_DATA = 5


class StreamReader:
    """Reads of a streaming link, decoded; frames kept for ``recv``, replies, faults.

    Parameters
    ----------
    link : SerialLink
        The device's port (opened and closed by the driver).
    reply_timeout : float
        Seconds to wait for a reply after the last byte received.
    config : Mcs1Config
        The configuration whose frame rate, frame size and baud rate set the
        silence and flush thresholds (:meth:`retime`).
    """

    def __init__(self, link: SerialLink, reply_timeout: float, config: Mcs1Config) -> None:
        self._link = link
        self.reply_timeout = reply_timeout
        self._stash: list[FrameBlock] = []
        self.retime(config)

    def retime(self, config: Mcs1Config) -> None:
        """Silence and flush thresholds of ``config``'s frame rate and size."""
        period_s = 1.0 / config.rate_hz
        self._silence_ns = int(max(SILENCE_S, 20 * period_s) * 1e9)
        send_s = config.frame_bytes * 10 / config.baud
        self._idle_flush_ns = int(max(0.05, 3 * send_s) * 1e9)
        self._last_frame_ns = 0
        self._last_rx_ns = 0
        # Bytes read since the last valid frame; more than this many means garbage
        # (a device at another baud rate), not a host that fell behind.
        self._rx_since_frame = 0
        self._garbage_bytes = 2 * max(config.frame_bytes, MIN_FRAME_WINDOW)

    def started(self, now_ns: int) -> None:
        """The stream (re)started at ``now_ns`` (monotonic ns): silence counts from there."""
        self._last_frame_ns = self._last_rx_ns = now_ns

    def pop(self) -> FrameBlock | None:
        """The oldest frame block kept, or None when none is."""
        return self._stash.pop(0) if self._stash else None

    def drain(self) -> list[FrameBlock]:
        """Every frame block kept, handed over once."""
        blocks, self._stash = self._stash, []
        return blocks

    def read(
        self, decoder: Mcs1Decoder, timeout: float | None, *, flush_idle: bool = False
    ) -> FrameBlock | None:
        """One read, decoded; frames go to the stash.

        With ``flush_idle`` (waiting for a reply), a frame that stopped arriving is
        flushed as truncated so that the reply behind it is not held back. While
        streaming it is not: a device (or a simulator on a busy host) that pauses
        within a frame sends the rest later, and a frame that really was truncated
        is resolved by the frames after it (CRC failure, then resynchronisation).
        """
        data, t_ns = self._link.read(None if timeout is None else max(0.0, timeout))
        block = decoder.feed(data, t_ns) if data else None
        if data:
            self._last_rx_ns = t_ns
            self._rx_since_frame += len(data)
        elif flush_idle and decoder.buffered and t_ns - self._last_rx_ns > self._idle_flush_ns:
            block = decoder.flush()
        if block is not None and len(block):
            self._last_frame_ns = t_ns
            self._rx_since_frame = 0
            self._stash.append(block)
        return block

    def await_reply(self, decoder: Mcs1Decoder, command: str, okay_only: bool = False) -> Reply:
        """Decode frames until the reply's event frame; keep the frames for ``recv``.

        The reply queues behind the data frames already in the device's FIFO: while
        frames keep arriving the device is alive, so the wait lasts ``reply_timeout``
        after the last byte (at most :data:`REPLY_BEHIND_DATA` times ``reply_timeout``).
        With ``okay_only``, replies other than ``OKAY`` (and not errors) are passed over.

        Raises
        ------
        DeviceError
            With the device's code when it answers ``ERRORxx``.
        DeviceTimeout
            If no reply comes in time.
        """
        start = time.monotonic()
        deadline = start + self.reply_timeout
        latest = start + REPLY_BEHIND_DATA * self.reply_timeout
        while True:
            if self.read(decoder, deadline - time.monotonic(), flush_idle=True) is not None:
                deadline = min(latest, time.monotonic() + self.reply_timeout)
            for event in decoder.take_events():
                try:
                    reply = parse_reply(event.payload)
                except ProtocolError as exc:
                    log.warning(
                        "%s: while waiting for the reply to %s: %s", self._link.url, command, exc
                    )
                    continue
                reply.raise_for_error(command)
                if reply.kind == "okay" or not okay_only:
                    return reply
            if time.monotonic() >= deadline:
                raise DeviceTimeout(
                    f"no reply to {command} from {self._link.url} within {self.reply_timeout:g} s"
                )

    def log_events(self, decoder: Mcs1Decoder) -> None:
        """Replies that arrive while streaming (none are expected): log them."""
        for event in decoder.take_events():
            try:
                reply = parse_reply(event.payload)
            except ProtocolError as exc:
                log.warning("%s: unexpected event frame: %s", self._link.url, exc)
                continue
            level = logging.WARNING if reply.kind in ("error", "warn") else logging.INFO
            log.log(level, "%s: device sent %r while streaming", self._link.url, reply.text)

    def fault(self, now_ns: int) -> str | None:
        """Why the link counts as gone at ``now_ns`` (monotonic ns), or None if it does not.

        Gone: no valid frame for the silence threshold, and either no byte at all
        for as long, more bytes than one frame window without a frame, or no
        frame for four thresholds. A host that was itself held up (a busy machine)
        finds the frames waiting for it: that is no fault.
        """
        since_frame = now_ns - self._last_frame_ns
        if since_frame > self._silence_ns and (
            now_ns - self._last_rx_ns > self._silence_ns
            or self._rx_since_frame > self._garbage_bytes
            or since_frame > 4 * self._silence_ns
        ):
            return f"no valid frame for {since_frame / 1e9:.2f} s"
        return None
