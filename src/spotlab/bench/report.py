"""The bench's report: ``report.json``, ``report.html`` and one PNG of plots per device.

The plots (matplotlib, Agg backend, no display needed) show, per device, each
arrival's delay above the device clock's line (:func:`~spotlab.bench.timing.clock_fit`)
against time, the histogram of host latency per frame, and the intervals between
arrivals.
"""

from __future__ import annotations

import html
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from spotlab.bench.timing import FrameStamps, clock_fit


def write_json(report: Mapping[str, Any], folder: Path) -> Path:
    """``folder/report.json``."""
    path = folder / "report.json"
    path.write_text(json.dumps(report, indent=2, sort_keys=False) + "\n", encoding="utf-8")
    return path


def plot_stream(stamps: FrameStamps, title: str, path: Path) -> Path:
    """Three panels of one stream's timing, written as a PNG to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    try:
        n = len(stamps)
        if n >= 3:
            _, _, residual = clock_fit(stamps)
            t = (stamps.arrival_ns - stamps.arrival_ns[0]) / 1e9
            axes[0].plot(t, residual / 1e3, ".", ms=2)
            latency = (stamps.delivered_ns - stamps.arrival_ns) / 1e3
            axes[1].hist(latency, bins=60)
            axes[1].set_yscale("log")
            intervals = np.diff(stamps.arrival_ns) / 1e6
            axes[2].plot(t[1:], intervals, ".", ms=2)
        axes[0].set(title="arrival delay above the device clock", xlabel="s", ylabel="µs")
        axes[1].set(title="host latency per frame", xlabel="µs", ylabel="frames")
        axes[2].set(title="interval between arrivals", xlabel="s", ylabel="ms")
        fig.suptitle(title)
        fig.tight_layout()
        fig.savefig(path, dpi=80)
    finally:
        plt.close(fig)
    return path


def _cell(value: Any) -> str:
    if value is None:
        return "—"
    if isinstance(value, float):
        return f"{value:g}"
    return html.escape(str(value))


def _table(rows: Sequence[Sequence[Any]], header: Sequence[str]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{_cell(c)}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


_STYLE = (
    "body{font-family:sans-serif;margin:2em}table{border-collapse:collapse;margin:0.5em 0}"
    "td,th{border:1px solid #bbb;padding:2px 8px;text-align:left}"
    ".failed{color:#b00}.passed{color:#070}.skipped{color:#777}img{max-width:100%}"
)


def write_html(report: Mapping[str, Any], folder: Path, plots: Mapping[str, str]) -> Path:
    """``folder/report.html``: the verdict, then per device its tests, figures and plots."""
    verdict = str(report.get("verdict", "?"))
    parts = [
        f"<!doctype html><html><head><meta charset='utf-8'><title>spotlab bench</title>"
        f"<style>{_STYLE}</style></head><body>",
        f"<h1>spotlab bench: <span class='{'passed' if verdict == 'pass' else 'failed'}'>"
        f"{html.escape(verdict)}</span></h1>",
        f"<p>{_cell(report.get('started'))}, {_cell(report.get('seconds'))} s measured per "
        f"run, spotlab {_cell(report.get('spotlab'))}</p>",
    ]
    failures = report.get("failures") or []
    if failures:
        parts.append("<h2>Failures</h2><ul>")
        parts += [f"<li class='failed'>{html.escape(str(f))}</li>" for f in failures]
        parts.append("</ul>")
    for device in report.get("devices", []):
        name = str(device.get("stream"))
        parts.append(
            f"<h2>{html.escape(name)} ({html.escape(str(device.get('family')))} at "
            f"<code>{html.escape(str(device.get('port')))}</code>)</h2>"
        )
        tests = device.get("conformance", [])
        n_failed = sum(t["outcome"] == "failed" for t in tests)
        parts.append(f"<h3>Conformance: {len(tests) - n_failed} of {len(tests)} not failed</h3>")
        parts.append("<table><tr><th>test</th><th>outcome</th><th>reason</th><th>s</th></tr>")
        for t in tests:
            parts.append(
                f"<tr><td>{_cell(t['name'])}</td><td class='{t['outcome']}'>{t['outcome']}</td>"
                f"<td>{_cell(t['reason'])}</td><td>{_cell(t['seconds'])}</td></tr>"
            )
        parts.append("</table>")
        figures = device.get("figures") or {}
        parts.append("<h3>Figures</h3>")
        parts.append(_table([[k, v] for k, v in figures.items()], ["figure", "value"]))
        steps = device.get("disruptive") or []
        if steps:
            parts.append("<h3>Disruptive steps</h3>")
            parts.append(
                _table(
                    [[s["step"], s["status"], s["recovery_s"], s["gap_s"], s["reason"]]
                     for s in steps],
                    ["step", "status", "recovery (s)", "longest gap (s)", "reason"],
                )
            )  # fmt: skip
        if name in plots:
            parts.append(f"<img src='{html.escape(plots[name])}' alt='timing of {name}'>")
    regressions = report.get("regressions")
    if regressions is not None:
        parts.append(f"<h2>Against the baseline {html.escape(str(report.get('baseline')))}</h2>")
        if regressions:
            parts.append(
                _table(
                    [[r["device"], r["figure"], r["baseline"], r["value"], r["limit"]]
                     for r in regressions],
                    ["device", "figure", "baseline", "now", "limit"],
                )
            )  # fmt: skip
        else:
            parts.append("<p class='passed'>no figure worse beyond its tolerance</p>")
    parts.append("</body></html>\n")
    path = folder / "report.html"
    path.write_text("\n".join(parts), encoding="utf-8")
    return path


__all__ = ["plot_stream", "write_html", "write_json"]
