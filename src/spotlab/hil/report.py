"""A scenario run's outputs: ``summary.json``, JUnit XML for CI, ``report.html``.

In JUnit XML the scenario is a test suite and each criterion a test case (failed
with the figure's value when it does not hold); a run that was interrupted or
could not record has one more case, ``run``, that failed with the reason.
"""

from __future__ import annotations

import html
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET


def write_summary(summary: Mapping[str, Any], path: Path) -> Path:
    """The summary as JSON."""
    path.write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return path


def write_junit(summary: Mapping[str, Any], path: Path) -> Path:
    """One ``<testsuite>`` (the scenario) with a ``<testcase>`` per criterion."""
    results = list(summary.get("criteria", []))
    run_problem = summary.get("problem")
    failures = sum(not r["passed"] for r in results) + (1 if run_problem else 0)
    suite = ET.Element(
        "testsuite",
        name=f"hil.{summary.get('scenario', '?')}",
        tests=str(len(results) + (1 if run_problem else 0)),
        failures=str(failures),
        errors="0",
        time=f"{float(summary.get('seconds', 0.0)):.3f}",
    )
    if run_problem:
        case = ET.SubElement(suite, "testcase", classname="hil.run", name="run")
        ET.SubElement(case, "failure", message=str(run_problem)).text = str(run_problem)
    for r in results:
        case = ET.SubElement(suite, "testcase", classname="hil.criteria", name=r["criterion"])
        if not r["passed"]:
            message = f"{r['criterion']}: got {r['value']}"
            ET.SubElement(case, "failure", message=message).text = message
    ET.ElementTree(suite).write(path, encoding="utf-8", xml_declaration=True)
    return path


def _rows(mapping: Mapping[str, Any]) -> str:
    return "".join(
        f"<tr><td>{html.escape(str(k))}</td><td>{html.escape(str(v))}</td></tr>"
        for k, v in mapping.items()
    )


def write_html(summary: Mapping[str, Any], path: Path) -> Path:
    """The verdict, the criteria, the figures per device and of the run."""
    verdict = str(summary.get("verdict"))
    colour = "#070" if verdict == "pass" else "#b00"
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>spotlab hil</title><style>"
        "body{font-family:sans-serif;margin:2em}table{border-collapse:collapse}"
        "td,th{border:1px solid #bbb;padding:2px 8px}</style></head><body>",
        f"<h1>{html.escape(str(summary.get('scenario')))}: "
        f"<span style='color:{colour}'>{html.escape(verdict)}</span></h1>",
        f"<p>{html.escape(str(summary.get('description', '')))}</p>",
        f"<p>seed {summary.get('seed')}, {summary.get('duration_s')} s recorded, "
        f"{summary.get('seconds')} s in all</p>",
    ]
    if summary.get("problem"):
        parts.append(f"<p style='color:#b00'>{html.escape(str(summary['problem']))}</p>")
    parts.append("<h2>Criteria</h2><table><tr><th>criterion</th><th>value</th><th></th></tr>")
    for r in summary.get("criteria", []):
        mark = "pass" if r["passed"] else "FAIL"
        parts.append(
            f"<tr><td>{html.escape(r['criterion'])}</td><td>{html.escape(str(r['value']))}</td>"
            f"<td>{mark}</td></tr>"
        )
    parts.append("</table><h2>Devices</h2>")
    for name, figures in (summary.get("devices") or {}).items():
        parts.append(f"<h3>{html.escape(name)}</h3><table>{_rows(figures)}</table>")
    run = summary.get("run") or {}
    if run:
        parts.append(f"<h2>Run</h2><table>{_rows(run)}</table>")
    parts.append("</body></html>\n")
    path.write_text("\n".join(parts), encoding="utf-8")
    return path


__all__ = ["write_html", "write_junit", "write_summary"]
