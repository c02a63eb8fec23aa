"""The console's acquisition: the lab's devices in a session, previewing or recording.

One thread (``spotlab-console-acq``) runs one :class:`~spotlab.acquisition.session.Session`
at a time: a preview session (view sink and live pipeline only) while nothing is
recorded, a recording session (the same plus a :class:`Recorder` of the trial's journal)
while a trial runs. Starting or stopping a trial ends one session and starts the next
with new driver objects, so each trial's journal is what ``spotlab record`` writes for
the same devices: start-up dialogue, every byte, the stop. The web side only flips the
wanted state and reads what the sinks keep; it never blocks a reader thread.

A device whose port is a path that does not exist is left out of the session, shown as
not connected with the reason, and reported once on stderr; the preview is restarted
when it appears.
"""

from __future__ import annotations

import math
import sys
import threading
import time
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from spotlab.acquisition.live import LivePipeline
from spotlab.acquisition.recorder import Recorder
from spotlab.acquisition.session import Session
from spotlab.acquisition.summary import summarize
from spotlab.console.device_settings import FAMILY_SETTINGS
from spotlab.console.web.lab_setup import LabPlan, settings_of
from spotlab.console.web.live_view import MarkerSlot, ViewSink
from spotlab.console.web.trials import TrialInfo, TrialStore
from spotlab.drivers import Driver
from spotlab.geometry import Rig
from spotlab.processing.decoding import decoder_for
from spotlab.processing.errors import InputError

__all__ = ["Acquisition"]

#: Seconds between tries to start a session that failed, or to find a missing port.
RETRY_S = 3.0
#: A device with no frame for this long is shown as not connected.
STALE_S = 1.5


def _warn(message: str) -> None:
    print(f"spotlab: warning: {message}", file=sys.stderr, flush=True)


def _port_missing(port: str) -> bool:
    return "://" not in port and not Path(port).exists()


