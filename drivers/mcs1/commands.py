"""MCS-1 commands and replies (docs/protocols/mcs1.md §3).

A command is ``VERB:ARGS`` + CRC-16 of that text as four upper-case hex digits +
``\\r``. A reply is ``TEXT`` + CRC + ``\\r`` where ``TEXT`` is ``OKAY``,
``ERRORxx``, ``WARNxx`` or a data reply starting with the verb's own word (or the
family code for ``VER:0``).

:func:`parse_reply` turns the bytes of one reply into a :class:`Reply` and rejects
what is not a reply at all; :meth:`Reply.raise_for_error` turns ``ERRORxx`` into a
:class:`~spotlab.core.errors.DeviceError` whose message names the code's meaning.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Literal

from spotlab.core.crc import crc16, crc16_hex
from spotlab.core.errors import BandwidthError, ConfigurationError, DeviceError, ProtocolError

log = logging.getLogger(__name__)

#: Banner sent at 9600 baud after power-up, BREAK or ``RESET:`` (``RESET`` + CRC + CR).
BANNER = b"RESET7DB2\r"

#: ``COMM:<c>`` code for each baud rate (mcs1.md §1).
BAUD_CODES: dict[int, int] = {
    9_600: 0,
    14_400: 1,
    19_200: 2,
    38_400: 3,
    57_600: 4,
    115_200: 5,
    921_600: 6,
    1_000_000: 7,
    2_000_000: 8,
    3_000_000: 9,
}
RESET_BAUD = 9_600
MAX_COMMAND = 255

#: Meaning of every ``ERRORxx`` / ``WARNxx`` code of mcs1.md §3.
ERROR_MEANINGS: dict[int, str] = {
    0x01: "invalid (unknown) command",
    0x02: "command too long",
    0x03: "command too short",
    0x04: "bad CRC",
    0x05: "timeout (command not finished by CR within 1 s of its first byte)",
    0x07: "wrong number of parameters",
    0x0C: "not allowed in this mode (e.g. configuring while streaming)",
    0x23: "parameter out of range",
    0x80: "bandwidth exceeded: the configuration does not fit the line",
    0x81: "bad LED / marker table",
    0x82: "not configured (no LED / marker table yet)",
    0x83: "FIFO overflow",
    0x84: "sensor fault",
    0x85: "external sync lost",
}


class DeviceConfigurationError(DeviceError, ConfigurationError):
    """The device refused a configuration (codes 23, 81, 82); also a ``ConfigurationError``."""


class DeviceBandwidthError(DeviceConfigurationError, BandwidthError):
    """The device refused ``START:`` with ``ERROR80``; also a ``BandwidthError``."""


def encode_command(verb: str, args: str = "") -> bytes:
    """The wire bytes of a command: ``VERB:ARGS`` + CRC hex + CR.

    Parameters
    ----------
    verb : str
        Upper-case command word (``"COMM"``).
    args : str, optional
        Argument text after the colon (``"8"``).

    Returns
    -------
    bytes
        For example ``b"COMM:88B92\\r"`` for ``("COMM", "8")``.

    Raises
    ------
    ConfigurationError
        If the text is not printable ASCII, or the verb is not alphanumeric.

    Notes
    -----
    mcs1.md §3 limits a command to 255 bytes before the CR unless its family
    allows more for a verb (SPX: ``LEDT`` up to 1024, so 128 entries fit). The
    command is built whatever its length; the device answers ``ERROR02`` when
    it is too long.
    """
    text = f"{verb}:{args}"
    if not verb.isalnum() or not text.isascii() or not text.isprintable():
        raise ConfigurationError(f"not a valid MCS-1 command: {text!r}")
    return f"{text}{crc16_hex(text)}\r".encode("ascii")


def error_message(code: int) -> str:
    """The meaning of an ``ERRORxx`` code, or ``"unknown error code"``."""
    return ERROR_MEANINGS.get(code, "unknown error code")


ReplyKind = Literal["okay", "error", "warn", "data"]


@dataclass(frozen=True)
class Reply:
    """One reply of the device, CRC checked.

    Attributes
    ----------
    kind : {"okay", "error", "warn", "data"}
        What the reply is.
    text : str
        The reply text without CRC and CR (``"OKAY"``, ``"ERROR80"``, ``"TIME ..."``).
    code : int or None
        The code of ``ERRORxx`` / ``WARNxx``, else ``None``.
    raw : bytes
        The reply as received, CRC and CR included.
    """

    kind: ReplyKind
    text: str
    code: int | None
    raw: bytes

    def raise_for_error(self, command: str) -> Reply:
        """Raise the error an ``ERRORxx`` reply stands for; return ``self`` otherwise.

        Parameters
        ----------
        command : str
            The command this replies to (``"START:"``), named in the message.

        Raises
        ------
        DeviceBandwidthError
            For ``ERROR80``.
        DeviceConfigurationError
            For ``ERROR23``, ``ERROR81``, ``ERROR82``.
        DeviceError
            For every other code; ``code`` holds the device's code.
        """
        if self.kind == "warn":
            log.warning(
                "device warned after %s: %s (%s)", command, self.text, error_message(self.code or 0)
            )
        if self.kind != "error":
            return self
        code = self.code if self.code is not None else -1
        message = f"device refused {command} with {self.text}: {error_message(code)}"
        if code == 0x80:
            raise DeviceBandwidthError(message, code=code)
        if code in (0x23, 0x81, 0x82):
            raise DeviceConfigurationError(message, code=code)
        raise DeviceError(message, code=code)


def check_line(line: bytes) -> str | None:
    """The text of a reply line if its CRC checks, else ``None``.

    Parameters
    ----------
    line : bytes
        One line as received, ending in CR.
    """
    if len(line) < 6 or not line.endswith(b"\r"):
        return None
    body, crc_text = line[:-5], line[-5:-1]
    if crc_text.strip(b"0123456789ABCDEF") or crc16(body) != int(crc_text, 16):
        return None
    try:
        text = body.decode("ascii")
    except UnicodeDecodeError:
        return None
    return text if text.isprintable() else None


#: MCS-1 family codes (first word of the ``VER:0`` reply) and spotlab's driver families.
FAMILY_NAMES = {"SPX": "selspot", "TMR": "timer", "CEN": "centroid"}


class WrongFamilyError(ConfigurationError):
    """A ``VER:0`` reply from a device of another MCS-1 family than the one expected.

    Attributes
    ----------
    answered : str
        The family code the device gave (``"SPX"``).
    expected : str
        The family code asked for.
    text : str
        The reply text.
    """

    def __init__(self, answered: str, expected: str, text: str, port: str = "") -> None:
        self.answered, self.expected, self.text = answered, expected, text
        family = FAMILY_NAMES.get(answered, answered)
        where = f" on {port}" if port else ""
        super().__init__(
            f"the device{where} is a {family} device ({answered}), not a "
            f"{FAMILY_NAMES.get(expected, expected)} one ({expected}): it answered VER:0 with "
            f"{text!r}; use the {family} driver (--driver {family} or --device {family}=PORT)"
        )


def parse_reply(line: bytes, data_prefix: str | None = None) -> Reply:
    """Parse one reply line (CRC and CR included).

    Parameters
    ----------
    line : bytes
        The line, for example ``b"OKAY26CF\\r"``.
    data_prefix : str, optional
        First word a data reply to the command must start with (``"TIME"``,
        ``"SPX"`` for ``VER:0``). ``None`` when the command has no data reply.

    Returns
    -------
    Reply

    Raises
    ------
    ProtocolError
        If the line's CRC fails, or it is neither ``OKAY``, ``ERRORxx``,
        ``WARNxx`` nor the expected data reply; the message shows the bytes.
    WrongFamilyError
        If ``data_prefix`` is a family code and the reply is another family's ``VER:0``.
    """
    text = check_line(line)
    if text is None:
        raise ProtocolError(f"reply {line!r} is malformed or its CRC does not check")
    if text == "OKAY":
        return Reply("okay", text, None, bytes(line))
    for word, kind in (("ERROR", "error"), ("WARN", "warn")):
        if text.startswith(word):
            digits = text[len(word) :]
            if len(digits) == 2 and all(c in "0123456789ABCDEF" for c in digits):
                return Reply(kind, text, int(digits, 16), bytes(line))  # type: ignore[arg-type]
            raise ProtocolError(f"reply {line!r} has a malformed {word} code")
    if data_prefix is not None and (text == data_prefix or text.startswith(data_prefix + " ")):
        return Reply("data", text, None, bytes(line))
    word = text.split(" ", 1)[0]
    if data_prefix in FAMILY_NAMES and word in FAMILY_NAMES:
        raise WrongFamilyError(word, data_prefix, text)
    expected = "OKAY, ERRORxx or WARNxx" + (f" or '{data_prefix} ...'" if data_prefix else "")
    raise ProtocolError(f"unexpected reply {line!r}: expected {expected}")


def parse_conf(text: str) -> dict[str, str]:
    """The fields of a ``CONF`` reply: verb -> the arguments that verb would take.

    Parameters
    ----------
    text : str
        Reply text, for example ``"CONF RATE=200000 CAMS=2 SLOT=100"``.

    Returns
    -------
    dict of str to str
        ``{"RATE": "200000", "CAMS": "2", "SLOT": "100"}``.

    Raises
    ------
    ProtocolError
        If the text is not ``CONF`` followed by ``VERB=ARGS`` words.
    """
    words = text.split(" ")
    if not words or words[0] != "CONF":
        raise ProtocolError(f"reply {text!r} to CONF does not start with 'CONF'")
    fields: dict[str, str] = {}
    for word in words[1:]:
        verb, sep, args = word.partition("=")
        if not sep or not verb.isalpha() or not verb.isupper():
            raise ProtocolError(f"reply {text!r} to CONF: {word!r} is not VERB=ARGS")
        fields[verb] = args
    return fields
