"""Output files checked before a command does its work: a bad path is one clear error,
and nothing is half-written."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from spotlab.console.errors import CommandError

__all__ = ["check_output_paths"]


def check_output_paths(paths: Sequence[tuple[str, Path]]) -> None:
    """Refuse outputs that cannot be written, before any of them is.

    Parameters
    ----------
    paths : sequence of (str, Path)
        The option that names each output (``"--out"``) and the file.

    Raises
    ------
    CommandError
        Naming the option and the cause: the file is a folder, its folder does not
        exist or is a file, the folder or the file is not writable, or two outputs
        are one file.
    """
    seen: dict[Path, str] = {}
    for option, path in paths:
        parent = path.parent
        if path.is_dir():
            raise CommandError(f"{option} {path}: is a folder, not a file")
        if parent.exists() and not parent.is_dir():
            raise CommandError(f"{option} {path}: {parent} is a file, not a folder")
        if not parent.is_dir():
            raise CommandError(f"{option} {path}: the folder {parent} does not exist")
        if not os.access(parent, os.W_OK | os.X_OK):
            raise CommandError(f"{option} {path}: cannot write in the folder {parent}")
        if path.exists() and not os.access(path, os.W_OK):
            raise CommandError(f"{option} {path}: the file is not writable")
        key = path.resolve()
        if key in seen:
            raise CommandError(f"{option} {path}: the same file as {seen[key]}")
        seen[key] = option
