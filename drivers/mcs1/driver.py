"""The state machine every MCS-1 family shares: bring-up, streaming, recovery, stop.

:class:`Mcs1Driver` opens the port at 9600 baud, resets the device (BREAK,
else ``RESET:``) and waits for its banner, moves to the streaming baud rate
(``COMM``, then ``VER:0`` within 1 s, else reset and try once more), lets the
family check the device's ``VER:0`` reply, sends the configuration commands
(every reply checked) and starts the stream. :meth:`recv` decodes what the port
holds (through a :class:`~spotlab.drivers.mcs1.reader.StreamReader`).

While streaming the driver watches for the faults of selspot.md §7 and recovers
by itself: a port that went away, the device's reset banner, or no valid frame
for ``max(0.5 s, 20 frame periods)``. It then reopens the port as often as
needed, resets, renegotiates, reconfigures and restarts, marks the discontinuity
in the decoder, counts a reconnect and a gap, and tells the taps
(``disconnected`` / ``device_reset``, then ``reconnected``).

A family provides its configuration and decoder (``contracts``), ``family_code``
and the hooks; :class:`~spotlab.drivers.mcs1.family.FamilyDriver` writes most
of them once (``drivers/selspot``, ``drivers/timer``, ``drivers/centroid``).
"""

from __future__ import annotations

import logging
import time
from abc import abstractmethod
from collections.abc import Mapping
from typing import Any, ClassVar

from spotlab.core.errors import (
    ConfigurationError,
    DeviceDisconnected,
    DeviceError,
    DeviceTimeout,
    ProtocolError,
)
from spotlab.core.frames import FrameBlock
from spotlab.core.wire import LinkEventKind
from spotlab.drivers.base import Driver
from spotlab.drivers.mcs1.commands import (
    BAUD_CODES,
    RESET_BAUD,
    DeviceConfigurationError,
    Reply,
    encode_command,
    parse_conf,
)
from spotlab.drivers.mcs1.contracts import Mcs1Config, Mcs1Decoder
from spotlab.drivers.mcs1.link import SerialLink
from spotlab.drivers.mcs1.reader import StreamReader
from spotlab.drivers.mcs1.session import CommandChannel

#: Seconds between the last ``RESET:`` at the streaming rate and the move to 9600 baud.
STOP_RESET_PAUSE_S = 0.05

log = logging.getLogger(__name__)

#: Pause between two reconnection attempts (s).
RETRY_INTERVAL = 0.05
#: Longest wait for the banner while recovering (s): a returning device answers in ms.
RECOVERY_RESET_WAIT = 0.5
#: Faults after which the driver tries to recover instead of raising.
_TRANSIENT = (DeviceTimeout, DeviceDisconnected, ProtocolError)