class Acquisition:
    """The lab's devices, previewed or recorded into trials.

    Parameters
    ----------
    plan : LabPlan
        The lab.
    store : TrialStore
        Where trials go.
    warn : callable
        Takes one line for the operator (default: ``spotlab: warning: ...`` on stderr).
    realtime_priority : int, optional
        The sessions' threads under ``SCHED_FIFO`` at this priority where the system
        allows it (``Session``'s option; a refusal is told once). Default: normal.
    """

    def __init__(
        self,
        plan: LabPlan,
        store: TrialStore,
        warn: Callable[[str], None] = _warn,
        *,
        realtime_priority: int | None = None,
    ) -> None:
        self.plan = plan
        self.realtime_priority = realtime_priority
        self.store = store
        self._warn = warn
        self._warned: set[str] = set()
        self._reconnect_asked: dict[str, float] = {}  # device -> monotonic s of the ask
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._closed = False
        self._wanted: TrialInfo | None = None  # the trial to record, None: preview
        self._seconds: float | None = None
        self.trial: TrialInfo | None = None  # the trial being recorded
        self._active: TrialInfo | None = None  # the trial taken up, until its sidecar is final
        self.finished = threading.Condition(self._lock)
        self.drivers: list[Driver] = []
        self.missing: dict[str, str] = {}
        self.errors: dict[str, str] = {}  # stream (or "lab") -> last error in words
        self.view = ViewSink()
        self.markers = MarkerSlot()
        self.live_note: str | None = None
        self.rig_cameras: list[dict[str, Any]] = []  # for the 3-D view
        self.live: LivePipeline | None = None
        self.session: Session | None = None
        self.started_at = time.time()
        self._thread = threading.Thread(target=self._run, name="spotlab-console-acq", daemon=True)

    # ---- control (any thread) -------------------------------------------------------
    def start(self) -> None:
        """Start the acquisition thread (preview)."""
        self._thread.start()

    def close(self, timeout: float = 15.0) -> None:
        """End the running session (a trial is finished as stopped) and the thread."""
        with self._lock:
            self._closed = True
            self._wanted = None
        self._wake.set()
        self._thread.join(timeout)

    def start_trial(self, info: TrialInfo, seconds: float | None = None) -> TrialInfo:
        """Record ``info`` (names checked, journal new); returns it. InputError if a trial
        runs, the names are taken or ``seconds`` is not positive."""
        journal = self.store.journal(info.subject, info.session, info.trial)
        if seconds is not None and not seconds > 0:
            raise InputError(f"seconds must be positive, got {seconds}")
        with self._lock:
            if self._wanted is not None or self._active is not None:
                raise InputError("a trial is being recorded: stop it first")
            if journal.exists() or self.store.sidecar(journal).exists():
                raise InputError(f"trial {info.id} exists: choose another trial name")
            info.started_at = datetime.now(UTC).isoformat(timespec="milliseconds")
            info.state = "recording"
            self.store.save(info)
            self._wanted, self._seconds = info, seconds
        self._wake.set()
        return info

    def restart(self, plan: LabPlan | None = None) -> None:
        """Start the preview again with new driver objects (every device reconnects,
        start-up dialogue included), of ``plan`` when given. InputError while a trial is
        being recorded."""
        with self._lock:
            if self._wanted is not None or self._active is not None:
                raise InputError("a trial is being recorded: stop it first")
            if plan is not None:
                self.plan = plan
        self._wake.set()

    def reconnect(self, name: str) -> str:
        """Reconnect device ``name``: ``"device"`` when it reconnects alone in the running
        session (an MCS-1 driver: the others keep streaming, a trial being recorded goes
        on and its journal marks the outage), ``"session"`` when the preview starts
        again with new driver objects instead (no session runs, or the driver cannot
        reconnect alone). InputError for no such device, or for a session restart while
        a trial is being recorded."""
        session = self.session
        driver = next((d for d in self.drivers if d.name == name), None)
        if name not in self.plan.names():
            raise InputError(f"no device {name!r} in the lab")
        ask = getattr(driver, "request_reconnect", None)
        if session is not None and driver in session.devices and callable(ask):
            self._reconnect_asked[name] = time.monotonic()
            ask("reconnect asked from the console")
            self.errors.pop(name, None)
            return "device"
        self.restart()
        return "session"

    def stop_trial(self, timeout: float = 20.0) -> TrialInfo:
        """Stop the trial being recorded and wait until its sidecar is final."""
        with self._lock:
            info = self._wanted or self._active
            if info is None:
                raise InputError("no trial is being recorded")
            self._wanted = None
            if self._active is not info:  # not taken up by the acquisition thread yet
                info.state = "failed"
                info.messages.append("stopped before the devices started")
                self.store.save(info)
                return info
        self._wake.set()
        deadline = time.monotonic() + timeout
        with self.finished:
            while self._active is info or self._wanted is info:
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                self.finished.wait(left)
        return self.store.load(info.id)

    # ---- what the page shows ----------------------------------------------------------
    def devices(self) -> list[dict[str, Any]]:
        """One row per device of the lab (JSON-safe)."""
        rows = []
        session = self.session
        trial = self.trial
        kept = "" if trial is None else f" (trial {trial.id} keeps what arrived)"
        plan = self.plan
        given = {n: settings_of(plan, n) for n in plan.names()}
        for driver in list(self.drivers):
            name = driver.name
            stats = driver.stats.as_dict()
            age = self.view.last_arrival_s(name)
            clock = self.view.clocks.get(name)
            offset = None if clock is None else clock.offset_s
            drift = None if clock is None else clock.drift_ppm
            running = session is not None and name not in self.missing
            rate = None
            try:
                rate = float(driver.spec.rate_hz) if running else None
            except Exception:  # a spec the device has not given yet
                rate = None
            rows.append(
                {
                    "name": name,
                    "family": driver.family,
                    "port": driver.port,
                    "connected": bool(running and age is not None and age < STALE_S),
                    "rate_hz": rate,
                    "frames": stats["frames"],
                    "lost_frames": stats["lost_frames"],
                    "crc_errors": stats["crc_errors"],
                    "resyncs": stats["resyncs"],
                    "reconnects": stats["reconnects"],
                    "rate_settable": "rate" in FAMILY_SETTINGS.get(driver.family, {}),
                    # the family's settings (key: what it is) and those the device is given
                    "settings": {
                        key: what
                        for key, (_, _, what) in FAMILY_SETTINGS.get(driver.family, {}).items()
                    },
                    "set": given.get(name, {}),
                    "clock_offset_s": None if offset is None else round(offset, 6),
                    "clock_drift_ppm": None if drift is None else round(drift, 1),
                    "last_error": self.missing.get(name)
                    or self.errors.get(name)
                    or (
                        f"no frame for {age:.1f} s{kept}"
                        if running and age is not None and age >= STALE_S
                        else None
                    ),
                }
            )
        return rows

    def status(self) -> dict[str, Any]:
        """The console's state (JSON-safe)."""
        trial = self.trial
        return {
            "lab": str(self.plan.lab.path),
            "simulated": self.plan.simulated,
            "rig": None if self.plan.lab.rig is None else str(self.plan.lab.rig),
            "data": str(self.store.root),
            "mode": "recording" if trial is not None else "preview",
            "trial": None if trial is None else trial.to_dict(),
            "uptime_s": round(time.time() - self.started_at, 1),
            "live_3d": self.live_note or "on",
            "cameras": self.rig_cameras,
            "errors": dict(self.errors),
        }

    def live_latency(self) -> dict[str, Any] | None:
        """The live pipeline's host latency in the running session (frames, p50_us,
        p99_us, max_us, mean_us, over_1ms; docs/live.md), None without one."""
        live = self.live
        if live is None or self.session is None or self.live_note:
            return None
        summary = live.stats().latency
        if summary.frames == 0:  # a session just started: no figures yet (NaN)
            return None
        out: dict[str, Any] = {}
        for key in summary.__dataclass_fields__:
            value = getattr(summary, key)
            out[key] = None if isinstance(value, float) and not math.isfinite(value) else value
        return out

    # ---- the acquisition thread -------------------------------------------------------
    def _note(self, key: str, message: str) -> None:
        self.errors[key] = message
        if message not in self._warned:
            self._warned.add(message)
            self._warn(message)

    def _run(self) -> None:
        while True:
            with self._lock:
                if self._closed:
                    return
                # cleared under the lock: a stop that changes _wanted after this wakes us
                self._wake.clear()
                wanted, seconds = self._wanted, self._seconds
                self._active = wanted
            self._one_session(wanted, seconds)
            if wanted is None and self.session is None:
                self._wake.wait(RETRY_S)

    def _sinks(self, live: bool) -> tuple[list[Any], str | None]:
        sinks: list[Any] = [self.view]
        rig_path = self.plan.lab.rig
        if not live:
            return sinks, "off"
        if rig_path is None:
            return sinks, "off: the lab file names no rig"
        try:
            rig = Rig.load(rig_path)
        except Exception as exc:  # told to the operator, preview goes on
            return sinks, f"off: rig {rig_path}: {exc}"
        self.rig_cameras = [
            {
                "name": name,
                "center": [round(float(v), 1) for v in cam.center],
                "axis": [round(float(v), 4) for v in cam.R[2]],  # optical axis, world
            }
            for name, cam in zip(rig.names, rig, strict=True)
        ]
        self.live = LivePipeline(rig, [self.markers], name="console-live")
        sinks.append(self.live)
        return sinks, None

    def _start_session(self, recorder: Recorder | None) -> Session | None:
        """A started session of the present devices (None if none could start)."""
        drivers = self.plan.drivers()
        self.missing = {
            d.name: f"port {d.port} does not exist" for d in drivers if _port_missing(d.port)
        }
        for name, why in self.missing.items():
            self._note(name, f"device {name}: {why}")
        present = [d for d in drivers if d.name not in self.missing]
        self.view = ViewSink()
        self.drivers = drivers
        if not present:
            return None
        # The live pipeline is tried in the preview; a recording session takes what the
        # preview found (a failed start stops every sink, the trial's recorder too).
        tries = (True, False) if recorder is None else (not self.live_note,)
        for live in tries:
            sinks, note = self._sinks(live)
            if recorder is not None:
                sinks.insert(0, recorder)
            session = Session(
                present, sinks, close_devices=True, realtime_priority=self.realtime_priority
            )
            try:
                session.start()
            except Exception as exc:  # told to the operator
                if live and note is None and recorder is None:
                    self.live_note = f"off: {exc}"
                    self.drivers = drivers = self.plan.drivers()
                    present = [d for d in drivers if d.name not in self.missing]
                    self.view = ViewSink()
                    continue
                self._note("lab", f"cannot start the devices: {exc}")
                return None
            self.live_note = note
            self.errors.pop("lab", None)
            if session.realtime_refused is not None:
                self._note("realtime", f"--realtime: {session.realtime_refused}")
            return session
        return None

    def _one_session(self, wanted: TrialInfo | None, seconds: float | None) -> None:
        recorder = None
        if wanted is not None:
            journal = self.store.journal(wanted.subject, wanted.session, wanted.trial)
            meta: dict[str, Any] = {"command": "console", "trial": wanted.to_dict()}
            meta["lab"] = {
                "path": str(self.plan.lab.path),
                "rig": None if self.plan.lab.rig is None else str(self.plan.lab.rig),
                "model": None if self.plan.lab.model is None else str(self.plan.lab.model),
            }
            if self.plan.lab.wiring:
                meta["timer_wiring"] = dict(self.plan.lab.wiring)
            try:
                recorder = Recorder(journal, meta)
            except Exception as exc:  # the trial fails, preview goes on
                self._fail_trial(wanted, f"cannot write {journal}: {exc}")
                return
        session = self._start_session(recorder)
        if session is None:
            if wanted is not None and recorder is not None:
                try:
                    recorder.stop()
                finally:
                    # nothing but a failed start-up: leave no journal (the sidecar says why)
                    journal.unlink(missing_ok=True)
                self._fail_trial(wanted, self.errors.get("lab", "no device could start"))
            return
        self.session = session
        self.trial = wanted
        t0 = time.monotonic()
        try:
            while True:
                timeout = RETRY_S if seconds is None else max(0.0, t0 + seconds - time.monotonic())
                woken = self._wake.wait(min(timeout, RETRY_S if wanted is None else 0.5))
                if seconds is not None and time.monotonic() - t0 >= seconds:
                    with self._lock:
                        if self._wanted is wanted:
                            self._wanted = None
                    break
                if woken:
                    break
                if wanted is None and any(not _port_missing(p) for p in self._missing_ports()):
                    break  # a missing device appeared: start again with it
                self._watch(session)
                self._watch_stale(wanted)
        finally:
            elapsed = session.status().elapsed_s
            self._watch(session)
            stale = {
                d.name: age
                for d in self.drivers
                if (age := self.view.last_arrival_s(d.name)) is not None and age > STALE_S
            }
            session.stop()
            self.session = None
            if wanted is not None:
                self._finish_trial(wanted, elapsed, stale)

    def _missing_ports(self) -> list[str]:
        return [d.port for d in self.drivers if d.name in self.missing]

    def _watch(self, session: Session) -> None:
        for record in session.errors:
            self.errors[record.stream] = str(record.error)

    def _watch_stale(self, trial: TrialInfo | None) -> None:
        """Tell stderr, once per device and trial, of a device that stopped sending while
        ``trial`` is recorded (the page's device row says it too)."""
        if trial is None:
            return
        for d in self.drivers:
            age = self.view.last_arrival_s(d.name)
            asked = self._reconnect_asked.get(d.name, -math.inf)
            reconnecting = time.monotonic() - asked < 10.0  # a reconnect the operator asked
            if age is not None and age > STALE_S and not reconnecting:
                message = (
                    f"device {d.name} stopped sending while trial {trial.id} is recorded: "
                    "the trial keeps what arrived before"
                )
                if message not in self._warned:
                    self._warned.add(message)
                    self._warn(message)

    def _fail_trial(self, info: TrialInfo, why: str) -> None:
        info.state = "failed"
        info.messages.append(why)
        self.store.save(info)
        with self.finished:
            if self._wanted is info:
                self._wanted = None
            self._active = None
            self.finished.notify_all()

    def _finish_trial(self, info: TrialInfo, elapsed_s: float, stale: dict[str, float]) -> None:
        journal = self.store.journal(info.subject, info.session, info.trial)
        info.duration_s = round(elapsed_s, 3)
        info.state = "done"
        try:
            summary = summarize(journal, decoder_for).to_dict()
            for s in summary["streams"]:
                info.frames[s["name"]] = int(s.get("frames", 0))
                info.lost[s["name"]] = int(s.get("lost_frames", 0))
        except Exception as exc:  # kept in the sidecar
            info.state = "interrupted"
            info.messages.append(f"the journal could not be summarised: {exc}")
        if self._closed:
            info.messages.append("stopped when the console was stopped")
        for name, why in self.missing.items():
            info.messages.append(f"{name}: not recorded: {why}")
        for name, age in stale.items():
            message = (
                f"{name}: no frame in the last {age:.1f} s of the trial: "
                "it keeps what arrived before"
            )
            info.messages.append(message)
            self._warn(f"trial {info.id}: {message}")
        for stream, error in self.errors.items():
            if stream in info.frames:
                info.messages.append(f"{stream}: {error}")
        self.store.save(info)
        with self.finished:
            self.trial = None
            self._active = None
            self.finished.notify_all()
