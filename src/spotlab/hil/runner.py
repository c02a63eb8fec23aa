"""Run a scenario: preparation, simulators as processes, ``spotlab record``, processing,
scoring, report.

0. the lab's preparation, when the scenario asks for it: each system calibrated from
   its own wand dance and L-frame, the hub's marker model learnt from a static trial
   and a range of motion (:mod:`spotlab.hil.preparation`);
1. every simulator starts as its own ``spotlab sim`` process on a real pty or TCP
   port (:mod:`spotlab.hil.processes`);
2. a lab file naming their addresses, settings and the timer's wiring is written and
   recorded by ``spotlab record --lab`` in its own process, as in a lab, while the
   memory of it and of the simulators is sampled (:mod:`spotlab.hil.memory`);
3. the simulators are stopped (they write their truth and fault logs);
4. the processing steps run through :mod:`spotlab.processing` (session times,
   reconstruction of every SELSPOT system and labelling of every hub with the
   calibrated rigs, else the simulators' true ones, C3D export), then the figures are
   scored against the truth (:mod:`spotlab.hil.scoring`) and the criteria checked;
5. ``summary.json``, ``junit.xml`` (or ``--junit``) and ``report.html`` are written.

Ctrl-C (KeyboardInterrupt) at any point stops the recorder (SIGINT: it closes the
journal) and every simulator, and still writes the report of what was done, marked
interrupted; the interrupt is then raised again.
"""

from __future__ import annotations

import json
import signal
import subprocess
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from spotlab.hil.labelling import score_labelling
from spotlab.hil.memory import MemorySampler, memory_figures, sample_interval
from spotlab.hil.preparation import PreparationError, Prepared, prepare
from spotlab.hil.processes import (
    CLI,
    RunningSim,
    check_ports,
    start_simulators,
    stop_simulators,
)
from spotlab.hil.report import write_html, write_junit, write_summary
from spotlab.hil.scenario import Scenario
from spotlab.hil.scoring import device_figures, frame_latency, score_reconstruction, sync_error
from spotlab.hil.streams import one_stream


def _toml_value(value: Any) -> str:
    return json.dumps(value) if isinstance(value, str) else str(value).lower() if isinstance(
        value, bool) else str(value)  # fmt: skip


def write_lab(
    scenario: Scenario, sims: list[RunningSim], path: Path, learnt: Path | None = None
) -> Path:
    """The lab file of the running simulators (docs/lab.md); its marker model is the
    scenario's, else ``learnt`` (the ``model`` step's), else, for the ``labelling`` step,
    the hub simulator's own."""
    lines = []
    if scenario.rig is not None:
        lines.append(f"rig = {json.dumps(str(scenario.rig))}")
    model = scenario.model or learnt
    hubs = [s for s in sims if s.device.family == "centroid"]
    if model is None and "labelling" in scenario.steps and hubs:
        model = hubs[0].truth.parent / f"{hubs[0].device.name}.model.json"
    if model is not None:
        lines.append(f"model = {json.dumps(str(model))}")
    for sim in sims:
        d = sim.device
        lines += ["", "[[device]]", f"family = {json.dumps(d.family)}",
                  f"port = {json.dumps(sim.address)}", f"name = {json.dumps(d.name)}"]  # fmt: skip
        lines += [f"{k} = {_toml_value(v)}" for k, v in d.settings.items()]
    if scenario.wiring:
        lines += ["", "[wiring]"] + [f"{k} = {v}" for k, v in scenario.wiring.items()]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def _record(
    lab: Path, journal: Path, seconds: float, folder: Path, sims: list[RunningSim]
) -> dict[str, Any]:
    """``spotlab record --lab LAB --seconds S --out JOURNAL --json`` in its own process,
    the memory of it and of the simulators sampled meanwhile (``DIR/memory.csv``)."""
    out, err = folder / "record.stdout", folder / "record.stderr"
    argv = [
        *CLI,
        "record",
        "--lab",
        str(lab),
        "--seconds",
        f"{seconds:g}",
        "--out",
        str(journal),
        "--json",
        "--overwrite",
    ]  # fmt: skip  (the run's own folder)
    with open(out, "wb") as fo, open(err, "wb") as fe:
        proc = subprocess.Popen(argv, stdout=fo, stderr=fe, stdin=subprocess.DEVNULL)
    pids = {"record": proc.pid} | {s.device.name: s.proc.pid for s in sims}
    sampler = MemorySampler(pids, sample_interval(seconds)).start()
    late = None
    try:
        try:
            code = proc.wait(timeout=record_timeout(seconds))
        except subprocess.TimeoutExpired:  # still summarising, or stuck: it is told to end
            late = (f"spotlab record did not end within {record_timeout(seconds):g} s; "
                    "stopped with SIGINT")  # fmt: skip
            code = _interrupt(proc)
    except BaseException:  # Ctrl-C: the recorder closes its journal on SIGINT
        _interrupt(proc)
        raise
    finally:
        sampler.stop()
        sampler.write_csv(folder / "memory.csv")
    errors = [ln for ln in err.read_text(errors="replace").splitlines()
              if ln.startswith("spotlab: error:")]  # fmt: skip
    return {"record_exit_code": code, "record_error": late or (errors[0] if errors else None),
            **memory_figures(sampler.samples, seconds)}  # fmt: skip


