"""A bench report against a baseline: every figure that got worse beyond its tolerance.

A figure regresses when it moved in its bad direction by more than
``relative * |baseline| + absolute`` (:data:`TOLERANCES`). Link counters (lost
frames, CRC errors, ...) tolerate no increase. Devices are matched by stream name;
a figure missing on either side (None, or a device not in the baseline) is not
compared. A conformance test that passed in the baseline and fails now is a
failure of the run anyway, and is named here too.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

#: figure -> (bad direction, relative tolerance, absolute tolerance in the figure's unit).
TOLERANCES: dict[str, tuple[str, float, float]] = {
    "latency_p50_us": ("higher", 0.5, 200.0),
    "latency_p99_us": ("higher", 1.0, 1000.0),
    "latency_max_us": ("higher", 2.0, 5000.0),
    "jitter_rms_us": ("higher", 0.5, 200.0),
    "jitter_p99_us": ("higher", 1.0, 1000.0),
    "rate_hz": ("lower", 0.01, 0.0),
    "throughput_bits_per_s": ("lower", 0.02, 0.0),
    "lost_frames": ("higher", 0.0, 0.0),
    "crc_errors": ("higher", 0.0, 0.0),
    "resyncs": ("higher", 0.0, 0.0),
    "reconnects": ("higher", 0.0, 0.0),
    "clock_drift_abs_ppm": ("higher", 0.0, 20.0),
    "recovery_reset_s": ("higher", 0.5, 0.5),
    "recovery_cable_s": ("higher", 0.5, 0.5),
}


@dataclass(frozen=True)
class Regression:
    """A figure of one device that got worse than the baseline beyond its tolerance."""

    device: str
    figure: str
    baseline: float
    value: float
    limit: float

    def describe(self) -> str:
        """``selspot: latency_p99_us 812.0 (baseline 301.0, limit 1602.0)``."""
        return (
            f"{self.device}: {self.figure} {self.value:g} "
            f"(baseline {self.baseline:g}, limit {self.limit:g})"
        )


def comparable_figures(device: Mapping[str, Any]) -> dict[str, float]:
    """The figures of one device of a report that :data:`TOLERANCES` knows, as floats."""
    figures = dict(device.get("figures") or {})
    drift = figures.get("clock_drift_ppm")
    if isinstance(drift, int | float):
        figures["clock_drift_abs_ppm"] = abs(float(drift))
    for step in device.get("disruptive") or []:
        if step.get("recovery_s") is not None:
            figures[f"recovery_{step['step']}_s"] = step["recovery_s"]
    return {
        k: float(v)
        for k, v in figures.items()
        if k in TOLERANCES and isinstance(v, int | float) and not isinstance(v, bool)
    }


def limit_of(figure: str, baseline: float) -> float:
    """The worst value of ``figure`` still within tolerance of ``baseline``."""
    direction, relative, absolute = TOLERANCES[figure]
    margin = relative * abs(baseline) + absolute
    return baseline + margin if direction == "higher" else baseline - margin


def compare(report: Mapping[str, Any], baseline: Mapping[str, Any]) -> list[Regression]:
    """Every figure of ``report`` worse than in ``baseline`` beyond its tolerance, and
    every conformance test that passed in the baseline and fails now (as figure
    ``conformance:TEST``, value 1 for failed)."""
    old = {d.get("stream"): d for d in baseline.get("devices", [])}
    out: list[Regression] = []
    for device in report.get("devices", []):
        name = str(device.get("stream"))
        before = old.get(name)
        if before is None:
            continue
        new_figures = comparable_figures(device)
        for figure, base in comparable_figures(before).items():
            if figure not in new_figures:
                continue
            value = new_figures[figure]
            limit = limit_of(figure, base)
            direction = TOLERANCES[figure][0]
            if (value > limit) if direction == "higher" else (value < limit):
                out.append(Regression(name, figure, base, value, limit))
        passed = {t["name"] for t in before.get("conformance", []) if t["outcome"] == "passed"}
        for test in device.get("conformance", []):
            if test["outcome"] == "failed" and test["name"] in passed:
                out.append(Regression(name, f"conformance:{test['name']}", 0.0, 1.0, 0.0))
    return out


__all__ = ["TOLERANCES", "Regression", "comparable_figures", "compare", "limit_of"]
