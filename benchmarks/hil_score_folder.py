"""Score a scenario run's folder again, with the runner's own functions.

For a run whose scoring did not happen (the soak of 2026-11-25 ended in the recorder's
time-out, docs/hil.md): the devices' figures, the latency at the start and the end
(``DIR/latency.csv``), the session times against the truth (``DIR/timestamps.csv``),
the memory figures from ``DIR/memory.csv``, and the scenario's criteria. Writes
``DIR/summary-scored.json`` and prints one line per criterion.

Usage: ``python benchmarks/hil_score_folder.py DIR SCENARIO`` (a file or a shipped
scenario's name).
"""

from __future__ import annotations

import csv
import json
import sys
import time
from pathlib import Path
from typing import Any

from spotlab.hil.catalog import resolve
from spotlab.hil.memory import memory_figures
from spotlab.hil.runner import _criteria
from spotlab.hil.scenario import load_scenario
from spotlab.hil.scoring import device_figures, frame_latency, sync_error
from spotlab.io.journal import JournalReader


def _memory(folder: Path, names: list[str], duration_s: float) -> dict[str, Any]:
    with open(folder / "memory.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    samples = [
        (float(r["t_s"]), {k.removesuffix("_rss_mb"): float(v) if v else None
                           for k, v in r.items() if k != "t_s"})
        for r in rows
    ]  # fmt: skip
    out: dict[str, Any] = dict(memory_figures(samples, duration_s))
    for name in names:  # each simulator's, as the recorder's figures
        own = [(t, {"record": row.get(name)}) for t, row in samples]
        found = memory_figures(own, duration_s)
        out[f"{name}_rss_start_mb"] = found["record_rss_start_mb"]
        out[f"{name}_rss_end_mb"] = found["record_rss_end_mb"]
    return out


def main(folder: Path, scenario_name: str) -> None:
    started = time.monotonic()
    scenario = load_scenario(resolve(scenario_name))
    journal = folder / "run.spj"
    facts = JournalReader(journal).scan()
    print(f"journal complete: {facts.complete}, damaged records: {facts.corrupt_records}")
    names = [d.name for d in scenario.devices]
    devices = device_figures(journal, {n: folder / f"{n}.faults.json" for n in names})
    truths = {d.name: (d.family, folder / f"{d.name}.truth.csv") for d in scenario.devices
              if (folder / f"{d.name}.truth.csv").is_file()}  # fmt: skip
    for name, figures in frame_latency(journal, truths, folder / "latency.csv").items():
        devices.setdefault(name, {}).update(figures)
    run: dict[str, Any] = {"record_exit_code": None}
    if "timestamps" in scenario.steps:
        found = sync_error(journal, truths, scenario.wiring, folder / "timestamps.csv")
        run.update(sync_error_us=found["sync_error_us"],
                   sync_error_timed_us=found["sync_error_timed_us"],
                   sync_error_per_stream_us=found["per_stream_us"])  # fmt: skip
    run.update(_memory(folder, names, scenario.duration_s))
    criteria = _criteria(scenario, devices, run)
    summary = {"devices": devices, "run": run, "criteria": criteria,
               "scoring_seconds": round(time.monotonic() - started)}  # fmt: skip
    (folder / "summary-scored.json").write_text(json.dumps(summary, indent=2) + "\n")
    for c in criteria:
        print(f"{'pass' if c['passed'] else 'FAIL'}  {c['criterion']}  (got {c['value']})")


if __name__ == "__main__":
    main(Path(sys.argv[1]), sys.argv[2])
