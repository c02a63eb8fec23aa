"""What ``spotlab udev install`` plans and what it did, as data for text or JSON output."""

from __future__ import annotations

import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, NamedTuple

FileStatus = Literal["create", "replace", "unchanged"]


class PlannedFile(NamedTuple):
    """One file :func:`~.installer.install` would write: ``(path, content)``."""

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
    """One command run by :func:`~.installer.install` (only with ``yes`` and ``reload``)."""

    args: tuple[str, ...]
    returncode: int
    output: str

    def to_dict(self) -> dict[str, Any]:
        return {"args": list(self.args), "returncode": self.returncode, "output": self.output}


@dataclass
class InstallResult:
    """Outcome of :func:`~.installer.install`: enough for text or JSON output."""

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
