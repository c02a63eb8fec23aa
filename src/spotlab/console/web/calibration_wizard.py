"""The calibration wizard of the page: wand dance, L-frame, calibration, accept.

For the simulated lab (``--sim``) it calibrates a video-centroid hub, as
``spotlab calibrate`` does for centroid recordings (docs/calibration.md): the wand
dance and the L-frame are recorded as trials of a session (``calib_wand``,
``calib_lframe``) from a hub of :data:`SIM_CAMERAS` cameras whose scene is the wand
(``motion=wand``, a 3-marker wand of :data:`WAND_MM` mm) and then the L-frame
(``motion=lframe``, its marker table written by the simulator); while they are recorded
the console's session holds that hub alone (the recordings must hold one stream), and
the lab's devices come back after. The calibration runs in a thread of its own
(:func:`spotlab.processing.blob_calibration_inputs.load_blob_recordings`, then
:func:`spotlab.calibration.wand_calibrate` and its report figure) and writes
``DATA/SUBJECT/SESSION/rig.candidate.toml`` with ``.report.json`` and ``.report.png``;
"Accept" copies it to ``rig.toml`` there, the rig of that session's later processing
and exports (:meth:`Processor.rig_for`). While the wand is recorded, the share of each
camera's image where blobs were seen (a :data:`GRID` x :data:`GRID` grid over the
smallest common sensor size that holds them) is sampled from the live view about 30
times a second.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from spotlab.calibration import wand_calibrate, write_report_figure
from spotlab.console.web.acquisition import Acquisition
from spotlab.console.web.lab_setup import LabPlan
from spotlab.console.web.processing_jobs import Processor
from spotlab.console.web.trials import TrialInfo, check_name
from spotlab.io.lab_file import LabDevice
from spotlab.processing.blob_calibration_inputs import SENSOR_SIZES, load_blob_recordings
from spotlab.processing.errors import InputError

__all__ = ["GRID", "CalibrationWizard"]

#: Cameras of the simulated hub the wizard calibrates.
SIM_CAMERAS = 4
#: The simulated wand's length between its end markers, mm.
WAND_MM = 500.0
#: Coverage grid cells per image side.
GRID = 16
#: Stream name of the hub while the wizard records.
STREAM = "wand_hub"


def _sensor(xy: np.ndarray) -> tuple[int, int]:
    """The smallest common sensor size holding every point (N, 2) px."""
    w, h = (float(v) for v in xy.max(axis=0)) if len(xy) else (0.0, 0.0)
    for size in SENSOR_SIZES:
        if w < size[0] and h < size[1]:
            return size
    return SENSOR_SIZES[-1]


class CalibrationWizard:
    """The wizard's steps and state (one calibration at a time).

    Parameters
    ----------
    acq : Acquisition
        The console's acquisition (its session is switched to the wand hub and back).
    processor : Processor
        The trials' processing (which takes a session's accepted rig).
    """

    def __init__(self, acq: Acquisition, processor: Processor) -> None:
        self.acq, self.processor = acq, processor
        self.lab_plan = acq.plan
        self.lock = threading.Lock()
        self.state: dict[str, Any] = {"step": "idle"}
        self._points: dict[int, list[tuple[float, float]]] = {}
        self._seq = -1
        self._folder: Path | None = None

    # ---- steps (API) ------------------------------------------------------------------
    def record(self, what: str, subject: object, session: object, seconds: object) -> None:
        """Record the wand dance (``what="wand"``) or the L-frame (``"lframe"``)."""
        if not self.lab_plan.simulated:
            raise InputError("the calibration wizard runs on the simulated lab (--sim) only")
        if isinstance(seconds, bool) or not isinstance(seconds, int | float) or seconds <= 0:
            raise InputError("seconds must be a positive number")
        with self.lock:
            step = self.state["step"]
            if what == "lframe" and step not in ("wand_done", "lframe_done", "failed"):
                raise InputError("record the wand dance first")
            if step in ("wand", "lframe", "calibrating"):
                raise InputError(f"the wizard is busy ({step})")
            if what == "wand":
                sub, ses = check_name("subject", subject), check_name("session", session)
            else:
                sub, ses = self.state["subject"], self.state["session"]
            if [d.name for d in self.acq.plan.lab.devices] != [STREAM]:
                self.lab_plan = self.acq.plan  # the lab's, as set now (a rate set included)
            info = TrialInfo(sub, ses, self._free_name(sub, ses, f"calib_{what}"))
            info.notes = f"calibration wizard: {what}"
            self.acq.restart(self._plan(what))
            try:
                self.acq.start_trial(info, float(seconds))
            except InputError:
                self._restart(self.lab_plan)
                raise
            if what == "wand":
                self._folder = self.acq.store.resolve(sub, ses)
                self.state = {"step": "wand", "subject": sub, "session": ses, "coverage": {}}
                self._points, self._seq = {}, -1
            self.state.update(step=what, error=None, trial=info.id)
        threading.Thread(target=self._follow, args=(what, info), daemon=True).start()

    def calibrate(self) -> None:
        """Run the calibration from the two recordings (in a thread)."""
        with self.lock:
            if self.state["step"] not in ("lframe_done", "calibrated", "failed"):
                raise InputError("record the wand dance and the L-frame first")
            if "lframe_trial" not in self.state:
                raise InputError("record the L-frame first")
            self.state.update(step="calibrating", error=None, report=None)
        threading.Thread(target=self._calibrate, daemon=True).start()

    def accept(self) -> str:
        """Make the candidate rig current: ``rig.toml`` of the session; its path."""
        with self.lock:
            if self.state["step"] != "calibrated" or self._folder is None:
                raise InputError("there is no calibration to accept")
            rig = self._folder / "rig.toml"
            shutil.copyfile(self._folder / "rig.candidate.toml", rig)
            self.state.update(step="accepted", rig=str(rig.relative_to(self.acq.store.root)))
            return str(rig)

    def figure(self) -> Path:
        """The report figure of the last calibration (InputError if none)."""
        if self._folder is None or not (self._folder / "rig.candidate.report.png").is_file():
            raise InputError("no calibration report yet")
        return self._folder / "rig.candidate.report.png"

    def snapshot(self) -> dict[str, Any]:
        """The wizard's state (JSON-safe), with the live coverage while the wand runs."""
        if self.state.get("step") == "wand":
            self._sample()
        with self.lock:
            return json.loads(json.dumps(self.state))

    # ---- work -------------------------------------------------------------------------
    def _plan(self, what: str) -> LabPlan:
        folder = self.acq.store.root / ".sim"
        url = f"sim://centroid?cameras={SIM_CAMERAS}&rate=100"
        if what == "wand":
            url += "&markers=3&motion=wand&seed=1"
        else:
            url += f"&markers=4&motion=lframe&seed=2&frame_points_out={folder / 'lframe.csv'}"
        device = LabDevice("centroid", url, STREAM, {}, "calibration wizard")
        lab = dataclasses.replace(self.lab_plan.lab, devices=(device,), rig=None, model=None)
        return LabPlan(lab, True)

    def _free_name(self, subject: str, session: str, base: str) -> str:
        """``base``, or ``base2``, ``base3``... : the first trial name not taken."""
        for n in range(1, 1000):
            name = base if n == 1 else f"{base}{n}"
            journal = self.acq.store.journal(subject, session, name)
            if not journal.exists() and not self.acq.store.sidecar(journal).exists():
                return name
        raise InputError(f"too many {base} trials in {subject}/{session}")

    def _restart(self, plan: LabPlan, timeout: float = 20.0) -> None:
        """Switch the session to ``plan`` once the trial being finished is done."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                self.acq.restart(plan)
                return
            except InputError:
                if time.monotonic() > deadline:
                    return
                time.sleep(0.1)

    def _sample(self) -> None:
        view = self.acq.view.views.get(STREAM)
        if view is None:
            return
        with self.lock:
            if view.seq == self._seq:
                return
            self._seq = view.seq
            for c, blobs in enumerate(view.cameras):
                self._points.setdefault(c, []).extend((float(x), float(y)) for x, y in blobs)
            coverage = {}
            for c, pts in self._points.items():
                xy = np.asarray(pts, dtype=float).reshape(-1, 2)
                w, h = _sensor(xy)
                cells = {(int(GRID * x / w), int(GRID * y / h)) for x, y in xy}
                coverage[f"cam{c + 1}"] = round(len(cells) / GRID**2, 4)
            self.state["coverage"] = coverage

    def _follow(self, what: str, info: TrialInfo) -> None:
        """Wait for the recording to end (sampling the coverage); then the next step."""
        while True:
            if what == "wand":
                self._sample()
            try:
                done = self.acq.store.load(info.id)
            except InputError:
                done = info
            if done.state != "recording":
                break
            time.sleep(1 / 30)
        with self.lock:
            if done.state != "done":
                self.state.update(step="failed", error=f"{info.id}: {done.state}")
            else:
                self.state.update(step=f"{what}_done")
                self.state[f"{what}_trial"] = info.id
        if what == "lframe" or done.state != "done":
            self._restart(self.lab_plan)  # the lab's devices again
        else:
            self._restart(self._plan("lframe"))  # show the L-frame until it is recorded

    def _calibrate(self) -> None:
        store = self.acq.store
        folder = self._folder
        try:
            if folder is None:
                raise InputError("record the wand dance first")
            wand = store.journal(*store.parse_id(self.state["wand_trial"]))
            frame = store.journal(*store.parse_id(self.state["lframe_trial"]))
            found = load_blob_recordings(
                wand, frame, store.root / ".sim" / "lframe.csv", wand_length=WAND_MM
            )
            obs = found.observations
            result = wand_calibrate(
                obs.wand, WAND_MM, obs.frame, obs.frame_points, obs.image_size,
                names=obs.names, units=obs.units,
            )  # fmt: skip
            out = folder / "rig.candidate.toml"
            write_report_figure(
                result.rig, obs.wand, result.wand_residuals, result.inliers, result.report,
                out.with_suffix(".report.png"), frame_points=obs.frame_points,
            )  # fmt: skip
            report = {**result.report, "finder": found.summary()}
            out.with_suffix(".report.json").write_text(json.dumps(report, indent=2) + "\n")
            result.rig.save(out)
        except Exception as exc:  # an input or numerics error, told to the page
            with self.lock:
                self.state.update(step="failed", error=str(exc) or type(exc).__name__)
            return
        cameras = [
            {
                "name": cam["name"],
                "reprojection_rms": cam["reprojection_rms_px"],
                "observations": cam["observations"],
                "image_coverage": cam["image_coverage"],
            }
            for cam in report["cameras"]
        ]
        with self.lock:
            self.state.update(
                step="calibrated",
                report={
                    "units": report["image_units"],
                    "cameras": cameras,
                    "wand_sd_mm": report["wand"]["sd_mm"],
                    "verdict": report["verdict"]["grade"],
                    "reasons": report["verdict"]["reasons"],
                },
                candidate=str(out.relative_to(store.root)),
            )
