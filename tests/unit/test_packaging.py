"""The distribution lists every package folder (auto-discovery drops some with package-dir)."""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _declared() -> tuple[list[str], dict[str, str]]:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    setuptools = config["tool"]["setuptools"]
    return setuptools["packages"], setuptools["package-dir"]


def _packages_on_disk(package_dir: dict[str, str]) -> set[str]:
    found = set()
    for package, folder in package_dir.items():
        base = ROOT / folder
        for init in base.rglob("__init__.py"):
            rel = init.parent.relative_to(base)
            if "__pycache__" in rel.parts:
                continue
            name = ".".join((package, *rel.parts)) if rel.parts else package
            found.add(name)
    return found


def test_every_package_folder_is_listed() -> None:
    packages, package_dir = _declared()
    on_disk = _packages_on_disk(package_dir)
    missing = sorted(on_disk - set(packages))
    assert not missing, f"add these to [tool.setuptools] packages in pyproject.toml: {missing}"


def test_every_listed_package_exists() -> None:
    packages, package_dir = _declared()
    on_disk = _packages_on_disk(package_dir)
    assert sorted(set(packages) - on_disk) == []


def test_required_top_level_exists() -> None:
    for name in ("pyproject.toml", "src", "drivers", "tests", "simulators", "udev", "README.md"):
        assert (ROOT / name).exists(), name
