"""What udev makes of a value: MODE bits, format substitutions, OPTIONS.

Pure functions on one string each, used by :mod:`.checks` and by the tests of
the shipped rules (:func:`is_world_writable`).
"""

from __future__ import annotations

import re

# Format substitutions of udev-format.c: long names ($name) in udev's order, short (%c).
_SUBST_LONG = (
    ("devnode", "N"),
    ("tempnode", "N"),
    ("attr", "s"),
    ("sysfs", "s"),
    ("env", "E"),
    ("kernel", "k"),
    ("number", "n"),
    ("driver", "d"),
    ("devpath", "p"),
    ("id", "b"),
    ("major", "M"),
    ("minor", "m"),
    ("result", "c"),
    ("parent", "P"),
    ("name", "D"),
    ("links", "L"),
    ("root", "r"),
    ("sys", "S"),
)
_SUBST_SHORT = frozenset(char for _, char in _SUBST_LONG)
_OCTAL_MODE = re.compile(r"[0-7]{1,4}")
_RESULT_INDEX = re.compile(r"[0-9]+\+?")

_LOG_LEVELS = frozenset(
    {"emerg", "alert", "crit", "err", "warning", "notice", "info", "debug", "reset"}
    | {str(n) for n in range(8)}
)
_PLAIN_OPTIONS = frozenset(
    {"dump", "string_escape=none", "string_escape=replace", "db_persist", "watch", "nowatch"}
)


def mode_bits(value: str) -> int | None:
    """The permission bits of a MODE value ("0660", "660"), or None if not octal."""
    if not _OCTAL_MODE.fullmatch(value):
        return None
    return int(value, 8)


def is_world_writable(value: str) -> bool:
    """True if a MODE value lets every user write (the "other" write bit, 0o002)."""
    bits = mode_bits(value)
    return bits is not None and bool(bits & 0o002)


def is_option(value: str) -> bool:
    """True if ``value`` is one option udev knows (``OPTIONS`` takes one per key)."""
    if value.startswith("static_node="):
        return bool(value.removeprefix("static_node="))
    if value.startswith("link_priority="):
        return re.fullmatch(r"[+-]?[0-9]+", value.removeprefix("link_priority=")) is not None
    if value.startswith("log_level="):
        return value.removeprefix("log_level=") in _LOG_LEVELS
    return value in _PLAIN_OPTIONS


def format_problem(value: str) -> tuple[int, str] | None:
    """Check udev substitutions (``%E{KEY}``, ``$attr{x}``, ``%%``, ``$$``) like udev_check_format.

    Returns (offset, hint) of the first invalid substitution, or None.
    """
    i = 0
    n = len(value)
    while i < n:
        char = value[i]
        if char not in "%$":
            i += 1
            continue
        nxt = value[i + 1 : i + 2]
        if nxt == char:
            i += 2
            continue
        kind = ""
        j = i + 1
        if char == "$":
            for name, short in _SUBST_LONG:
                if value.startswith(name, i + 1):
                    kind, j = short, i + 1 + len(name)
                    break
        elif nxt in _SUBST_SHORT and nxt:
            kind, j = nxt, i + 2
        if not kind:
            return (
                i,
                f"invalid substitution '{value[i : i + 2]}' "
                f"(write '{char}{char}' for a literal '{char}')",
            )
        attr = ""
        if value[j : j + 1] == "{":
            end = value.find("}", j + 1)
            if end < 0:
                return j, "'{' of the substitution is not closed"
            attr = value[j + 1 : end]
            if not attr:
                return j, "empty '{}' in substitution"
            j = end + 1
        if kind in ("s", "E") and not attr:
            return i, f"'{value[i:j]}' needs an attribute, e.g. %E{{ID_SERIAL_SHORT}}"
        if kind == "c" and attr and not _RESULT_INDEX.fullmatch(attr):
            return i, f"'{value[i:j]}': result index must be a number, optionally followed by '+'"
        i = j
    return None
