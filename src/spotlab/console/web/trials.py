"""Trials of the web console on disk: ``DATA/SUBJECT/SESSION/TRIAL.spj`` and a sidecar.

Every trial is a journal written by :class:`~spotlab.acquisition.recorder.Recorder`
and a small JSON sidecar beside it (``TRIAL.json``: names, notes, start time, duration,
frames, lost frames, state). Names are checked against ``[A-Za-z0-9_-]{1,64}``, so no
path made here leaves the data folder; :meth:`TrialStore.resolve` checks it again.
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from spotlab.processing.errors import InputError

__all__ = ["NAME_RE", "TrialInfo", "TrialStore", "check_name", "trial_id"]

#: What a subject, session or trial name may hold.
NAME_RE = re.compile(r"[A-Za-z0-9_-]{1,64}")

#: States a trial's sidecar gives.
STATES = ("recording", "done", "interrupted", "failed")


def check_name(kind: str, value: object) -> str:
    """``value`` if it is a valid name, else InputError naming ``kind``.

    Parameters
    ----------
    kind : str
        What the name is for (``subject``, ``session``, ``trial``), used in the message.
    value : object
        The name given (from a request body: any JSON value).
    """
    if not isinstance(value, str) or NAME_RE.fullmatch(value) is None:
        raise InputError(
            f"{kind} name {value!r} is not valid: use 1-64 letters, digits, '_' or '-'"
        )
    return value


def trial_id(subject: str, session: str, trial: str) -> str:
    """The id of a trial in the API: ``SUBJECT.SESSION.TRIAL`` (names hold no dot)."""
    return f"{subject}.{session}.{trial}"


@dataclass
class TrialInfo:
    """What a trial's sidecar holds.

    Attributes
    ----------
    subject, session, trial : str
        The names.
    notes : str
        The operator's notes.
    started_at : str
        Start, ISO 8601 UTC.
    duration_s : float
        Recorded time, s (so far, while recording).
    frames : dict of str to int
        Frames per stream (from the journal once stopped; live counts while recording).
    lost : dict of str to int
        Lost frames per stream.
    state : str
        One of ``recording``, ``done``, ``interrupted``, ``failed``.
    messages : list of str
        What the operator should know (a device that dropped out, a failed start).
    exports : list of str
        Files exported, relative to the data folder.
    processing : dict or None
        The last processing from the page (``path``, ``quality``, ``rig``), if any.
    """

    subject: str
    session: str
    trial: str
    notes: str = ""
    started_at: str = ""
    duration_s: float = 0.0
    frames: dict[str, int] = field(default_factory=dict)
    lost: dict[str, int] = field(default_factory=dict)
    state: str = "recording"
    messages: list[str] = field(default_factory=list)
    exports: list[str] = field(default_factory=list)
    processing: dict[str, Any] | None = None

    @property
    def id(self) -> str:
        """The trial's id in the API."""
        return trial_id(self.subject, self.session, self.trial)

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe form, with the id and the journal's path in the data folder."""
        out = asdict(self)
        out["id"] = self.id
        out["journal"] = f"{self.subject}/{self.session}/{self.trial}.spj"
        return out


class TrialStore:
    """The trials under one data folder.

    Parameters
    ----------
    root : Path
        The data folder (made if missing).
    """

    def __init__(self, root: Path) -> None:
        root.mkdir(parents=True, exist_ok=True)
        self.root = root.resolve()

    def resolve(self, *parts: str) -> Path:
        """``root/parts...``, refused (InputError) if it would leave the data folder."""
        path = self.root.joinpath(*parts).resolve()
        if path != self.root and self.root not in path.parents:
            raise InputError(f"{'/'.join(parts)} is outside the data folder")
        return path

    def journal(self, subject: str, session: str, trial: str) -> Path:
        """Path of a trial's journal (names checked)."""
        names = (
            check_name("subject", subject),
            check_name("session", session),
            check_name("trial", trial),
        )
        return self.resolve(names[0], names[1], f"{names[2]}.spj")

    def parse_id(self, tid: str) -> tuple[str, str, str]:
        """(subject, session, trial) of an id, checked; InputError if malformed."""
        parts = tid.split(".")
        if len(parts) != 3:
            raise InputError(f"trial id {tid!r} is not SUBJECT.SESSION.TRIAL")
        return (
            check_name("subject", parts[0]),
            check_name("session", parts[1]),
            check_name("trial", parts[2]),
        )

    def sidecar(self, journal: Path) -> Path:
        """The sidecar of a journal: the same name, ``.json``."""
        return journal.with_suffix(".json")

    def save(self, info: TrialInfo) -> None:
        """Write the sidecar (atomically: a temporary file renamed)."""
        path = self.sidecar(self.journal(info.subject, info.session, info.trial))
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(info.to_dict(), indent=1) + "\n", encoding="utf-8")
        os.replace(tmp, path)

    def load(self, tid: str) -> TrialInfo:
        """The trial of an id; InputError if there is none."""
        subject, session, trial = self.parse_id(tid)
        path = self.sidecar(self.journal(subject, session, trial))
        if not path.is_file():
            raise InputError(f"no trial {tid}")
        raw = json.loads(path.read_text(encoding="utf-8"))
        known = {k: raw[k] for k in TrialInfo.__dataclass_fields__ if k in raw}
        return TrialInfo(**known)

    def all(self) -> list[TrialInfo]:
        """Every trial of the data folder, oldest first."""
        out = []
        for path in self.root.glob("*/*/*.json"):
            rel = path.relative_to(self.root).parts
            if not all(NAME_RE.fullmatch(p) for p in (rel[0], rel[1], path.stem)):
                continue
            try:
                out.append(self.load(trial_id(rel[0], rel[1], path.stem)))
            except (InputError, ValueError, TypeError, OSError):
                continue
        return sorted(out, key=lambda t: (t.started_at, t.id))
