"""A scenario's lab preparation: each system calibrated, the hub's subject modelled.

Before the scenario's own recording, as a lab prepares a session (docs/calibration.md,
docs/identification.md), with the command line a lab uses, each step its own process:

* ``calibration``: every SELSPOT system and centroid hub waves a wand and shows an
  L-frame, each recorded from a simulator of the device's cameras (``spotlab sim ...
  --motion wand|lframe``, ``spotlab record``), and ``spotlab calibrate`` makes its rig
  of them. The rig, not the simulator's true one, reconstructs the scenario's trial.
* ``model``: the hub's subject (the simulator's seed) stands still and then goes
  through a range of motion (``--motion static``, ``rom``); ``spotlab model init``
  (the ``spotlab-body`` template) and ``spotlab model learn`` make the marker model
  that labels the scenario's trial: a model learnt from other motions than the one it
  labels.

Nothing here reads a simulator's truth: the rigs and models come from recordings alone.
"""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from spotlab.hil.processes import CLI, first_line
from spotlab.hil.scenario import Scenario, SimDevice

#: Seconds of each preparation recording.
WAND_S = {"selspot": 20.0, "centroid": 20.0}
#: The hub's wand dance is recorded at this rate (Hz) whatever the scenario's rate, as
#: docs/calibration.md advises (20 s at 200 Hz: the world-frame ratio within 5 % in 20 of
#: 20 scenes of ``benchmarks/centroid_calibration.py``; 15 s at 100 Hz in 13 of 20).
CENTROID_WAND_HZ = 200
FRAME_S = {"selspot": 1.0, "centroid": 5.0}
STATIC_S, ROM_S = 2.0, 6.0
WAND_LENGTH_MM = 500.0
#: The template ``spotlab model init`` fits to the hub's static trial.
TEMPLATE = "spotlab-body"
#: The L-frame's four markers (SELSPOT LED numbers 1-4 of ``--motion lframe``).
FRAME_MARKERS = ("1", "2", "3", "4")
RECORD_TIMEOUT_S = 120.0
COMMAND_TIMEOUT_S = 300.0


class PreparationError(RuntimeError):
    """A preparation step failed; the message names it and the command's error line."""


@dataclass
class Prepared:
    """What the preparation made, by stream name."""

    rigs: dict[str, Path] = field(default_factory=dict)
    models: dict[str, Path] = field(default_factory=dict)
    #: Per stream: the calibration's figures (``calibration_rms``, ``calibration_verdict``).
    figures: dict[str, dict[str, Any]] = field(default_factory=dict)


def _seed(device: SimDevice, seed: int) -> int:
    return int(device.sim.get("seed", seed + device.index))


def _settings(device: SimDevice) -> tuple[str, str]:
    return str(device.settings.get("cameras", 4)), str(device.settings.get("rate", 100))


def _at_rate(argv: list[str], rate: str) -> list[str]:
    """``argv`` with the value after its ``--rate`` replaced by ``rate``."""
    i = argv.index("--rate")
    return [*argv[: i + 1], rate, *argv[i + 2 :]]


def _run(argv: list[str], log: Path, timeout: float, what: str) -> str:
    """Run ``spotlab ARGV``; stdout returned, stderr in ``log``; a failure raises."""
    result = subprocess.run(
        [*CLI, *argv], capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL
    )
    log.write_text(result.stderr, encoding="utf-8")
    if result.returncode != 0:
        lines = [ln for ln in result.stderr.splitlines() if ln.startswith("spotlab: error:")]
        why = lines[-1].removeprefix("spotlab: error: ") if lines else f"exit {result.returncode}"
        raise PreparationError(f"{what}: {why}")
    return result.stdout


def _recorded(
    device: SimDevice, sim_args: list[str], record_args: list[str], out: Path, seconds: float
) -> Path:
    """One scene: a simulator of the device's cameras, recorded by ``spotlab record``."""
    folder = out.parent
    sim_out, sim_err = folder / f"{out.stem}.sim.stdout", folder / f"{out.stem}.sim.stderr"
    with open(sim_out, "wb") as fo, open(sim_err, "wb") as fe:
        sim = subprocess.Popen([*CLI, *sim_args], stdout=fo, stderr=fe, stdin=subprocess.DEVNULL)
    try:
        port = first_line(sim_out, sim, 30.0)
        if port is None:
            lines = sim_err.read_text(errors="replace").splitlines()
            raise PreparationError(f"{device.name}: the {out.stem} simulator did not start: "
                                   f"{lines[-1] if lines else 'no address'}")  # fmt: skip
        argv = [*(a.replace("{port}", port) for a in record_args), "--seconds", f"{seconds:g}"]
        try:
            _run([*argv, "--out", str(out), "--overwrite"], folder / f"{out.stem}.record.stderr",
                 RECORD_TIMEOUT_S + seconds, f"{device.name}: recording {out.stem}")  # fmt: skip
        except PreparationError:
            if not out.is_file():  # a recording ended by a slow simulator still holds its frames
                raise
    finally:
        if sim.poll() is None:
            sim.terminate()
        try:
            sim.wait(timeout=15)
        except subprocess.TimeoutExpired:
            sim.kill()
            sim.wait()
    return out