class Mcs1Driver(Driver):
    """Driver of an MCS-1 device; a family subclass fills in the hooks.

    Parameters
    ----------
    port : str or path-like
        Device path or pyserial URL.
    config : Mcs1Config
        The family's checked configuration.
    decoder : Mcs1Decoder
        The family's decoder, built on ``self.stats`` (the subclass builds it
        after ``Driver.__init__`` and passes it here).
    name : str, optional
        Stream name; the family name by default.
    reply_timeout : float
        Seconds to wait for each reply and for the reset banner.
    reconnect_timeout : float or None
        Give up recovering after this many seconds (``DeviceDisconnected``);
        ``None`` keeps trying for as long as ``recv`` is called.
    """

    family_code: ClassVar[str] = ""
    #: ``module:function`` that rebuilds the family's decoder from :meth:`metadata`.
    decoder_path: ClassVar[str] = ""
    #: Baud rate -> ``COMM`` code the family's devices accept.
    baud_codes: ClassVar[Mapping[int, int]] = BAUD_CODES
    #: The family's configuration (set by the subclass before :meth:`_setup`).
    config: Mcs1Config
    _decoder: Mcs1Decoder

    def metadata(self) -> dict[str, Any]:
        """Everything a recording needs to decode this stream again.

        The family's ``decoder_from_metadata(driver.metadata())`` rebuilds the decoder.
        """
        device = getattr(self, "device", None)  # what the device said of itself (VER:0)
        return {
            **super().metadata(),
            "config": self.config.to_dict(),
            "device": None if device is None else device.to_dict(),
            "protocol": {"transport": "MCS-1", "family_code": self.family_code, "version": 1},
            "decoder": self.decoder_path,
        }

    def _setup(
        self,
        config: Mcs1Config,
        decoder: Mcs1Decoder,
        reply_timeout: float,
        reconnect_timeout: float | None,
    ) -> None:
        """Second half of ``__init__`` (after ``Driver.__init__`` and the family's own)."""
        if not reply_timeout > 0:
            raise ConfigurationError(f"reply_timeout must be positive, got {reply_timeout}")
        self.reply_timeout = reply_timeout
        self.reconnect_timeout = reconnect_timeout
        self._decoder = decoder
        #: Whether the settings not given are still to be read from the device (``CONF:``).
        self._adopt_pending = bool(self._unasked())
        self._link = SerialLink(self.port, on_rx=self._tap_rx, on_tx=self._tap_tx)
        self._channel = CommandChannel(self._link, reply_timeout, self.stats)
        self._reader = StreamReader(self._link, reply_timeout, config)
        self._streaming = False
        self._recovering: str | None = None
        self._reconnect_asked: str | None = None
        self._outage_start = 0.0

    # -- settings the user did not give: the device's own (CONF:) ---------------------
    @abstractmethod
    def _unasked(self) -> list[str]:
        """Settings the user left to the device (``create`` keywords); none: no ``CONF:``."""

    @abstractmethod
    def _device_settings(self, fields: Mapping[str, str]) -> dict[str, Any]:
        """The family's ``create`` keywords from a ``CONF`` reply's fields."""

    @abstractmethod
    def _rebuild(self, device: Mapping[str, Any]) -> tuple[Mcs1Config, Mcs1Decoder]:
        """Configuration and decoder from the device's settings overlaid by the user's."""

    def _adopt_device_config(self) -> None:
        """Read the device's configuration (``CONF:``) and keep it for every setting the
        user did not give; once, at the first start (a reconnection sends the same).

        A device that does not know ``CONF:`` (``ERROR01``, or a bare ``OKAY``) gets the
        driver's defaults.
        """
        if not self._adopt_pending:
            return
        try:
            reply: Reply | None = self._channel.transact("CONF", data_prefix="CONF")
        except DeviceError as exc:
            if exc.code != 0x01:
                raise
            reply = None
        if reply is None or reply.kind != "data":  # ERROR01 (unknown verb), or a bare OKAY
            log.warning(
                "%s: the device does not report its configuration (CONF:); %s take the "
                "driver's defaults",
                self.port,
                ", ".join(self._unasked()),
            )
            self._adopt_pending = False
            return
        config, decoder = self._rebuild(self._device_settings(parse_conf(reply.text)))
        self.config, self._decoder = config, decoder
        self._reader.retime(config)
        self._adopt_pending = False

    @abstractmethod
    def _check_device(self, reply: Reply) -> None:
        """Parse the ``VER:0`` reply and keep it; ``ConfigurationError`` if the device cannot."""

    @abstractmethod
    def _describe_load(self) -> str:
        """What the configuration asks of the line, for the bandwidth message."""

    def request_reconnect(self, reason: str = "reconnect asked") -> None:
        """Ask a streaming driver to reconnect as after a lost port; safe from any thread.

        The reader's next :meth:`recv` closes the port and recovers as from a fault
        (``disconnected`` with ``reason``, the bring-up again, ``reconnected``): the
        stream, its counters and the recording's taps go on, only this device restarts.
        Ignored when the driver is not streaming.
        """
        self._reconnect_asked = reason

    @property
    def recovering(self) -> bool:
        """Whether the driver is reconnecting after a fault."""
        return self._recovering is not None

    # -- life cycle ----------------------------------------------------------------
    def _start(self) -> None:
        self._reconnect_asked = None
        try:
            if not self._link.is_open:
                self._link.open()
                self._tap_event("open", port=self.port)
            self._bring_up(self.reply_timeout)
        except BaseException:
            self._link.close()
            raise

    def _bring_up(self, reset_wait: float, streaming_baud: int | None = None) -> None:
        """Reset, negotiate, configure and start; one more try if it fails after the reset."""
        for attempt in (1, 2):
            self._reset(reset_wait, streaming_baud)
            try:
                self._configure_and_start()
                return
            except (DeviceTimeout, ProtocolError) as exc:
                if attempt == 2:
                    raise
                log.info("%s: %s; resetting and trying once more", self.port, exc)

    def _reset(self, wait: float, streaming_baud: int | None) -> None:
        try:
            self._channel.reset(wait, streaming_baud=streaming_baud)
        except DeviceTimeout as exc:
            if streaming_baud is not None or self.config.baud == RESET_BAUD:
                raise
            # No banner at 9600: the device may still stream at our rate (a recording
            # killed before its STOP:), deaf to RESET: at 9600 where no BREAK reaches it
            # (pseudo-terminals, TCP).
            log.info("%s: no reset banner at 9600 baud; trying at %d", self.port, self.config.baud)
            try:
                self._channel.reset(min(wait, RECOVERY_RESET_WAIT), streaming_baud=self.config.baud)
            except DeviceTimeout:
                raise exc from None

    def _configure_and_start(self) -> None:
        c = self.config
        reply = self._channel.negotiate(c.baud, self.family_code, self.baud_codes)
        self._tap_event("baud_change", baud=c.baud)
        if self._adopt_pending:  # the family was checked by negotiate (VER:0)
            self._adopt_device_config()
            if self.config.baud != c.baud:  # "auto" for the device's own rate
                reply = self._channel.negotiate(self.config.baud, self.family_code, self.baud_codes)
                self._tap_event("baud_change", baud=self.config.baud)
            c = self.config
        self._check_device(reply)
        for verb, args in c.commands():
            self._channel.transact(verb, args)
        self._tap_event("configured", config=c.to_dict())
        try:
            self._channel.transact("START")
        except DeviceError as exc:
            if exc.code == 0x80:
                raise type(exc)(
                    f"{exc}; the host computes {c.line_bits_per_s / 1e6:.4g} Mbit/s for "
                    f"{self._describe_load()}, "
                    f"{c.baud} baud with 20 % reserve carries "
                    f"{0.8 * c.baud / 1e6:.4g}: lower the rate or use a faster baud",
                    code=exc.code,
                ) from exc
            raise
        # The stream restarts: seq and frame_no count from 0 again.
        self._decoder.mark_discontinuity()
        self._streaming = True
        self._reader.started(time.monotonic_ns())
        self._tap_event("started")

    def command(self, text: str) -> Reply:
        """Send one command (``"VERB:ARGS"`` or ``"VERB"``) and return the device's reply.

        Works while idle and while streaming (the reply then comes in an event
        frame; data frames that arrive meanwhile are kept for :meth:`recv`).

        Raises
        ------
        DeviceError
            With the device's code when it answers ``ERRORxx``.
        DeviceTimeout
            If no reply comes within ``reply_timeout``.
        """
        verb, _, args = text.partition(":")
        if not self._link.is_open:
            raise DeviceError(f"{self.port} is not open: call start() first")
        if not self._streaming:
            return self._channel.transact(verb, args)
        self._link.write(encode_command(verb, args))
        return self._reader.await_reply(self._decoder, f"{verb}:{args}")

    def _stop(self) -> None:
        if self._recovering is not None:
            self._recovering = None
            return
        if not self._streaming:
            return
        self._streaming = False
        try:
            self._link.write(encode_command("STOP"))
            self._reader.await_reply(self._decoder, "STOP:", okay_only=True)
            # Leave the device as it powers up (9600 baud, its defaults), where the next
            # program (another driver, `spotlab devices --probe`) finds it.
            self._link.write(encode_command("RESET"))
            # Let the command reach the device at the rate it was sent at before the
            # host moves to 9600 baud (a USB adapter or a pty's reader may still hold
            # it; the in-process sim:// device has read it already).
            if self.config.baud != RESET_BAUD and not str(self.port).startswith("sim://"):
                time.sleep(STOP_RESET_PAUSE_S)
            self._link.set_baud(RESET_BAUD)
        except DeviceDisconnected as exc:
            log.warning("%s: port lost while stopping: %s", self.port, exc)
        except DeviceTimeout as exc:
            # What was recorded stays good; the next start resets the device anyway.
            log.warning("%s: %s; the stream may still run", self.port, exc)
            self._tap_event("stop_unconfirmed", reason=str(exc))
            return
        self._tap_event("stopped")

    def drain(self) -> list[FrameBlock]:
        """Frames decoded but not yet returned by :meth:`recv` (those that arrived while
        the driver waited for its reply to ``STOP:``), handed over once."""
        return self._reader.drain()

    def _close(self) -> None:
        self._streaming = False
        self._recovering = None
        if self._link.is_open:
            self._link.close()
            self._tap_event("close", port=self.port)

    # -- streaming -----------------------------------------------------------------
    def _recv_internal(self, timeout: float | None) -> FrameBlock | None:
        if (kept := self._reader.pop()) is not None:
            return kept
        if self._recovering is not None:
            self._recover(timeout)
            return None
        if not self._streaming:
            raise DeviceError(f"{self.name} on {self.port} is not streaming: call start() first")
        if (asked := self._reconnect_asked) is not None:
            self._reconnect_asked = None
            self._link.close()
            self._tap_event("close", port=self.port)
            self._begin_recovery("disconnected", asked)
            return None
        try:
            self._reader.read(self._decoder, timeout)
        except DeviceDisconnected as exc:
            self._begin_recovery("disconnected", str(exc))
            return None
        self._reader.log_events(self._decoder)
        now = time.monotonic_ns()
        if self._decoder.banner_seen:
            self._decoder.banner_seen = False
            self._begin_recovery("device_reset", "the device sent its reset banner")
        elif (silence := self._reader.fault(now)) is not None:
            # Silence, or bytes that hold no frame.
            self._begin_recovery("device_reset", silence)
        return self._reader.pop()

    # -- recovery ------------------------------------------------------------------
    def _begin_recovery(self, kind: LinkEventKind, reason: str) -> None:
        log.warning("%s: %s; reconnecting", self.port, reason)
        self._streaming = False
        self._recovering = reason
        self._outage_start = time.monotonic()
        self._tap_event(kind, reason=reason)

    def _recover(self, timeout: float | None) -> None:
        """Try to reconnect until it works or ``timeout`` passes (at least one try)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while not self._try_reconnect():
            now = time.monotonic()
            if (
                self.reconnect_timeout is not None
                and now - self._outage_start > self.reconnect_timeout
            ):
                reason, self._recovering = self._recovering, None
                self._link.close()
                raise DeviceDisconnected(
                    f"{self.port}: could not reconnect within {self.reconnect_timeout:g} s "
                    f"after: {reason}"
                )
            wait = RETRY_INTERVAL if deadline is None else min(RETRY_INTERVAL, deadline - now)
            if wait <= 0:
                return
            time.sleep(wait)

    def _try_reconnect(self) -> bool:
        try:
            if not self._link.is_open:
                self._link.open()
                self._tap_event("open", port=self.port)
            # After a lost port the device may still stream at our rate, deaf to RESET:
            # at 9600 (no BREAK crosses a pseudo-terminal or TCP).
            self._bring_up(min(self.reply_timeout, RECOVERY_RESET_WAIT), self.config.baud)
        except DeviceConfigurationError:
            raise
        except DeviceDisconnected:
            self._link.close()
            return False
        except (*_TRANSIENT, DeviceError):
            return False
        outage = time.monotonic() - self._outage_start
        self.stats.reconnects += 1
        self.stats.gaps += 1
        self._tap_event("reconnected", reason=self._recovering, outage_s=round(outage, 3))
        log.warning("%s: streaming again after %.2f s", self.port, outage)
        self._recovering = None
        return True
