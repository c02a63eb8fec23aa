"""One bench run: conformance, measurement, disruptive steps, report, baseline comparison.

:func:`run_bench` is what ``spotlab bench`` runs; the command line only parses its
options, builds the drivers' factories and prints.
"""

from __future__ import annotations

import datetime
import json
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from spotlab import __version__
from spotlab.bench.compare import compare
from spotlab.bench.conformance import run_suite
from spotlab.bench.disruptive import Confirm, DriverFactory, cable_step, reset_step
from spotlab.bench.measure import measure
from spotlab.bench.report import plot_stream, write_html, write_json
from spotlab.core.errors import SpotlabError

#: Skips that only say a ``--hw`` run tests one port (the suites' simulator parameters).
_NOT_RUN = ("hardware run: one port only", "a real server speaks its own version")


@dataclass(frozen=True)
class BenchDevice:
    """A device on the bench.

    Attributes
    ----------
    family : str
        Its family (the conformance suite and driver).
    port : str
        Device path, pyserial URL (``sim://...``) or ``HOST[:PORT]``.
    name : str
        Its stream name in the report.
    make : callable
        ``port -> Driver`` (not started), with the device's settings.
    """

    family: str
    port: str
    name: str
    make: DriverFactory


@dataclass(frozen=True)
class BenchOptions:
    """How to run the bench.

    Attributes
    ----------
    seconds : float
        Seconds streamed for the figures.
    disruptive : bool
        Run the reset and cable steps.
    ask : callable or None
        Asks before each disruptive step (None: ``--yes``, no asking).
    pull_cable : callable or None
        Asks a person to pull a real cable (None: that step is skipped on real ports).
    report_dir : Path
        Where the report goes (made if missing).
    baseline : Path or None
        A previous ``report.json`` to compare with.
    select : str or None
        A ``-k`` expression choosing some conformance tests.
    """

    seconds: float
    disruptive: bool
    ask: Confirm | None
    pull_cable: Confirm | None
    report_dir: Path
    baseline: Path | None = None
    select: str | None = None


def _conformance(device: BenchDevice, select: str | None) -> tuple[list[dict[str, Any]], str]:
    outcomes, log = run_suite(device.family, device.port, select)
    tests = []
    for o in outcomes:
        if o.outcome == "skipped" and o.reason in _NOT_RUN:
            continue
        tests.append({**asdict(o), "name": o.name.removesuffix("[pty]")})
    return tests, log


def _disruptive(device: BenchDevice, options: BenchOptions) -> list[dict[str, Any]]:
    steps = []
    for step in ("reset", "cable"):
        if options.ask is not None and not options.ask(f"{device.name}: run the {step} step?"):
            steps.append({"step": step, "status": "skipped", "recovery_s": None,
                          "gap_s": None, "reason": "declined", "counters": None})  # fmt: skip
            continue
        if step == "reset":
            result = reset_step(device.make, device.port)
        else:
            result = cable_step(device.family, device.make, device.port, options.pull_cable)
        steps.append(asdict(result))
    return steps


def load_baseline(path: Path) -> dict[str, Any]:
    """A previous ``report.json``.

    Raises
    ------
    SpotlabError
        If it cannot be read or is not a bench report.
    """
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise SpotlabError(f"baseline {path}: cannot read it: {exc.strerror or exc}") from None
    except ValueError as exc:
        raise SpotlabError(f"baseline {path}: not JSON: {exc}") from None
    if not isinstance(data, dict) or "devices" not in data:
        raise SpotlabError(f"baseline {path}: not a spotlab bench report.json")
    return data


def run_bench(
    devices: Sequence[BenchDevice],
    options: BenchOptions,
    progress: Callable[[str], None] = lambda _: None,
) -> dict[str, Any]:
    """Bench ``devices`` and write the report; returns it (``verdict``, ``failures``)."""
    baseline = load_baseline(options.baseline) if options.baseline is not None else None
    folder = options.report_dir
    folder.mkdir(parents=True, exist_ok=True)
    started = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    entries: list[dict[str, Any]] = []
    failures: list[str] = []
    for device in devices:
        progress(f"{device.name}: conformance suite ({device.family}) on {device.port}")
        tests, log = _conformance(device, options.select)
        (folder / f"{device.name}.conformance.log").write_text(log, encoding="utf-8")
        failures += [f"{device.name}: {t['name']}: {t['reason']}" for t in tests
                     if t["outcome"] == "failed"]  # fmt: skip
        entries.append({"stream": device.name, "family": device.family, "port": device.port,
                        "conformance": tests, "figures": {}, "errors": []})  # fmt: skip
    progress(f"measuring {len(devices)} device(s) for {options.seconds:g} s")
    plots: dict[str, str] = {}
    try:
        results = measure([d.make(d.port) for d in devices], options.seconds)
    except SpotlabError as exc:
        failures.append(f"measurement: {exc}")
        results = []
    for entry, result in zip(entries, results, strict=False):
        entry["figures"] = result.figures
        entry["errors"] = result.errors
        if result.figures.get("frames", 0) == 0:
            failures.append(f"{entry['stream']}: no frames while measuring")
        png = f"{entry['stream']}.png"
        plot_stream(result.stamps, f"{entry['stream']} ({entry['family']})", folder / png)
        plots[entry["stream"]] = png
    if options.disruptive:
        for device, entry in zip(devices, entries, strict=True):
            progress(f"{device.name}: disruptive steps")
            entry["disruptive"] = _disruptive(device, options)
            failures += [f"{device.name}: {s['step']} step: {s['reason']}"
                         for s in entry["disruptive"] if s["status"] == "failed"]  # fmt: skip
    report: dict[str, Any] = {
        "spotlab_bench": 1,
        "spotlab": __version__,
        "started": started,
        "seconds": options.seconds,
        "devices": entries,
    }
    if baseline is not None:
        regressions = compare(report, baseline)
        report["baseline"] = str(options.baseline)
        report["regressions"] = [asdict(r) for r in regressions]
        failures += [f"regression: {r.describe()}" for r in regressions]
    report["failures"] = failures
    report["verdict"] = "fail" if failures else "pass"
    write_json(report, folder)
    write_html(report, folder, plots)
    return report


__all__ = ["BenchDevice", "BenchOptions", "load_baseline", "run_bench"]
