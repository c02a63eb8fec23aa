"""Option values shared by several commands, parsed from their text."""

from __future__ import annotations

from spotlab.console.errors import CommandError

__all__ = ["parse_wiring"]


def parse_wiring(items: list[str]) -> dict[str, int]:
    """``STREAM=INPUT`` options as a mapping; CommandError when malformed."""
    out: dict[str, int] = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            if not sep or not name:
                raise ValueError
            out[name] = int(value)
        except ValueError:
            raise CommandError(
                f"--wiring {item!r}: expected STREAM=INPUT, e.g. selspot0=0"
            ) from None
    return out
