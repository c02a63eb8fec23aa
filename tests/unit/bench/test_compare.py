"""A bench report against its baseline: what counts as worse, and by how much."""

from __future__ import annotations

from typing import Any

from spotlab.bench.compare import TOLERANCES, compare, limit_of


def _report(**figures: Any) -> dict[str, Any]:
    tests = figures.pop("tests", [])
    steps = figures.pop("steps", [])
    return {
        "devices": [
            {"stream": "selspot", "conformance": tests, "figures": figures, "disruptive": steps}
        ]
    }


def test_within_tolerance_is_no_regression() -> None:
    old = _report(latency_p99_us=1000.0, lost_frames=0, rate_hz=200.0, clock_drift_ppm=10.0)
    new = _report(latency_p99_us=2900.0, lost_frames=0, rate_hz=199.0, clock_drift_ppm=-25.0)
    assert compare(new, old) == []


def test_every_worse_figure_is_named_with_its_limit() -> None:
    old = _report(latency_p99_us=1000.0, lost_frames=0, rate_hz=200.0, clock_drift_ppm=1.0,
                  steps=[{"step": "reset", "recovery_s": 1.0}])  # fmt: skip
    new = _report(latency_p99_us=3100.0, lost_frames=2, rate_hz=190.0, clock_drift_ppm=-40.0,
                  steps=[{"step": "reset", "recovery_s": 3.0}])  # fmt: skip
    found = {r.figure: r for r in compare(new, old)}
    assert set(found) == {
        "latency_p99_us", "lost_frames", "rate_hz", "clock_drift_abs_ppm", "recovery_reset_s"
    }  # fmt: skip
    assert found["latency_p99_us"].limit == 3000.0
    assert found["rate_hz"].limit == 198.0
    assert "lost_frames 2 (baseline 0, limit 0)" in found["lost_frames"].describe()


def test_better_figures_and_unknown_devices_are_not_regressions() -> None:
    old = _report(latency_p50_us=500.0, lost_frames=3)
    new = _report(latency_p50_us=100.0, lost_frames=0)
    assert compare(new, old) == []
    other = {"devices": [{"stream": "timer", "figures": {"lost_frames": 0}}]}
    assert compare(_report(lost_frames=9), other) == []


def test_a_test_that_passed_before_and_fails_now_is_named() -> None:
    name = "test_bad_crc_is_error_04"
    old = _report(tests=[{"name": name, "outcome": "passed"}])
    new = _report(tests=[{"name": name, "outcome": "failed"}])
    (r,) = compare(new, old)
    assert r.figure == f"conformance:{name}"


def test_limits_go_the_bad_way() -> None:
    for figure, (direction, _, _) in TOLERANCES.items():
        limit = limit_of(figure, 100.0)
        assert (limit >= 100.0) if direction == "higher" else (limit <= 100.0), figure
