"""MCS-1 command exchanges outside a stream: reset, commands, baud negotiation.

:class:`CommandChannel` runs the steps of mcs1.md §1 and §3 on a
:class:`~spotlab.drivers.mcs1.link.SerialLink`, for every family:

* :meth:`~CommandChannel.reset` — BREAK, else ``RESET:`` at 9600 baud, until the
  banner ``RESET7DB2\\r`` arrives;
* :meth:`~CommandChannel.transact` — send one command, read its reply line,
  raise the ``ERRORxx`` it carries;
* :meth:`~CommandChannel.negotiate` — ``COMM:<c>`` at 9600, switch, ``VER:0`` at
  the new rate within 1 s.

Replies are read byte by byte up to their CR, so no byte that follows (the
first stream frame after ``START:``) is taken from the port: it reaches the
stream decoder untouched and the wire journal stays in order. Lines whose CRC
fails (line noise, ``AT\\r`` from ModemManager) are skipped; a reply behind
garbage on the same line is still found.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping

from spotlab.core.errors import DeviceError, DeviceTimeout, ProtocolError
from spotlab.core.stats import LinkStats
from spotlab.drivers.mcs1.commands import (
    BANNER,
    BAUD_CODES,
    RESET_BAUD,
    Reply,
    WrongFamilyError,
    check_line,
    encode_command,
    parse_reply,
)
from spotlab.drivers.mcs1.link import MAX_LINE, SerialLink

log = logging.getLogger(__name__)

#: Time the device has to answer ``VER:0`` at a new baud rate (mcs1.md §1).
VER_WINDOW = 1.0
#: Longest wait for the banner after a BREAK (s): a device answers within ~15 ms at 9600 baud.
BREAK_WAIT = 0.15
#: Quiet time after the banner before the first command (a second banner may follow).
_SETTLE = 0.02
#: Pause after ``RESET:`` at a streaming rate before the host moves to 9600 baud, so
#: that the command has reached the device at the rate it was sent at.
_STREAM_RESET_PAUSE = 0.05
#: Wait for the banner after each ``RESET:`` at a streaming rate, before sending it again
#: (a pseudo-terminal's far side reads late on a loaded machine, and takes the bytes at
#: the rate set by then).
_STREAM_RESET_WAIT = 0.15


def find_reply(line: bytes) -> bytes | None:
    """The longest tail of ``line`` that is a CRC-valid reply, or ``None``.

    Garbage before a reply on the same line (``AT`` without its own CR, noise)
    is cut off; a line that holds no valid reply gives ``None``.
    """
    for k in range(max(0, len(line) - 5) + 1):
        if check_line(line[k:]) is not None:
            return line[k:]
    return None


class CommandChannel:
    """Command exchanges with an MCS-1 device that is not streaming.

    Parameters
    ----------
    link : SerialLink
        The open port.
    reply_timeout : float
        Seconds to wait for each reply.
    stats : LinkStats, optional
        Counters to update with the bytes read here (``bytes``) and the reply
        lines thrown away for a bad CRC (``crc_errors``).
    """

    def __init__(
        self, link: SerialLink, reply_timeout: float = 1.0, stats: LinkStats | None = None
    ) -> None:
        self.link = link
        self.reply_timeout = reply_timeout
        self.stats = stats if stats is not None else LinkStats()
        #: False once a BREAK went unanswered: later resets go straight to ``RESET:``.
        self.break_works: bool | None = None

    # -- reset -------------------------------------------------------------------
    def reset(self, timeout: float | None = None, *, streaming_baud: int | None = None) -> None:
        """Bring the device to its reset state at 9600 baud and wait for the banner.

        Sends a BREAK (unless BREAK is known not to reach the device on this
        link) and waits up to a quarter of ``timeout`` (at most 0.15 s); then, without a banner,
        sends ``\\r`` + ``RESET:`` at ``streaming_baud`` (if given), then at 9600 baud,
        and waits for the rest (with ``streaming_baud``, both are sent again every
        0.2 s until the banner comes).

        Parameters
        ----------
        timeout : float, optional
            Total time allowed; ``reply_timeout`` by default.
        streaming_baud : int, optional
            A rate the device may still be running at (it kept streaming while the
            port was away): where no BREAK reaches it (pseudo-terminals, TCP), only a
            ``RESET:`` at that rate does.

        Raises
        ------
        DeviceTimeout
            If no banner arrives; the message names the port and what was sent.
        DeviceDisconnected
            If the port went away.
        """
        total = self.reply_timeout if timeout is None else timeout
        deadline = time.monotonic() + total
        self.link.set_baud(RESET_BAUD)
        sent = []
        if self.break_works is not False and self.link.send_break():
            sent.append("a BREAK")
            if self._await_banner(time.monotonic() + min(total / 4, BREAK_WAIT)):
                self.break_works = True
                return
        if streaming_baud is not None and streaming_baud != RESET_BAUD:
            sent += [f"RESET: at {streaming_baud} baud", "RESET: at 9600 baud"]
            while True:
                self.link.set_baud(streaming_baud)
                self.link.write(b"\r" + encode_command("RESET"))
                time.sleep(_STREAM_RESET_PAUSE)
                self.link.set_baud(RESET_BAUD)
                self.link.write(b"\r" + encode_command("RESET"))
                wait_until = min(deadline, time.monotonic() + _STREAM_RESET_WAIT)
                found = self._await_banner(wait_until)
                if found or time.monotonic() >= deadline:
                    break
        else:
            # An empty line ends any half-received command; the device ignores it.
            self.link.write(b"\r" + encode_command("RESET"))
            sent.append("RESET: at 9600 baud")
            found = self._await_banner(deadline)
        if found:
            if sent[0] == "a BREAK" and self.break_works is None:
                self.break_works = False  # the device is there; BREAK does not reach it
            return
        raise DeviceTimeout(
            f"no answer from {self.link.url}: sent {' and '.join(sent)}, no reset banner "
            f"within {total:g} s. Is the device powered and connected to this port?"
        )

    def _await_banner(self, deadline: float) -> bool:
        seen = b""
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return False
            data, _ = self.link.read(remaining)
            self.stats.bytes += len(data)
            seen = seen[-(len(BANNER) - 1) :] + data
            if BANNER in seen:
                self._settle()
                return True

    def _settle(self) -> None:
        """Read until the line is quiet for a moment (a late second banner, echoes)."""
        while True:
            data, _ = self.link.read(_SETTLE)
            if not data:
                return
            self.stats.bytes += len(data)

    # -- commands ------------------------------------------------------------------
    def send(self, verb: str, args: str = "") -> str:
        """Send one command; return its text as sent (``"CAMS:4"``) for messages."""
        self.link.write(encode_command(verb, args))
        return f"{verb}:{args}"

    def read_reply(
        self,
        command: str,
        data_prefix: str | None = None,
        timeout: float | None = None,
        ignore_banner: bool = False,
    ) -> Reply:
        """Read the reply to ``command``, skipping lines that fail their CRC.

        A reply that has begun but not ended when the time runs out gets the same time
        again, once, to end (a device or a host slowed down by other work).

        Parameters
        ----------
        command : str
            The command as sent, for messages.
        data_prefix : str, optional
            First word of the data reply the command may get (see :func:`parse_reply`).
        timeout : float, optional
            Seconds to wait; ``reply_timeout`` by default.
        ignore_banner : bool
            Skip a reset banner (right after a reset, a second one may come).

        Returns
        -------
        Reply
            The reply (``ERRORxx`` included; see :meth:`transact` to raise it).

        Raises
        ------
        DeviceTimeout
            If no line came at all.
        ProtocolError
            If only damaged lines came, or a CRC-valid line that is no reply to
            this command (the message shows the bytes).
        """
        wait = self.reply_timeout if timeout is None else timeout
        deadline = time.monotonic() + wait
        damaged: list[bytes] = []
        pending = b""  # a line under way when the time ran out
        grace = True
        while True:
            line, _ = self.link.read_line(deadline)
            self.stats.bytes += len(line)
            line, pending = pending + line, b""
            if grace and line and not line.endswith(b"\r") and len(line) < MAX_LINE:
                # The reply had begun when the time ran out (the device, or this host,
                # slowed down): the line gets one more period to end, once.
                grace = False
                pending, deadline = line, time.monotonic() + wait
                continue
            if line.endswith(b"\r"):
                reply = find_reply(line)
                if reply is not None:
                    if reply == BANNER:
                        if ignore_banner:
                            continue
                        raise ProtocolError(
                            f"the device on {self.link.url} reset itself (sent its banner "
                            f"{reply!r}) instead of answering {command}"
                        )
                    if len(reply) < len(line):
                        log.debug("skipped %r before the reply to %s", line[: -len(reply)], command)
                    try:
                        return parse_reply(reply, data_prefix)
                    except ProtocolError as exc:
                        raise ProtocolError(
                            f"{exc} (the answer to {command} from {self.link.url})"
                        ) from exc
            if line:
                damaged.append(line)
                self.stats.crc_errors += 1
                log.debug(
                    "skipped a damaged line %r while waiting for the reply to %s", line, command
                )
            if time.monotonic() >= deadline:
                break
        if damaged:
            raise ProtocolError(
                f"no valid reply to {command} from {self.link.url} within {wait:g} s; "
                f"received only damaged lines: {b''.join(damaged)[:200]!r}"
            )
        raise DeviceTimeout(f"no reply to {command} from {self.link.url} within {wait:g} s")

    def transact(
        self,
        verb: str,
        args: str = "",
        *,
        data_prefix: str | None = None,
        timeout: float | None = None,
    ) -> Reply:
        """Send a command and return its reply, raising the error it reports.

        Raises
        ------
        DeviceError
            (or a subclass) when the device answers ``ERRORxx``.
        DeviceTimeout, ProtocolError
            As :meth:`read_reply`.
        """
        command = self.send(verb, args)
        return self.read_reply(command, data_prefix, timeout).raise_for_error(command)

    # -- baud rate -----------------------------------------------------------------
    def _check_family(self, family_code: str) -> None:
        """``VER:0`` at the current rate: :class:`WrongFamilyError` naming the family that
        answered when it is another MCS-1 family; any other outcome is left to the caller."""
        command = self.send("VER", "0")
        try:
            self.read_reply(command, data_prefix=family_code)
        except WrongFamilyError as exc:
            raise WrongFamilyError(exc.answered, exc.expected, exc.text, self.link.url) from None
        except (DeviceError, ProtocolError):
            pass

    def negotiate(
        self, baud: int, family_code: str, codes: Mapping[int, int] = BAUD_CODES
    ) -> Reply:
        """Move the link from 9600 baud to ``baud`` and check it with ``VER:0``.

        Parameters
        ----------
        baud : int
            Target rate, one of ``codes``.
        family_code : str
            First word of the ``VER:0`` reply (``"SPX"``).
        codes : mapping of int to int
            Baud rate -> ``COMM`` code; :data:`~spotlab.drivers.mcs1.commands.BAUD_CODES`
            unless the family has more (CEN: 6 and 12 Mbaud).

        Returns
        -------
        Reply
            The ``VER:0`` reply.

        Raises
        ------
        DeviceTimeout
            If ``VER:0`` gets no answer within 1 s at the new rate.
        ProtocolError
            If the answer is not the expected family's.
        """
        if baud != RESET_BAUD:
            command = self.send("COMM", str(codes[baud]))
            reply = self.read_reply(command, ignore_banner=True)
            if reply.kind == "error":
                self._check_family(family_code)
            reply.raise_for_error(command)
            self.link.set_baud(baud)
        command = self.send("VER", "0")
        try:
            reply = self.read_reply(
                command, data_prefix=family_code, timeout=max(VER_WINDOW, self.reply_timeout)
            )
        except DeviceTimeout as exc:
            raise DeviceTimeout(
                f"no answer to VER:0 from {self.link.url} at {baud} baud after switching "
                f"from {RESET_BAUD}; the port or adapter may not support this rate"
            ) from exc
        except WrongFamilyError as exc:
            # Leave the device at 9600 baud, where the right driver finds it.
            self.link.write(encode_command("RESET"))
            raise WrongFamilyError(exc.answered, exc.expected, exc.text, self.link.url) from None
        except ProtocolError as exc:
            raise ProtocolError(f"{exc} (at {baud} baud after switching from 9600)") from exc
        return reply.raise_for_error(command)
