"""Processing of recorded trials from the page, in a worker thread of its own.

"Process" reconstructs a trial as ``spotlab reconstruct`` / ``spotlab export`` would,
through the processing layer: a recording whose streams are all ``blobs2d`` (a
video-centroid hub) is identified with the lab's marker model (or the one stored in the
recording) by :func:`spotlab.processing.reconstruct_file`; any other recording has its
``image2d`` streams (SELSPOT-style cameras) triangulated with the lab's rig by
:func:`spotlab.processing.reconstruct_recording` (on session time when it holds a timer
stream). Both with the rig of the trial's session (``rig.toml``, accepted there in the
calibration wizard) or else the lab's.

One trial is processed at a time, in a daemon thread niced below the acquisition's
threads (Linux: a thread's own nice value); nothing of the acquisition waits for it.
Its progress comes from a :class:`~spotlab.processing.progress.ProgressSink` and is
read by the API (:meth:`Processor.job`). The quality numbers of the result are kept in
the trial's sidecar (``processing``) and the trajectories in memory, for the export.
"""

from __future__ import annotations

import json
import os
import queue
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab import processing
from spotlab.console.web.trials import TrialInfo, TrialStore
from spotlab.processing.errors import InputError
from spotlab.processing.progress import ProgressSink
from spotlab.processing.trajectories import Reconstruction

__all__ = ["ProcessJob", "Processor", "gap_counts", "quality"]

#: Nice value of the processing thread (higher: less CPU when the acquisition needs it).
NICE = 10

#: Summary keys the page shows, in this order (those the result has).
QUALITY_KEYS = (
    "frames",
    "markers",
    "cameras",
    "rate_hz",
    "method",
    "reconstructed_fraction",
    "labelled_fraction",
    "markers_reconstructed",
    "rms_ray_px",
    "rms_ray_px_per_camera",
    "lost_frames",
    "ghosts_rejected",
    "marker_gaps",
)