def record_timeout(seconds: float) -> float:
    """Seconds ``spotlab record --seconds S`` is given to end: S, its devices' start and
    stop, and its summary of the journal (minutes for an hour's recording)."""
    return seconds * 1.1 + 120.0


def _interrupt(proc: subprocess.Popen[bytes]) -> int:
    """SIGINT (the recorder closes its journal), then SIGKILL after 15 s; the exit code."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    return int(proc.returncode)


def _process(
    scenario: Scenario,
    sims: list[RunningSim],
    journal: Path,
    folder: Path,
    prepared: Prepared,
) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """The processing steps and their scores: the run's figures, and each device's."""
    run: dict[str, Any] = {}
    per: dict[str, dict[str, Any]] = {}
    if "timestamps" in scenario.steps:
        truths = {s.device.name: (s.device.family, s.truth) for s in sims
                  if s.truth.suffix == ".csv" and s.truth.is_file()}  # fmt: skip
        found = sync_error(journal, truths, scenario.wiring, folder / "timestamps.csv")
        run["sync_error_us"] = found["sync_error_us"]
        run["sync_error_timed_us"] = found["sync_error_timed_us"]
        run["sync_error_per_stream_us"] = found["per_stream_us"]
        run["timebase_notes"] = found["notes"]
    alone = len(sims) == 1
    for sim in sims:
        name, family = sim.device.name, sim.device.family
        recon = family == "selspot" and "reconstruction" in scenario.steps
        label = family == "centroid" and "labelling" in scenario.steps
        if not (recon or label):
            continue
        rig = prepared.rigs.get(name, sim.rig)
        assert rig is not None
        stream = journal if alone else one_stream(journal, name, folder / f"{name}.spj")
        stem = scenario.path.stem if alone else f"{scenario.path.stem}.{name}"
        c3d = folder / f"{stem}.c3d" if "export" in scenario.steps else None
        figures: dict[str, Any]
        if recon:
            found = score_reconstruction(stream, rig, sim.truth, c3d)
            figures = {"error_3d_rms_mm": found["error_rms_mm"],
                       "error_3d_max_mm": found["error_max_mm"],
                       "markers_reconstructed": found["markers_reconstructed"]}  # fmt: skip
            if name in prepared.rigs and sim.rig is not None:  # scoring: the floor of the error
                figures.update(_against_true_rig(stream, sim.rig, sim.truth, figures))
        else:
            model = prepared.models.get(name)
            if model is None and not alone:  # the hub simulator's own model (lab.toml's)
                model = sim.truth.parent / f"{name}.model.json"
            figures = score_labelling(stream, rig, sim.truth, c3d, model)
        figures["rig"] = "calibrated" if name in prepared.rigs else "true"
        if c3d is not None:
            figures["c3d"] = str(c3d)
        per[name] = figures
        if alone:
            run.update(figures)
    return run, per


def _against_true_rig(
    journal: Path, true_rig: Path, truth: Path, calibrated: dict[str, Any]
) -> dict[str, Any]:
    """The same trial reconstructed with the simulator's true rig (scoring only): its RMS
    error, and the calibrated rig's RMS error over it (``error_3d_excess``)."""
    floor = score_reconstruction(journal, true_rig, truth)["error_rms_mm"]
    mine = calibrated["error_3d_rms_mm"]
    excess = mine / floor if mine is not None and floor else None
    return {"error_3d_rms_true_rig_mm": floor, "error_3d_excess": excess}


