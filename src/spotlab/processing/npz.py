"""Reading the npz files commands take as input, with errors that name the cause."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from spotlab.processing.errors import InputError

__all__ = ["number", "numeric_array", "read_npz"]


def read_npz(path: Path) -> dict[str, NDArray[np.generic]]:
    """Every array of an npz file, never unpickling anything.

    Raises
    ------
    InputError
        The file is not an npz archive, or it holds object arrays (pickled Python
        objects, which spotlab does not load: they can run code).
    """
    arrays: dict[str, NDArray[np.generic]] = {}
    try:
        with np.load(path, allow_pickle=False) as data:
            for name in data.files:
                try:
                    arrays[name] = data[name]
                except ValueError as exc:
                    if "pickle" not in str(exc):
                        raise
                    raise InputError(
                        f"{path}: array {name!r} holds Python objects (pickled), which "
                        "spotlab does not load; save it as numbers or strings"
                    ) from None
    except InputError:
        raise
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise InputError(f"{path}: not a readable npz file ({exc})") from None
    return arrays


def numeric_array(path: Path, name: str, array: NDArray[np.generic]) -> NDArray[np.float64]:
    """``array`` as float64, or a InputError naming the array that is not numeric."""
    if array.dtype.kind not in "biuf":
        raise InputError(f"{path}: array {name!r} must hold numbers, not {array.dtype.name} values")
    return np.asarray(array, dtype=np.float64)


def number(path: Path, name: str, array: NDArray[np.generic]) -> float:
    """The one number held by ``array``, or a InputError naming it."""
    values = numeric_array(path, name, array)
    if values.size != 1:
        raise InputError(f"{path}: {name!r} must be one number, not {values.size} values")
    return float(values.ravel()[0])
