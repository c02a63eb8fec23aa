"""Numeric CSV tables of the command line: a header row, then numbers (empty cell: NaN)."""

from __future__ import annotations

import csv
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from spotlab.processing.errors import InputError

__all__ = ["camera_count", "column", "read_table"]

FloatArray = NDArray[np.float64]


def read_table(path: Path) -> tuple[list[str], FloatArray]:
    """The header and the values (rows, columns) of a CSV table; empty cells are NaN.

    Raises
    ------
    InputError
        For an unreadable file, a table without data rows, a row of the wrong length or
        a cell that is not a number (naming the row and column).
    """
    try:
        with path.open(newline="") as fh:
            rows = list(csv.reader(fh))
    except OSError as exc:
        raise InputError(f"{path}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text (CSV) file") from None
    if len(rows) < 2:
        raise InputError(f"{path}: needs a header row and at least one data row")
    header = [h.strip() for h in rows[0]]
    values = np.full((len(rows) - 1, len(header)), np.nan)
    for i, row in enumerate(rows[1:]):
        if len(row) != len(header):
            raise InputError(
                f"{path}: row {i + 2} has {len(row)} cells, the header has {len(header)}"
            )
        for j, cell in enumerate(row):
            cell = cell.strip()
            if cell:
                try:
                    values[i, j] = float(cell)
                except ValueError:
                    raise InputError(
                        f"{path}: row {i + 2}, column {header[j]!r}: {cell!r} is not a number"
                    ) from None
    return header, values


def camera_count(header: Sequence[str], pattern: str, path: Path) -> int:
    """Number of cameras C of columns matching ``pattern`` (group 1: the camera, 1..C)."""
    return len(numbered(header, pattern, "camera", path))


def numbered(header: Sequence[str], pattern: str, what: str, path: Path) -> list[int]:
    """The numbers 1..N that group 1 of ``pattern`` takes in the header (all of them)."""
    found = {int(m.group(1)) for h in header if (m := re.fullmatch(pattern, h))}
    if not found:
        raise InputError(f"{path}: no {what} columns like {pattern!r} in the header")
    if found != set(range(1, max(found) + 1)):
        raise InputError(f"{path}: {what} columns must be numbered 1..N, found {sorted(found)}")
    return sorted(found)


def column(header: Sequence[str], values: FloatArray, name: str, path: Path) -> FloatArray:
    """The values of the column called ``name``."""
    try:
        return values[:, list(header).index(name)]
    except ValueError:
        raise InputError(f"{path}: column {name!r} is missing") from None