@dataclass
class ProcessJob:
    """The state of one trial's processing, as the API gives it.

    Attributes
    ----------
    trial : str
        The trial's id.
    state : str
        ``running``, ``done`` or ``failed``.
    path : str
        ``triangulation`` (``image2d`` streams and the rig) or ``identification``
        (video-centroid blobs and a marker model); empty until chosen.
    stage : str
        The step under way (``reconstructing``, ``identifying``) or ``""``.
    done, total : float
        Frames done of the stage's total.
    detail : str
        The stage's own words on its progress.
    elapsed_s : float
        Time since the start (to the end once finished), s.
    quality : dict or None
        The quality numbers of the result (:func:`quality`), once done.
    notes : list of str
        What the processing layer says the user should know.
    error : str or None
        Why it failed.
    """

    trial: str
    state: str = "running"
    path: str = ""
    stage: str = ""
    done: float = 0.0
    total: float = 0.0
    detail: str = ""
    elapsed_s: float = 0.0
    quality: dict[str, Any] | None = None
    notes: list[str] = field(default_factory=list)
    error: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe form, with ``fraction`` (0-1) of the stage under way."""
        out = asdict(self)
        out["fraction"] = min(1.0, self.done / self.total) if self.total > 0 else 0.0
        return out


class _Sink:
    """A :class:`ProgressSink` writing into a job (under the processor's lock)."""

    def __init__(self, job: ProcessJob, lock: threading.Lock, label: str, total: float) -> None:
        self.job, self.lock = job, lock
        with lock:
            job.stage, job.total, job.done, job.detail = label, float(total), 0.0, ""

    def update(self, done: float, detail: str = "") -> None:
        with self.lock:
            self.job.done, self.job.detail = float(done), detail

    def close(self) -> None:
        with self.lock:
            self.job.done = self.job.total


def gap_counts(points: NDArray[np.float64]) -> dict[str, int]:
    """Gaps of trajectories (F, M, 3) mm, NaN where not seen.

    Returns
    -------
    dict
        ``gaps``: runs of missing frames between a marker's first and last frame seen,
        all markers; ``longest_gap_frames``: the longest such run; ``markers_never_seen``.
    """
    seen = np.isfinite(points[..., 0]) if points.size else np.zeros((0, 0), dtype=bool)
    gaps, longest = 0, 0
    for m in range(seen.shape[1]):
        frames = np.flatnonzero(seen[:, m])
        if frames.size < 2:
            continue
        steps = np.diff(frames) - 1  # missing frames between two seen ones
        holes = steps[steps > 0]
        gaps += int(holes.size)
        longest = max(longest, int(holes.max()) if holes.size else 0)
    never = int((~seen.any(axis=0)).sum()) if seen.size else int(seen.shape[1])
    return {"gaps": gaps, "longest_gap_frames": longest, "markers_never_seen": never}


def _json_safe(value: Any) -> Any:
    return json.loads(json.dumps(value, default=lambda v: getattr(v, "tolist", str)()))


def quality(result: Reconstruction) -> dict[str, Any]:
    """The quality numbers of a reconstruction: :data:`QUALITY_KEYS` of its summary
    that it has, and :func:`gap_counts` of its trajectories (JSON-safe)."""
    out = {k: result.summary[k] for k in QUALITY_KEYS if k in result.summary}
    out.update(gap_counts(np.asarray(result.trial.points, dtype=float)))
    return dict(_json_safe(out))


def _stamp(rig: Path) -> tuple[str, int]:
    """A rig file's path and modification time (ns; 0 if it cannot be read)."""
    try:
        return str(rig), rig.stat().st_mtime_ns
    except OSError:
        return str(rig), 0


class Processor:
    """Processes trials of a data folder, one at a time, in a daemon thread.

    Parameters
    ----------
    store : TrialStore
        The data folder.
    rig : Path or None
        The lab's current rig (:attr:`rig` may be changed later).
    model : Path or None
        The lab's marker model (video-centroid trials), if it names one.
    lab : Path
        The lab file (named in errors).
    """

    def __init__(self, store: TrialStore, rig: Path | None, model: Path | None, lab: Path):
        self.store, self.rig, self.model, self.lab = store, rig, model, lab
        #: Guards the jobs, the results and sidecar updates made here.
        self.lock = threading.Lock()
        self._jobs: dict[str, ProcessJob] = {}
        self._results: dict[str, Reconstruction] = {}
        self._rig_used: dict[str, tuple[str, int]] = {}  # trial -> (rig, its mtime_ns)
        self._started: dict[str, float] = {}
        self._queue: queue.Queue[tuple[TrialInfo, ProcessJob] | None] = queue.Queue()
        self._thread = threading.Thread(target=self._work, name="console-process", daemon=True)
        self._thread.start()

    def submit(self, info: TrialInfo) -> ProcessJob:
        """Queue ``info`` for processing; InputError if it is being recorded or
        processed, or if the lab has no rig."""
        if info.state in ("recording", "failed"):
            raise InputError(
                f"trial {info.id} is being recorded: stop it first"
                if info.state == "recording"
                else f"trial {info.id} failed: it holds no recording"
            )
        if self.rig_for(info) is None:
            raise InputError(f"lab file {self.lab} names no rig: a trial is processed with one")
        with self.lock:
            old = self._jobs.get(info.id)
            if old is not None and old.state == "running":
                raise InputError(f"trial {info.id} is being processed")
            job = self._jobs[info.id] = ProcessJob(info.id)
            self._started[info.id] = time.monotonic()
            self._results.pop(info.id, None)
        self._queue.put((info, job))
        return job

    def rig_for(self, info: TrialInfo) -> Path | None:
        """The rig of a trial: its session folder's ``rig.toml`` (accepted in the
        calibration wizard) when there is one, else the lab's."""
        accepted = self.store.resolve(info.subject, info.session, "rig.toml")
        return accepted if accepted.is_file() else self.rig

    def job(self, tid: str) -> dict[str, Any] | None:
        """The job of a trial (JSON-safe), or None if it was not processed here."""
        with self.lock:
            job = self._jobs.get(tid)
            if job is None:
                return None
            if job.state == "running":
                job.elapsed_s = round(time.monotonic() - self._started[tid], 3)
            return job.to_dict()

    def result(self, info: TrialInfo) -> Reconstruction | None:
        """The reconstruction of a trial processed here, if done and made with the rig
        the trial would be processed with now (not one replaced since)."""
        rig = self.rig_for(info)
        now = _stamp(rig) if rig is not None else None
        with self.lock:
            if now is None or self._rig_used.get(info.id) != now:
                return None
            return self._results.get(info.id)

    def close(self) -> None:
        """Let the worker end after the job under way (it is a daemon thread)."""
        self._queue.put(None)

    def _work(self) -> None:
        try:  # this thread alone, on Linux (a thread is a task with its own nice value)
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), NICE)
        except (OSError, AttributeError):
            pass
        while (item := self._queue.get()) is not None:
            self._one(*item)

    def _one(self, info: TrialInfo, job: ProcessJob) -> None:
        def factory(label: str, total: float) -> ProgressSink:
            return _Sink(job, self.lock, label, total)

        try:
            result = self._reconstruct(info, job, factory)
            numbers = quality(result)
        except Exception as exc:  # an input or numerics error, told to the page
            with self.lock:
                job.state, job.error = "failed", str(exc) or type(exc).__name__
                job.elapsed_s = round(time.monotonic() - self._started[info.id], 3)
            return
        with self.lock:
            job.quality, job.notes = numbers, list(result.notes)
            job.elapsed_s = round(time.monotonic() - self._started[info.id], 3)
            self._results[info.id] = result
            try:
                saved = self.store.load(info.id)
                rig = str(self.rig_for(info))
                saved.processing = {"path": job.path, "quality": numbers, "rig": rig}
                self.store.save(saved)
            except (InputError, OSError, ValueError) as exc:
                job.notes.append(f"the sidecar could not be updated: {exc}")
            job.state, job.stage = "done", ""

    def _reconstruct(self, info: TrialInfo, job: ProcessJob, factory: Any) -> Reconstruction:
        journal = self.store.journal(info.subject, info.session, info.trial)
        rig = self.rig_for(info)
        if rig is None:
            raise InputError(f"lab file {self.lab} names no rig")
        used = _stamp(rig)
        with self.lock:
            self._rig_used[info.id] = used
        if processing.is_blob_recording(journal):
            with self.lock:
                job.path = "identification"
            return processing.reconstruct_file(journal, rig, model=self.model, progress=factory)
        with self.lock:
            job.path = "triangulation"
        return processing.reconstruct_recording(journal, rig, progress=factory)
