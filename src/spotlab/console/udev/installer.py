"""Plan and install the shipped rules into a rules folder, and optionally reload udev.

Nothing is written unless ``yes`` is true: :func:`install` without it only
reports what it would do. It never runs ``udevadm test`` (on systemd 252 that
applies the rules to the live /dev), and runs ``udevadm control --reload-rules``
and ``udevadm trigger`` only when asked with ``reload=True`` *and* ``yes``.
"""

from __future__ import annotations

import grp
import os
import shlex
import shutil
import subprocess
import tempfile
from collections.abc import Sequence
from pathlib import Path

from spotlab.console.udev.install_result import (
    CommandRun,
    FileAction,
    FileStatus,
    InstallResult,
    PlannedFile,
)
from spotlab.console.udev.shipped import DEFAULT_POLICY, POLICIES, UdevError, policy_rules

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


def plan_install(
    policy: str = DEFAULT_POLICY, target: Path | str = DEFAULT_TARGET
) -> list[PlannedFile]:
    """The files ``spotlab udev install`` writes: ``[(path, content), ...]``.

    Always the classification file plus the one policy file. Reads nothing in
    ``target``; refuses to plan rules that fail :mod:`spotlab.console.udev.rules`.
    """
    target_dir = Path(target)
    return [PlannedFile(target_dir / name, text) for name, text in policy_rules(policy).items()]


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
    _load_rules(result, reload)
    result.next_steps.extend(_policy_notes(policy))
    return result


def _load_rules(result: InstallResult, reload: bool) -> None:
    """Reload udev if asked and possible; otherwise say how to."""
    target = result.target
    reload_line = " && ".join("sudo " + shlex.join(cmd) for cmd in RELOAD_COMMANDS)
    udevadm = shutil.which("udevadm")
    if reload and udevadm and _is_live(target):
        result.commands.extend(_run_reload(udevadm))
        if result.ok:
            result.next_steps.append(
                "udev reloaded; unplug and replug devices if links are missing"
            )
        else:
            result.next_steps.append(f"Load the rules by hand:\n  {reload_line}")
        return
    if reload and not udevadm:
        result.warnings.append("udevadm not found; the rules apply when udev next starts")
    elif reload:
        result.warnings.append(f"{target} is not a folder udev reads; not reloading")
    if _is_live(target):
        result.next_steps.append(
            f"Load the rules now (or unplug and replug the devices):\n  {reload_line}"
        )


def _run_reload(udevadm: str) -> list[CommandRun]:
    """Run :data:`RELOAD_COMMANDS` with this udevadm, stopping at the first failure."""
    runs = []
    for cmd in RELOAD_COMMANDS:
        args = (udevadm, *cmd[1:])
        try:
            done = subprocess.run(
                list(args), check=False, capture_output=True, text=True, timeout=60
            )
        except subprocess.TimeoutExpired:
            runs.append(CommandRun(args, -1, "timed out after 60 s"))
            break
        except OSError as exc:
            runs.append(CommandRun(args, -1, str(exc)))
            break
        runs.append(CommandRun(args, done.returncode, done.stdout + done.stderr))
        if done.returncode != 0:
            break
    return runs


def _policy_of(plan: Sequence[PlannedFile]) -> str | None:
    by_file = {name: policy for policy, name in POLICIES.items()}
    for planned in plan:
        if planned.path.name in by_file:
            return by_file[planned.path.name]
    return None


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
