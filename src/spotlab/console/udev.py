"""``spotlab udev``: show, check and install the udev rules shipped with spotlab.

The rules live in the repository's top-level ``udev/`` folder, which the wheel
carries as the data package ``spotlab.udev``. They are found, in this order:

1. ``importlib.resources.files("spotlab.udev")`` (an installed wheel, or an
   editable install made after ``spotlab.udev`` was declared in pyproject.toml);
2. ``<checkout>/udev/`` next to ``src/`` (an editable install made before that).

Nothing is written unless ``yes`` is true: :func:`install` without it only
reports what it would do. It never runs ``udevadm test`` (on systemd 252 that
applies the rules to the live /dev), and runs ``udevadm control --reload-rules``
and ``udevadm trigger`` only when asked with ``reload=True`` *and* ``yes``.

The functions return data (:class:`InstallResult`, :class:`RulesFile`) so that
the command line can print text or JSON; ``add_udev_parser`` and ``run_udev``
are that command line.
"""

from __future__ import annotations

import argparse
import grp
import importlib.resources
import json
import os
import shlex
import shutil
import subprocess
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import Any, Literal, NamedTuple

from spotlab.console.errors import EXIT_FAILURE, EXIT_OK, CommandError
from spotlab.console.udev_rules import RulesFile, parse_file, parse_rules

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
DEFAULT_TARGET = Path("/etc/udev/rules.d")
#: Directories systemd-udevd reads rules from; reload is only run for these.
LIVE_RULES_DIRS: tuple[Path, ...] = (
    Path("/etc/udev/rules.d"),
    Path("/run/udev/rules.d"),
    Path("/usr/local/lib/udev/rules.d"),
    Path("/usr/lib/udev/rules.d"),
    Path("/lib/udev/rules.d"),
)
#: What makes udevd load new rules and apply them to devices already plugged in.
RELOAD_COMMANDS: tuple[tuple[str, ...], ...] = (
    ("udevadm", "control", "--reload-rules"),
    (
        "udevadm",
        "trigger",
        "--action=change",
        "--subsystem-match=usb",
        "--subsystem-match=tty",
        "--subsystem-match=usb-serial",
    ),
)
RULES_FILE_MODE = 0o644

FileStatus = Literal["create", "replace", "unchanged"]


class UdevError(CommandError):
    """A user-facing failure of ``spotlab udev`` (message says what to do)."""


class PlannedFile(NamedTuple):
    """One file :func:`install` would write: ``(path, content)``."""

    path: Path
    content: str


@dataclass(frozen=True)
class FileAction:
    """What happens (or would happen) to one planned file."""

    path: Path
    status: FileStatus
    size: int

    def to_dict(self) -> dict[str, Any]:
        return {"path": str(self.path), "status": self.status, "bytes": self.size}


@dataclass(frozen=True)
class CommandRun:
    """One command run by :func:`install` (only with ``yes`` and ``reload``)."""

    args: tuple[str, ...]
    returncode: int
    output: str

    def to_dict(self) -> dict[str, Any]:
        return {"args": list(self.args), "returncode": self.returncode, "output": self.output}


@dataclass
class InstallResult:
    """Outcome of :func:`install`: enough for text or JSON output."""

    target: Path
    policy: str | None
    written: bool
    writable: bool
    files: list[FileAction]
    warnings: list[str] = field(default_factory=list)
    next_steps: list[str] = field(default_factory=list)
    commands: list[CommandRun] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return all(run.returncode == 0 for run in self.commands)

    @property
    def changed(self) -> list[FileAction]:
        return [f for f in self.files if f.status != "unchanged"]

    def to_dict(self) -> dict[str, Any]:
        return {
            "ok": self.ok,
            "written": self.written,
            "target": str(self.target),
            "policy": self.policy,
            "writable": self.writable,
            "files": [f.to_dict() for f in self.files],
            "warnings": list(self.warnings),
            "next_steps": list(self.next_steps),
            "commands": [c.to_dict() for c in self.commands],
        }

    def to_text(self) -> str:
        policy = f" (policy: {self.policy})" if self.policy else ""
        if self.written:
            head = f"Installed the spotlab udev rules{policy} into {self.target}:"
            verbs = {"create": "created", "replace": "replaced", "unchanged": "unchanged"}
        else:
            head = f"Would install the spotlab udev rules{policy} into {self.target}:"
            verbs = {"create": "create", "replace": "replace", "unchanged": "unchanged"}
        lines = [head]
        for f in self.files:
            lines.append(f"  {verbs[f.status]:<9} {f.path}  ({f.size} bytes)")
        if not self.written:
            lines.append("Nothing was written.")
        lines.extend(f"warning: {w}" for w in self.warnings)
        for run in self.commands:
            state = "ok" if run.returncode == 0 else f"failed with exit code {run.returncode}"
            lines.append(f"ran: {shlex.join(run.args)}: {state}")
            if run.returncode != 0 and run.output:
                lines.append("  " + run.output.strip().replace("\n", "\n  "))
        lines.extend(self.next_steps)
        return "\n".join(lines)


