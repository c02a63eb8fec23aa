"""Host command lines as an MCS-1 device reads them (mcs1.md §3).

Bytes are collected up to ``\\r``. A line is either the CRC form
``VERB:ARGS`` + 4 hex digits of CRC, or the terminal form ``VERB ARGS`` (no
CRC). Decisions where the spec is silent (documented in docs/simulators.md):

* a ``\\n`` at the start of a line is skipped (a terminal's ``\\r\\n``);
* more than 255 bytes before ``\\r``: ``ERROR02`` when the ``\\r`` arrives;
* CRC form with fewer than 4 characters after the colon: ``ERROR03``;
* the CRC is checked before the verb (a bad CRC on an unknown verb is ``ERROR04``);
  the CRC digits may be upper or lower case;
* a bare word without colon or space (``AT``) is a terminal-form command
  without arguments, so an unknown one is ``ERROR01``;
* verbs are case-sensitive upper case; parameters are split at commas;
* a line not finished by ``\\r`` within 1 s of its first byte is dropped with
  ``ERROR05``.
"""

from __future__ import annotations

from dataclasses import dataclass

from spotlab.core.crc import crc16

MAX_LINE = 255
MAX_LEDT_LINE = 1024
LINE_TIMEOUT_NS = 1_000_000_000
_HEX = frozenset("0123456789ABCDEFabcdef")


class CommandError(Exception):
    """A line that cannot be taken as a command; ``code`` is the ERRORxx number."""

    def __init__(self, code: int) -> None:
        super().__init__(f"ERROR{code:02X}")
        self.code = code


@dataclass(frozen=True)
class Command:
    """A parsed command: ``verb``, its comma-separated ``params``, and whether it had a CRC."""

    verb: str
    params: tuple[str, ...]
    with_crc: bool


def parse_line(line: bytes) -> Command:
    """Parse one line (without the ``\\r``).

    Raises
    ------
    CommandError
        02 too long, 03 too short for its CRC, 04 bad CRC.
    """
    if len(line) > (MAX_LEDT_LINE if line.startswith((b"LEDT:", b"LEDT ")) else MAX_LINE):
        raise CommandError(0x02)
    text = line.decode("latin-1")
    colon, space = text.find(":"), text.find(" ")
    if colon >= 0 and (space < 0 or colon < space):
        if len(text) - colon - 1 < 4:
            raise CommandError(0x03)
        body, crc_text = text[:-4], text[-4:]
        if not set(crc_text) <= _HEX or int(crc_text, 16) != crc16(line[:-4]):
            raise CommandError(0x04)
        verb, args, with_crc = body[:colon], body[colon + 1 :], True
    elif space >= 0:
        verb, args, with_crc = text[:space], text[space + 1 :].strip(), False
    else:
        verb, args, with_crc = text, "", False
    params = tuple(args.split(",")) if args else ()
    return Command(verb, params, with_crc)


class LineAssembler:
    """Collects received bytes into lines, with the 1 s command timeout."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self._length = 0
        self._first_ns: int | None = None

    def clear(self) -> None:
        """Forget a partial line (after a reset)."""
        self._buf.clear()
        self._length = 0
        self._first_ns = None

    def deadline_ns(self) -> int | None:
        """When the partial line times out, or None when there is none."""
        return None if self._first_ns is None else self._first_ns + LINE_TIMEOUT_NS

    def feed(self, t_ns: int, byte: int) -> bytes | None:
        """Take one byte received at ``t_ns``; returns a complete line (maybe empty) at ``\\r``."""
        if byte == 0x0D:
            line = bytes(self._buf) if self._length <= MAX_LEDT_LINE else bytes(MAX_LEDT_LINE + 1)
            self.clear()
            return line
        if byte == 0x0A and self._length == 0:
            return None
        if self._first_ns is None:
            self._first_ns = t_ns
        self._length += 1
        if self._length <= MAX_LEDT_LINE:
            self._buf.append(byte)
        return None
