"""The scenarios shipped with spotlab (package data, ``spotlab/hil/scenarios/*.toml``)."""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path

from spotlab.core.errors import ConfigurationError


def shipped() -> dict[str, Path]:
    """Name (file stem) -> path of every shipped scenario, sorted by name."""
    folder = Path(str(resources.files("spotlab.hil") / "scenarios"))
    return {p.stem: p for p in sorted(folder.glob("*.toml"))}


def describe(path: Path) -> tuple[str, float, str]:
    """``(name, duration_s, description)`` of a scenario file, read without checking it."""
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    return (
        str(data.get("name", path.stem)),
        float(data.get("duration", 0)),
        str(data.get("description", "")),
    )


def resolve(name_or_path: str) -> Path:
    """A scenario file by path, or by the name of a shipped one.

    Raises
    ------
    ConfigurationError
        If it is neither a file nor a shipped scenario's name.
    """
    path = Path(name_or_path)
    if path.is_file():
        return path
    found = shipped().get(name_or_path.removesuffix(".toml"))
    if found is None:
        raise ConfigurationError(
            f"{name_or_path}: no such scenario file, nor a shipped scenario "
            f"({', '.join(shipped())})"
        )
    return found


__all__ = ["describe", "resolve", "shipped"]