# --------------------------------------------------------------------------- locating the rules


def _checkout_rules_dir() -> Path:
    # src/spotlab/console/udev.py -> parents[3] is the repository root.
    return Path(__file__).resolve().parents[3] / "udev"


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


def _policy_file(policy: str) -> str:
    try:
        return POLICIES[policy]
    except KeyError:
        choices = ", ".join(POLICIES)
        raise UdevError(f"unknown udev policy {policy!r}; choose one of: {choices}") from None


def _policy_of(plan: Sequence[PlannedFile]) -> str | None:
    by_file = {name: policy for policy, name in POLICIES.items()}
    for planned in plan:
        if planned.path.name in by_file:
            return by_file[planned.path.name]
    return None


# --------------------------------------------------------------------------- plan and install


def plan_install(
    policy: str = DEFAULT_POLICY, target: Path | str = DEFAULT_TARGET
) -> list[PlannedFile]:
    """The files ``spotlab udev install`` writes: ``[(path, content), ...]``.

    Always the classification file plus the one policy file. Reads nothing in
    ``target``; refuses to plan rules that fail :mod:`spotlab.console.udev_rules`.
    """
    policy_name = _policy_file(policy)
    rules = shipped_rules()
    target_dir = Path(target)
    plan = []
    for name in (CLASSIFY_FILE, policy_name):
        if name not in rules:
            raise UdevError(f"{name} is missing from the shipped udev rules; reinstall spotlab")
        checked = parse_rules(rules[name], name)
        if not checked.ok:
            raise UdevError(f"shipped {name} is invalid: {checked.errors[0]}")
        plan.append(PlannedFile(target_dir / name, rules[name]))
    return plan


def _status(planned: PlannedFile) -> FileStatus:
    try:
        current = planned.path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return "create"
    except (OSError, UnicodeDecodeError):
        return "replace"
    return "unchanged" if current == planned.content else "replace"


def _writable(folder: Path) -> bool:
    return folder.is_dir() and os.access(folder, os.W_OK | os.X_OK)


