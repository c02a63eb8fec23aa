"""Where a key is written in a TOML file: its line number, for messages.

``tomllib`` gives values, not positions. :func:`line_of` finds a key by a simple
scan of the text: the table headers (``[a.b]``, ``[[a]]``, counting the array's
entries) and then ``key =`` lines inside the table. It is only used to point a
person at a line; when a key cannot be found (written in an inline table, say) the
line of its table, or 1, is given.
"""

from __future__ import annotations

import re
from collections.abc import Sequence

_HEADER = re.compile(r"^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
_KEY = re.compile(r"""^\s*("[^"]*"|'[^']*'|[A-Za-z0-9_\-]+)\s*(\.|=)""")

#: A key path: table names, array indexes and the key (``("device", 1, "sim", "faults")``).
KeyPath = Sequence[str | int]


def _unquote(word: str) -> str:
    return word[1:-1] if word[:1] in "\"'" else word


def _header_path(text: str) -> list[str]:
    return [_unquote(p.strip()) for p in re.split(r"\.(?=(?:[^\"]*\"[^\"]*\")*[^\"]*$)", text)]


def line_of(text: str, path: KeyPath) -> int:
    """The 1-based line where ``path`` is written in ``text`` (best effort, never fails)."""
    names = [p for p in path if isinstance(p, str)]
    lines = text.splitlines()
    counts: dict[tuple[str, ...], int] = {}
    current: list[str | int] = []
    best = 1
    best_len = -1
    for number, line in enumerate(lines, start=1):
        header = _HEADER.match(line)
        if header:
            parts = _header_path(header.group(2))
            if header.group(1) == "[[":
                key = tuple(parts)
                index = counts.get(key, -1) + 1
                counts[key] = index
                current = [*parts[:-1], parts[-1], index]
            else:
                current = list(parts)
                # a [device.sim] table belongs to the latest [[device]] entry
                for key, index in counts.items():
                    if tuple(parts[: len(key)]) == key:
                        current = [*key, index, *parts[len(key) :]]
            if _prefix(current, path) and len(current) > best_len:
                best, best_len = number, len(current)
            continue
        match = _KEY.match(line)
        if match and names:
            full = [*current, _unquote(match.group(1))]
            if _prefix(full, path) and len(full) > best_len:
                best, best_len = number, len(full)
    return best


def _prefix(found: Sequence[str | int], path: KeyPath) -> bool:
    """Whether ``found`` is a leading part of ``path`` (array indexes must agree)."""
    if len(found) > len(path):
        return False
    return all(a == b for a, b in zip(found, path, strict=False))


__all__ = ["KeyPath", "line_of"]