def calibrate_device(device: SimDevice, seed: int, folder: Path) -> tuple[Path, dict[str, Any]]:
    """Record a wand dance and an L-frame of ``device``'s cameras and calibrate them.

    Returns
    -------
    rig : Path
        ``folder/NAME.calibrated.toml``.
    figures : dict
        ``calibration_rms`` (the largest camera's reprojection RMS, px or counts) and
        ``calibration_verdict`` of the report.
    """
    cameras, rate = _settings(device)
    name, family = device.name, device.family
    common = ["sim", family, "--pty", "--cameras", cameras, "--rate", rate,
              "--seed", str(_seed(device, seed))]  # fmt: skip
    wand, frame = folder / f"{name}.wand.spj", folder / f"{name}.lframe.spj"
    points = folder / f"{name}.lframe.csv"
    if family == "selspot":
        rec = ["record", "{port}", "--driver", "selspot", "--cameras", cameras, "--rate", rate]
        dark = ["--reflectance", "0"]  # a PSD sees the floor's reflection too
        _recorded(device, [*common, "--leds", "2", "--motion", "wand", *dark],
                  [*rec, "--leds", "2"], wand, WAND_S[family])  # fmt: skip
        _recorded(device, [*common, "--leds", "4", "--motion", "lframe", *dark,
                           "--frame-points-out", str(points)],
                  [*rec, "--leds", "4"], frame, FRAME_S[family])  # fmt: skip
        markers = ["--wand-markers", "1", "2", "--frame-markers", *FRAME_MARKERS]
    else:
        rec = ["record", "--device", f"{family}={{port}}", "--cameras", cameras, "--rate", rate]
        wand_hz = str(CENTROID_WAND_HZ)
        _recorded(device, [*_at_rate(common, wand_hz), "--motion", "wand"],
                  _at_rate(rec, wand_hz), wand, WAND_S[family])  # fmt: skip
        _recorded(device, [*common, "--motion", "lframe", "--frame-points-out", str(points)],
                  rec, frame, FRAME_S[family])  # fmt: skip
        markers = []
    rig = folder / f"{name}.calibrated.toml"
    out = _run(
        ["calibrate", str(wand), *markers, "--frame-recording", str(frame), "--frame-points",
         str(points), "--wand-length", f"{WAND_LENGTH_MM:g}", "--out", str(rig), "--json"],
        folder / f"{name}.calibrate.stderr", COMMAND_TIMEOUT_S, f"{name}: spotlab calibrate",
    )  # fmt: skip
    report = json.loads(out.strip().splitlines()[-1])
    rms = max(float(c["reprojection_rms_px"]) for c in report["cameras"])
    return rig, {"calibration_rms": round(rms, 4),
                 "calibration_verdict": report["verdict"]["grade"]}  # fmt: skip


def learn_model(device: SimDevice, seed: int, rig: Path, folder: Path) -> Path:
    """The hub subject's static trial and range of motion, recorded and learnt from:
    ``folder/NAME.model.json`` (``spotlab model init`` then ``spotlab model learn``)."""
    cameras, rate = _settings(device)
    name = device.name
    common = ["sim", "centroid", "--pty", "--cameras", cameras, "--rate", rate,
              "--seed", str(_seed(device, seed))]  # fmt: skip
    rec = ["record", "--device", "centroid={port}", "--cameras", cameras, "--rate", rate]
    static, rom = folder / f"{name}.static.spj", folder / f"{name}.rom.spj"
    _recorded(device, [*common, "--motion", "static"], rec, static, STATIC_S)
    _recorded(device, [*common, "--motion", "rom"], rec, rom, ROM_S)
    first, model = folder / f"{name}.model0.json", folder / f"{name}.model.json"
    _run(["model", "init", str(static), "--template", TEMPLATE, "--calibration", str(rig),
          "--out", str(first)], folder / f"{name}.model-init.stderr", COMMAND_TIMEOUT_S,
         f"{name}: spotlab model init")  # fmt: skip
    _run(["model", "learn", str(rom), "--model", str(first), "--calibration", str(rig),
          "--out", str(model)], folder / f"{name}.model-learn.stderr", COMMAND_TIMEOUT_S,
         f"{name}: spotlab model learn")  # fmt: skip
    return model


def prepare(
    scenario: Scenario,
    seed: int,
    folder: Path,
    progress: Callable[[str], None] = lambda _: None,
) -> Prepared:
    """Run the scenario's ``calibration`` and ``model`` steps into ``folder/prepare``
    (``model`` learns with the calibrated rig: the scenario checks it calibrates)."""
    done = Prepared()
    where = folder / "prepare"
    if {"calibration", "model"} & set(scenario.steps):
        where.mkdir(parents=True, exist_ok=True)
    if "calibration" in scenario.steps:
        for device in scenario.devices:
            if device.family in ("selspot", "centroid"):
                progress(f"calibrating {device.name} (wand dance and L-frame)")
                rig, figures = calibrate_device(device, seed, where)
                done.rigs[device.name] = rig
                done.figures[device.name] = figures
    if "model" in scenario.steps:
        for device in scenario.devices:
            if device.family == "centroid":
                progress(f"learning {device.name}'s marker model (static trial and ROM)")
                rig = done.rigs[device.name]
                done.models[device.name] = learn_model(device, seed, rig, where)
    return done


__all__ = ["PreparationError", "Prepared", "calibrate_device", "learn_model", "prepare"]