def _atomic_write(path: Path, content: str) -> None:
    """Write via a hidden temporary file in the same folder (udev reads only *.rules)."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(content)
            handle.flush()
            os.fchmod(handle.fileno(), RULES_FILE_MODE)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _command_hint(policy: str | None, target: Path, sudo: bool = True) -> str:
    args = ["udev", "install"]
    if policy:
        args += ["--policy", policy]
    if target != DEFAULT_TARGET:
        args += ["--target", str(target)]
    command = shlex.join([*args, "--yes"])
    return f'sudo "$(command -v spotlab)" {command}' if sudo else f"spotlab {command}"


def _is_live(target: Path) -> bool:
    try:
        resolved = target.resolve()
    except OSError:
        return False
    return any(resolved == live.resolve() for live in LIVE_RULES_DIRS)


def _group_exists(name: str) -> bool:
    try:
        grp.getgrnam(name)
    except KeyError:
        return False
    return True


def install(
    plan: Sequence[PlannedFile], yes: bool = False, *, reload: bool = False
) -> InstallResult:
    """Write the planned files if ``yes``; otherwise only report what would be written.

    With ``yes`` and ``reload`` it also runs ``udevadm control --reload-rules``
    and ``udevadm trigger`` (as argument lists, never through a shell), but
    only when udevadm exists and the target is a folder udev reads.
    Raises :class:`UdevError` when the target is missing or not writable.
    """
    if not plan:
        raise UdevError("nothing to install: the plan is empty")
    targets = {p.path.parent for p in plan}
    if len(targets) != 1:
        raise UdevError("all planned files must go into one folder")
    target = targets.pop()
    policy = _policy_of(plan)
    writable = _writable(target)
    result = InstallResult(
        target=target,
        policy=policy,
        written=False,
        writable=writable,
        files=[FileAction(p.path, _status(p), len(p.content.encode())) for p in plan],
    )

    planned_names = {p.path.name for p in plan}
    for other in sorted(set(POLICIES.values()) - planned_names):
        if (target / other).exists():
            result.warnings.append(
                f"{target / other} is also installed; two policies apply at once. "
                f"Remove it: sudo rm {shlex.quote(str(target / other))}"
            )
    if policy == "plugdev" and not _group_exists("plugdev"):
        result.warnings.append(
            'group plugdev does not exist on this machine; udev will ignore GROUP="plugdev". '
            "Create it (sudo groupadd plugdev) or use --policy uaccess"
        )
    if reload and not yes:
        result.warnings.append("--reload does nothing without --yes")

    if not yes:
        if not target.is_dir():
            result.warnings.append(f"{target} does not exist (is udev installed?)")
        how = "run" if writable else "run as root"
        hint = _command_hint(policy, target, sudo=not writable)
        result.next_steps.append(f"To write the files, {how}:\n  {hint}")
        return result

    if not target.is_dir():
        raise UdevError(
            f"{target} does not exist or is not a folder (is udev installed?); "
            "create it first or choose another folder with --target"
        )
    if not writable:
        raise UdevError(
            f"cannot write to {target}: permission denied. Run it as root: "
            f"{_command_hint(policy, target)}"
        )
    for planned, action in zip(plan, result.files, strict=True):
        if action.status == "unchanged":
            continue
        try:
            _atomic_write(planned.path, planned.content)
        except PermissionError:
            raise UdevError(
                f"cannot write {planned.path}: permission denied. Run it as root: "
                f"{_command_hint(policy, target)}"
            ) from None
        except OSError as exc:
            raise UdevError(f"cannot write {planned.path}: {exc.strerror or exc}") from None
    result.written = True

    reload_line = " && ".join("sudo " + shlex.join(cmd) for cmd in RELOAD_COMMANDS)
    udevadm = shutil.which("udevadm")
    if reload and udevadm and _is_live(target):
        for cmd in RELOAD_COMMANDS:
            args = (udevadm, *cmd[1:])
            try:
                done = subprocess.run(
                    list(args),
                    check=False,
                    capture_output=True,
                    text=True,
                    timeout=60,
                )
            except subprocess.TimeoutExpired:
                result.commands.append(CommandRun(args, -1, "timed out after 60 s"))
                break
            except OSError as exc:
                result.commands.append(CommandRun(args, -1, str(exc)))
                break
            result.commands.append(CommandRun(args, done.returncode, done.stdout + done.stderr))
            if done.returncode != 0:
                break
        if result.ok:
            result.next_steps.append(
                "udev reloaded; unplug and replug devices if links are missing"
            )
        else:
            result.next_steps.append(f"Load the rules by hand:\n  {reload_line}")
    else:
        if reload and not udevadm:
            result.warnings.append("udevadm not found; the rules apply when udev next starts")
        elif reload:
            result.warnings.append(f"{target} is not a folder udev reads; not reloading")
        if _is_live(target):
            result.next_steps.append(
                f"Load the rules now (or unplug and replug the devices):\n  {reload_line}"
            )
    result.next_steps.extend(_policy_notes(policy))
    return result


def _policy_notes(policy: str | None) -> list[str]:
    if policy == "uaccess":
        return [
            "Access goes to the user logged in at the local seat. Over SSH or on a headless "
            "PC use --policy plugdev, and add users to dialout for serial ports: "
            'sudo usermod -aG dialout "$USER"'
        ]
    if policy == "plugdev":
        return [
            "Add acquisition users to plugdev (USB devices) and dialout (serial ports), then "
            'log out and in again: sudo usermod -aG plugdev,dialout "$USER"'
        ]
    return []


# --------------------------------------------------------------------------- show and check


def show_rules(policy: str | None = None) -> list[tuple[str, str]]:
    """``(name, content)`` of the files ``install --policy`` writes, or of every shipped file."""
    if policy is None:
        return list(shipped_rules().items())
    return [(p.path.name, p.content) for p in plan_install(policy, DEFAULT_TARGET)]


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


# --------------------------------------------------------------------------- command line


def add_udev_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``udev`` with ``install``, ``show`` and ``check`` to a subparsers object."""
    parser: argparse.ArgumentParser = subparsers.add_parser(
        "udev",
        help="install or check the udev rules for USB-serial adapters and OAK cameras",
        description="udev rules that give the logged-in user (uaccess) or the plugdev group "
        "access to the USB-serial adapters and Luxonis OAK cameras spotlab talks to, keep "
        "ModemManager away from them, set the FTDI latency timer to 1 ms and create "
        "/dev/spotlab/<serial> links. See docs/udev.md.",
    )
    actions = parser.add_subparsers(dest="udev_action", metavar="ACTION")
    actions.required = True

    inst = actions.add_parser(
        "install",
        help="show (or, with --yes, write) the rules files",
        description="Without --yes, only show what would be written. With --yes, write "
        f"{CLASSIFY_FILE} and the policy file into the target folder (needs root for "
        f"{DEFAULT_TARGET}).",
    )
    inst.add_argument(
        "--policy",
        choices=tuple(POLICIES),
        default=DEFAULT_POLICY,
        help="uaccess: the user at the local seat (default); plugdev: members of plugdev",
    )
    inst.add_argument(
        "--target",
        type=Path,
        default=DEFAULT_TARGET,
        metavar="DIR",
        help=f"folder to write into (default {DEFAULT_TARGET})",
    )
    inst.add_argument("--yes", action="store_true", help="really write the files")
    inst.add_argument(
        "--reload",
        action="store_true",
        help="with --yes: also run udevadm control --reload-rules and udevadm trigger",
    )
    inst.add_argument("--json", action="store_true", help="print JSON")

    show = actions.add_parser(
        "show",
        help="print the shipped rules",
        description="Print the shipped rules files; with --policy only the ones that "
        "install --policy writes.",
    )
    show.add_argument("--policy", choices=tuple(POLICIES), default=None)
    show.add_argument("--json", action="store_true", help="print JSON")

    check = actions.add_parser(
        "check",
        help="validate udev rules files strictly",
        description="Check rules files for unknown keys, wrong operators, missing commas, "
        "unbalanced quotes, GOTO without LABEL and world-writable modes. Without FILE, "
        "check the shipped rules. Never runs udevadm.",
    )
    check.add_argument("files", nargs="*", type=Path, metavar="FILE")
    check.add_argument("--strict", action="store_true", help="fail on warnings too")
    check.add_argument("--json", action="store_true", help="print JSON")

    parser.set_defaults(run=run_udev)
    return parser


