"""Golden byte vectors read from a protocol page (docs/protocols/*.md), so that a
family's driver tests and simulator tests check the very bytes the page shows.

A vector is the first block of hex bytes after its bold name (``**G6**``, ``**Server
info**``): a fenced block, an indented block, or an inline code span ending a line. A
line ``(N rows of 16 zero bytes)`` inside a block stands for 16 N zero bytes; inside a
fenced block, what follows a line's hex bytes is a comment.
"""

from __future__ import annotations

import re
from pathlib import Path

__all__ = ["golden_vector"]

_ZERO_ROWS = re.compile(r"^\(?(\d+) rows? of 16 zero bytes\)?$")
_HEX_LINE = re.compile(r"^(?:[0-9A-Fa-f]{2})(?: [0-9A-Fa-f]{2})*$")
_HEX_PREFIX = re.compile(r"^(?:[0-9A-Fa-f]{2} )*")


def golden_vector(page: str | Path, name: str) -> bytes:
    """The bytes of vector ``name`` on protocol page ``page``.

    Parameters
    ----------
    page : str or Path
        The Markdown page.
    name : str
        The vector's bold name, without the asterisks.

    Returns
    -------
    bytes

    Raises
    ------
    KeyError
        When the page has no such name, or no hex block follows it.
    """
    text = Path(page).read_text(encoding="utf-8")
    marker = f"**{name}**"
    if marker not in text:
        raise KeyError(f"{page}: no vector {marker}")
    after = text.split(marker, 1)[1]
    inline = re.match(r"[^\n`]*`([0-9A-Fa-f ]+)`\s*\n", after)
    if inline:
        return bytes.fromhex(inline.group(1))
    out = bytearray()
    started = fenced = False
    for raw in after.splitlines()[1:]:
        line = raw.strip()
        if line.startswith("```"):
            if started:
                break
            started = fenced = True
            continue
        if fenced:
            line = _HEX_PREFIX.match(line + " ").group(0).strip()  # type: ignore[union-attr]
        zeros = _ZERO_ROWS.match(line)
        if _HEX_LINE.match(line) or zeros:
            started = True
            out += bytes(16 * int(zeros.group(1))) if zeros else bytes.fromhex(line)
        elif started and out:
            break
    if not out:
        raise KeyError(f"{page}: no hex block after {marker}")
    return bytes(out)
