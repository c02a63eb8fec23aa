"""The calibration wizard of the page: wand dance, L-frame, calibration, accept.

It calibrates one camera system of the lab as ``spotlab calibrate`` does
(docs/calibration.md), through :mod:`spotlab.processing.recording_calibration`: the wand
dance and the L-frame are recorded as trials of a session (``calib_wand``,
``calib_lframe``) while the console's session holds that device alone (a recording for
calibration holds one stream); the lab's devices come back after.

* A lab file's own device (``--lab``): a video-centroid hub (``centroid``: the wand and
  the reference object found among its blobs) or a SELSPOT-style system (``selspot``:
  its LEDs carry numbers), with the wand and reference object of the lab file's
  ``[calibration]`` table (``wand_length``, ``frame_points``, for SELSPOT
  ``wand_markers`` and ``frame_markers``; docs/lab.md). The operator waves the wand, then
  lays the L-frame down.
* The simulated lab (``--sim``): a simulated hub of :data:`SIM_CAMERAS` cameras whose
  scene is the wand (``motion=wand``, a 3-marker wand of :data:`WAND_MM` mm), then the
  L-frame (``motion=lframe``, its marker table written by the simulator), since the
  simulated SELSPOT system's scene is the gait.

The calibration runs in a thread of its own and writes
``DATA/SUBJECT/SESSION/rig.candidate.toml`` with ``.report.json`` and ``.report.png``;
"Accept" copies it to ``rig.toml`` there, the rig of that session's later processing and
exports (:meth:`Processor.rig_for`). While the wand is recorded, the share of each
camera's image where it was seen (a :data:`GRID` x :data:`GRID` grid over the image: the
smallest common sensor size that holds the blobs, or a PSD detector's 4096 x 4096
counts) is sampled from the live view about 30 times a second.
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

from spotlab.console.web.acquisition import Acquisition
from spotlab.console.web.lab_setup import LabPlan
from spotlab.console.web.processing_jobs import Processor
from spotlab.console.web.trials import TrialInfo, check_name
from spotlab.io.lab_file import LabDevice
from spotlab.processing.blob_calibration_inputs import SENSOR_SIZES, load_blob_recordings
from spotlab.processing.calibration_inputs import load_recordings
from spotlab.processing.errors import InputError
from spotlab.processing.recorded_observations import PSD_IMAGE_SIZE
from spotlab.processing.recording_calibration import (
    Calibrated,
    calibrate_observations,
    write_calibration,
)

__all__ = ["GRID", "CalibrationWizard"]

#: Cameras of the simulated hub the wizard calibrates.
SIM_CAMERAS = 4
#: The simulated wand's length between its end markers, mm.
WAND_MM = 500.0
#: Coverage grid cells per image side.
GRID = 16
#: Stream name of the simulated hub while the wizard records.
STREAM = "wand_hub"
#: Device families the wizard calibrates.
FAMILIES = ("centroid", "selspot")


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
        self._device: LabDevice | None = None  # the lab's device calibrated (None: --sim)
        self._stream = STREAM

    # ---- steps (API) ------------------------------------------------------------------
    def devices(self) -> list[str]:
        """The lab's devices the wizard can calibrate (stream names; empty for ``--sim``,
        whose simulated hub it calibrates)."""
        if self.lab_plan.simulated:
            return []
        lab = self.lab_plan.lab
        names = self.lab_plan.names()
        return [n for n, d in zip(names, lab.devices, strict=True) if d.family in FAMILIES]

    def _choose(self, device: object) -> tuple[LabDevice | None, str]:
        """The lab device to calibrate and its stream name (None, STREAM for --sim)."""
        if self.lab_plan.simulated:
            if device not in (None, "", STREAM):
                raise InputError("on the simulated lab the wizard calibrates its own hub")
            return None, STREAM
        choices = self.devices()
        if device in (None, "") and len(choices) == 1:
            device = choices[0]
        if device not in choices:
            raise InputError(
                f"choose the device to calibrate: one of {', '.join(choices) or 'none'} "
                f"(families {', '.join(FAMILIES)}), got {device!r}"
            )
        lab = self.lab_plan.lab
        index = self.lab_plan.names().index(str(device))
        cal = lab.calibration
        if cal is None:
            raise InputError(
                f"lab file {lab.path} has no [calibration] table (wand_length, frame_points; "
                "docs/lab.md)"
            )
        chosen = lab.devices[index]
        if chosen.family == "selspot" and (cal.wand_markers is None or cal.frame_markers is None):
            raise InputError(
                f"lab file {lab.path}: [calibration] needs wand_markers and frame_markers "
                "for a SELSPOT-style system"
            )
        if not cal.frame_points.is_file():
            raise InputError(f"lab file {lab.path}: calibration.frame_points: no file "
                             f"{cal.frame_points}")  # fmt: skip
        return dataclasses.replace(chosen, name=str(device)), str(device)

    def record(
        self, what: str, subject: object, session: object, seconds: object, device: object = None
    ) -> None:
        """Record the wand dance (``what="wand"``) of ``device`` (a stream name of the lab;
        the only one that can be calibrated by default) or the L-frame (``"lframe"``)."""
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
                if [d.name for d in self.acq.plan.lab.devices] != [self._stream]:
                    self.lab_plan = self.acq.plan  # the lab's, as set now (a rate included)
                self._device, self._stream = self._choose(device)
            else:
                sub, ses = self.state["subject"], self.state["session"]
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
                self.state = {
                    "step": "wand",
                    "subject": sub,
                    "session": ses,
                    "device": self._stream,
                    "coverage": {},
                }
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
            state: dict[str, Any] = json.loads(json.dumps(self.state))
        state["devices"] = self.devices()
        return state

    # ---- work -------------------------------------------------------------------------
    def _plan(self, what: str) -> LabPlan:
        if self._device is not None:  # the lab's device alone, for both recordings
            lab = self.lab_plan.lab
            only = dataclasses.replace(lab, devices=(self._device,), rig=None, model=None)
            return LabPlan(only, False)
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
        view = self.acq.view.views.get(self._stream)
        if view is None:
            return
        psd = self._device is not None and self._device.family == "selspot"
        with self.lock:
            if view.seq == self._seq:
                return
            self._seq = view.seq
            for c, blobs in enumerate(view.cameras):
                self._points.setdefault(c, []).extend((float(x), float(y)) for x, y in blobs)
            coverage = {}
            for c, pts in self._points.items():
                xy = np.asarray(pts, dtype=float).reshape(-1, 2)
                w, h = (int(PSD_IMAGE_SIZE[0]), int(PSD_IMAGE_SIZE[1])) if psd else _sensor(xy)
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

    def _calibrated(self, wand: Path, frame: Path) -> Calibrated:
        """The calibration of the two recordings, as ``spotlab calibrate`` computes it."""
        if self._device is None:  # the simulated hub
            points = self.acq.store.root / ".sim" / "lframe.csv"
            found = load_blob_recordings(wand, frame, points, wand_length=WAND_MM)
            return calibrate_observations(found.observations, WAND_MM, found)
        cal = self.lab_plan.lab.calibration
        assert cal is not None  # checked by _choose
        option = "wand_length of the lab file's [calibration]"
        if self._device.family == "centroid":
            found = load_blob_recordings(
                wand, frame, cal.frame_points, wand_length=cal.wand_length,
                wand_middle=cal.wand_middle,
            )  # fmt: skip
            return calibrate_observations(
                found.observations, cal.wand_length, found, length_option=option
            )
        assert cal.wand_markers is not None and cal.frame_markers is not None
        obs = load_recordings(wand, cal.wand_markers, frame, cal.frame_markers, cal.frame_points)
        return calibrate_observations(obs, cal.wand_length, length_option=option)

    def _calibrate(self) -> None:
        store = self.acq.store
        folder = self._folder
        try:
            if folder is None:
                raise InputError("record the wand dance first")
            wand = store.journal(*store.parse_id(self.state["wand_trial"]))
            frame = store.journal(*store.parse_id(self.state["lframe_trial"]))
            calibrated = self._calibrated(wand, frame)
            out = folder / "rig.candidate.toml"
            report = write_calibration(
                calibrated, out, out.with_suffix(".report.json"), out.with_suffix(".report.png")
            )
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
