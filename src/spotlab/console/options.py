"""Option values shared by several commands, parsed from their text."""

from __future__ import annotations

import argparse
from typing import Any

from spotlab.console.errors import CommandError

__all__ = ["add_realtime_argument", "parse_wiring"]


def _priority(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer 1-99, got {text!r}") from None
    if not 1 <= value <= 99:
        raise argparse.ArgumentTypeError(f"expected 1-99, got {value}")
    return value


def add_realtime_argument(p: Any) -> None:
    """``--realtime PRIO``: the session's threads under SCHED_FIFO (docs/live.md)."""
    p.add_argument(
        "--realtime",
        type=_priority,
        default=None,
        metavar="PRIO",
        help="run the acquisition's threads under real-time scheduling (SCHED_FIFO, "
        "priority 1-99) where the system allows it (root, CAP_SYS_NICE or rtprio); "
        "other programs then do not delay them (docs/live.md)",
    )


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
