"""The rules files shipped with spotlab: where they are, which is which, show and check them.

The rules live in the repository's top-level ``udev/`` folder, which the wheel
carries as the data package ``spotlab.udev``. They are found, in this order:

1. ``importlib.resources.files("spotlab.udev")`` (an installed wheel, or an
   editable install made after ``spotlab.udev`` was declared in pyproject.toml);
2. ``<checkout>/udev/`` next to ``src/`` (an editable install made before that).
"""

from __future__ import annotations

import importlib.resources
from collections.abc import Sequence
from importlib.resources.abc import Traversable
from pathlib import Path

from spotlab.console.errors import CommandError
from spotlab.console.udev.rules import RulesFile, parse_file, parse_rules

#: Data package that holds the rules in a wheel (pyproject maps it to ``udev/``).
RULES_PACKAGE = "spotlab.udev"
#: Classifies devices (ID_SPOTLAB, ModemManager, /dev/spotlab links, FTDI latency).
CLASSIFY_FILE = "60-spotlab.rules"
#: Access policy -> the file that implements it. Exactly one is installed.
POLICIES: dict[str, str] = {
    "uaccess": "61-spotlab-uaccess.rules",
    "plugdev": "61-spotlab-plugdev.rules",
}
DEFAULT_POLICY = "uaccess"


class UdevError(CommandError):
    """A user-facing failure of ``spotlab udev`` (message says what to do)."""


def _checkout_rules_dir() -> Path:
    # src/spotlab/console/udev/shipped.py -> parents[4] is the repository root.
    return Path(__file__).resolve().parents[4] / "udev"


def rules_dir() -> Traversable:
    """The folder holding the shipped ``*.rules`` files (package data or checkout)."""
    try:
        packaged: Traversable | None = importlib.resources.files(RULES_PACKAGE)
    except ModuleNotFoundError:
        packaged = None
    if packaged is not None and packaged.joinpath(CLASSIFY_FILE).is_file():
        return packaged
    checkout = _checkout_rules_dir()
    if (checkout / CLASSIFY_FILE).is_file():
        return checkout
    raise UdevError(
        f"the udev rules are missing from this installation (no {CLASSIFY_FILE} in package "
        f"{RULES_PACKAGE} nor in {checkout}); reinstall spotlab"
    )


def shipped_rules() -> dict[str, str]:
    """Every shipped rules file: name -> content, sorted by name (udev's order)."""
    folder = rules_dir()
    names = sorted(
        entry.name
        for entry in folder.iterdir()
        if entry.name.endswith(".rules") and entry.is_file()
    )
    return {name: folder.joinpath(name).read_text(encoding="utf-8") for name in names}


def policy_rules(policy: str) -> dict[str, str]:
    """The classification file and the file of ``policy``: name -> content.

    Refuses an unknown policy, and shipped files that are missing or fail the
    checks of :mod:`spotlab.console.udev.rules`.
    """
    try:
        policy_name = POLICIES[policy]
    except KeyError:
        choices = ", ".join(POLICIES)
        raise UdevError(f"unknown udev policy {policy!r}; choose one of: {choices}") from None
    rules = shipped_rules()
    chosen = {}
    for name in (CLASSIFY_FILE, policy_name):
        if name not in rules:
            raise UdevError(f"{name} is missing from the shipped udev rules; reinstall spotlab")
        checked = parse_rules(rules[name], name)
        if not checked.ok:
            raise UdevError(f"shipped {name} is invalid: {checked.errors[0]}")
        chosen[name] = rules[name]
    return chosen


def show_rules(policy: str | None = None) -> list[tuple[str, str]]:
    """``(name, content)`` of the files ``install --policy`` writes, or of every shipped file."""
    rules = shipped_rules() if policy is None else policy_rules(policy)
    return list(rules.items())


def check_rules(paths: Sequence[Path | str] = ()) -> list[RulesFile]:
    """Validate rules files; with no paths, the shipped ones."""
    if paths:
        results = []
        for path in paths:
            try:
                results.append(parse_file(path))
            except OSError as exc:
                raise UdevError(f"cannot read {path}: {exc.strerror or exc}") from None
            except UnicodeDecodeError:
                raise UdevError(f"cannot read {path}: not UTF-8 text") from None
        return results
    folder = rules_dir()
    return [
        parse_rules(content, str(folder.joinpath(name)))
        for name, content in shipped_rules().items()
    ]