def _criteria(
    scenario: Scenario, devices: dict[str, dict[str, Any]], run: dict[str, Any]
) -> list[dict[str, Any]]:
    out = []
    for c in scenario.criteria:
        stream, dot, figure = c.figure.partition(".")
        value = devices.get(stream, {}).get(figure) if dot else run.get(c.figure)
        out.append({"criterion": c.describe(), "figure": c.figure, "value": value,
                    "passed": c.holds(value)})  # fmt: skip
    return out


def run_scenario(
    scenario: Scenario,
    folder: Path,
    *,
    seed: int | None = None,
    junit: Path | None = None,
    progress: Callable[[str], None] = lambda _: None,
) -> dict[str, Any]:
    """Run ``scenario`` with its outputs in ``folder``; returns the summary (``verdict``).

    Raises
    ------
    ScenarioError
        A fixed port is busy (nothing is written then), or a simulator does not start.
    """
    check_ports(scenario)
    folder.mkdir(parents=True, exist_ok=True)
    seed = scenario.seed if seed is None else seed
    started = time.monotonic()
    summary: dict[str, Any] = {
        "scenario": scenario.name, "file": str(scenario.path), "description": scenario.description,
        "seed": seed, "duration_s": scenario.duration_s, "steps": list(scenario.steps),
        "devices": {}, "run": {}, "criteria": [], "problem": None,
    }  # fmt: skip
    journal = folder / "run.spj"
    sims: list[RunningSim] = []
    prepared = Prepared()
    try:
        prepared = prepare(scenario, seed, folder, progress)
        for name, figures in prepared.figures.items():
            summary["devices"].setdefault(name, {}).update(figures)
        progress(f"starting {len(scenario.devices)} simulator(s)")
        sims = start_simulators(scenario, seed, folder)
        summary["run"]["simulator_pids"] = {s.device.name: s.proc.pid for s in sims}
        learnt = next(iter(prepared.models.values()), None)
        lab = write_lab(scenario, sims, folder / "lab.toml", learnt)
        progress(f"recording {scenario.duration_s:g} s")
        summary["run"].update(_record(lab, journal, scenario.duration_s, folder, sims))
        codes = stop_simulators(sims)
        summary["run"]["simulator_exit_codes"] = codes
        if not journal.is_file():  # a journal ended by an error is scored (record_exit_code)
            summary["problem"] = summary["run"]["record_error"] or "the recording failed"
        else:
            progress("processing and scoring against the truth")
            logs = {s.device.name: s.fault_log for s in sims}
            for name, figures in device_figures(journal, logs).items():
                summary["devices"].setdefault(name, {}).update(figures)
            truths = {s.device.name: (s.device.family, s.truth) for s in sims
                      if s.truth.suffix == ".csv" and s.truth.is_file()}  # fmt: skip
            timeline = folder / "latency.csv"
            for name, figures in frame_latency(journal, truths, timeline).items():
                summary["devices"].setdefault(name, {}).update(figures)
            run, per = _process(scenario, sims, journal, folder, prepared)
            summary["run"].update(run)
            for name, figures in per.items():
                summary["devices"].setdefault(name, {}).update(figures)
    except PreparationError as exc:
        summary["problem"] = f"preparation failed: {exc}"
    except KeyboardInterrupt:
        summary["problem"] = "interrupted (Ctrl-C): partial report"
        raise
    finally:
        if sims:
            stop_simulators(sims)
        summary["criteria"] = _criteria(scenario, summary["devices"], summary["run"])
        summary["seconds"] = round(time.monotonic() - started, 2)
        ok = summary["problem"] is None and all(c["passed"] for c in summary["criteria"])
        summary["verdict"] = "pass" if ok else "fail"
        write_summary(summary, folder / "summary.json")
        write_junit(summary, junit or folder / "junit.xml")
        write_html(summary, folder / "report.html")
    return summary


__all__ = ["run_scenario", "write_lab"]
