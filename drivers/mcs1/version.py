"""The ``VER:0`` reply every MCS-1 device gives: ``<code> <firmware> <serial> <ints...>``.

A family declares its reply as a frozen dataclass that derives from
:class:`VersionReply`: fields ``firmware``, ``serial_number``, then the integer
fields in reply order, then ``text`` (the whole reply), and the class variables
``code`` (the family code, first word of the reply) and ``form`` (the integer
fields as the error message names them).
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar, Self

from spotlab.core.errors import ProtocolError


class VersionReply:
    """What an MCS-1 device says of itself in reply to ``VER:0`` (base of the family records).

    Subclasses are frozen dataclasses whose fields are ``firmware: str``,
    ``serial_number: str``, one ``int`` field per number of the reply, and ``text: str``.
    """

    #: The family code that opens the reply (``"SPX"``, ``"TMR"``, ``"CEN"``).
    code: ClassVar[str] = ""
    #: The numbers of the reply as the error message names them (``"<inputs> <outputs>"``).
    form: ClassVar[str] = ""

    firmware: str
    serial_number: str
    text: str

    @classmethod
    def parse(cls, text: str) -> Self:
        """Parse a ``VER:0`` reply text such as ``"TMR 1.0 SIM00077 8 4 10000000"``.

        Words after the last field are ignored.

        Raises
        ------
        ProtocolError
            If it is not a version reply of the family's form; the message shows it.
        """
        n_numbers = len(dataclasses.fields(cls)) - 3  # type: ignore[arg-type]
        fields = text.split()
        try:
            if len(fields) < 3 + n_numbers or fields[0] != cls.code:
                raise ValueError(text)
            numbers = [int(f) for f in fields[3 : 3 + n_numbers]]
            return cls(fields[1], fields[2], *numbers, text)  # type: ignore[call-arg]
        except ValueError as exc:
            raise ProtocolError(
                f"VER:0 reply {text!r} is not '{cls.code} <firmware> <serial> {cls.form}'"
            ) from exc

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe form."""
        return dataclasses.asdict(self)  # type: ignore[call-overload]