def run_udev(args: argparse.Namespace) -> int:
    """Run ``spotlab udev ACTION``; returns the exit code."""
    as_json = bool(getattr(args, "json", False))
    try:
        if args.udev_action == "install":
            return _run_install(args, as_json)
        if args.udev_action == "show":
            return _run_show(args, as_json)
        if args.udev_action == "check":
            return _run_check(args, as_json)
    except UdevError as exc:
        if as_json:
            print(json.dumps({"ok": False, "error": str(exc)}))
            return exc.exit_code
        raise
    raise UdevError(f"unknown udev action {args.udev_action!r}")


def _run_install(args: argparse.Namespace, as_json: bool) -> int:
    plan = plan_install(args.policy, args.target)
    result = install(plan, yes=args.yes, reload=args.reload)
    print(json.dumps(result.to_dict()) if as_json else result.to_text())
    return EXIT_OK if result.ok else EXIT_FAILURE


def _run_show(args: argparse.Namespace, as_json: bool) -> int:
    files = show_rules(args.policy)
    if as_json:
        source = str(rules_dir())
        payload = {"source": source, "files": [{"name": n, "content": c} for n, c in files]}
        print(json.dumps(payload))
        return EXIT_OK
    for index, (name, content) in enumerate(files):
        if index:
            print()
        print(f"# ==> {name} <==")
        print(content, end="" if content.endswith("\n") else "\n")
    return EXIT_OK


def _run_check(args: argparse.Namespace, as_json: bool) -> int:
    results = check_rules(args.files)
    failed = any(not r.ok or (args.strict and r.warnings) for r in results)
    if as_json:
        print(json.dumps({"ok": not failed, "files": [r.to_dict() for r in results]}))
        return EXIT_FAILURE if failed else EXIT_OK
    for r in results:
        for issue in r.issues:
            print(issue)
        state = "ok" if r.ok and not (args.strict and r.warnings) else "FAILED"
        print(
            f"{r.path}: {len(r.rules)} rules, {len(r.errors)} errors, "
            f"{len(r.warnings)} warnings: {state}"
        )
    return EXIT_FAILURE if failed else EXIT_OK
