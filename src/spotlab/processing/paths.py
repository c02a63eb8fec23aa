"""Checks of the files a command will write, made before any work starts.

A command that fails on its last output after minutes of work, or leaves half its
outputs behind, wastes the user's time: every command checks all its output paths
first with :func:`check_output_paths` and fails with one line naming the option.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from spotlab.processing.errors import InputError

__all__ = ["check_output_dir", "check_output_paths"]


def _folder_problem(folder: Path) -> str | None:
    """Why files cannot be created in ``folder``, or None when they can."""
    folder = folder if str(folder) else Path(".")
    if folder.is_dir():
        if not os.access(folder, os.W_OK | os.X_OK):
            return f"the folder {folder} is not writable"
        return None
    # Name the first part of the path that is in the way.
    for part in [folder, *folder.parents]:
        if part.exists() and not part.is_dir():
            return f"{part} is a file, not a folder"
    return f"the folder {folder} does not exist"


def check_output_paths(outputs: Iterable[tuple[str, Path | None]]) -> None:
    """Refuse output files that cannot be written, before any work is done.

    Parameters
    ----------
    outputs : iterable of (str, Path or None)
        ``(option, path)`` pairs, for example ``("--out", Path("rig.toml"))``; a
        ``None`` path (option not given) is skipped.

    Raises
    ------
    InputError
        Naming the option and the path: the path is a folder, its folder does not
        exist, a part of it is a regular file, the folder or the file is not writable,
        or two outputs are one file.
    """
    seen: dict[Path, str] = {}
    for option, path in outputs:
        if path is None:
            continue
        if path.is_dir():
            raise InputError(f"{option} {path}: is a folder, not a file")
        problem = _folder_problem(path.parent)
        if problem is not None:
            raise InputError(f"{option} {path}: {problem}")
        if path.exists() and not os.access(path, os.W_OK):
            raise InputError(f"{option} {path}: the file is not writable")
        key = path.resolve()
        if key in seen:
            raise InputError(f"{option} {path}: the same file as {seen[key]}")
        seen[key] = option


def check_output_dir(option: str, folder: Path) -> None:
    """Refuse an output folder that cannot be created or written (it may not exist yet).

    Raises
    ------
    InputError
        When ``folder`` or one of its parents is a regular file, or the nearest existing
        parent is not writable.
    """
    for part in [folder, *folder.parents]:
        if part.exists():
            if not part.is_dir():
                raise InputError(f"{option} {folder}: {part} is a file, not a folder")
            if not os.access(part, os.W_OK | os.X_OK):
                raise InputError(f"{option} {folder}: the folder {part} is not writable")
            return
