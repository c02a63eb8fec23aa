"""Clock-model alignment error against the truth, per fitting method and clock fault.

Prints one JSON object per line: scenario, method, max and RMS alignment error (µs)
of every frame's session time against its true time, after removing nothing (the
reference is the truth's own clock), the drift the model reports (ppm), the events
found, and the fit time (s). Target (TARGETS.md): within 50 µs of the truth for drift
up to +-500 ppm, steps, counter wraps and jitter, after synchronisation by timer edges.

Scenarios: 60 s at 100 Hz with 2 µs RMS frame trigger jitter, device clock of 1 MHz;
timer reference of 0.1 µs; arrival stamps with 0.2 ms latency plus 1 ms mean
exponential queueing; probes as liblsl (8 every 2 s) with one-way delays of
100 µs + exp(200 µs) up and 300 µs + exp(200 µs)
down (asymmetric by 200 µs).

Usage: ``python benchmarks/clock_alignment.py [--seconds 60] [--rate 100] [--jitter 2e-6]``
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable

import numpy as np

from spotlab.acquisition.clocks import (
    ClockModel,
    EdgeClockEstimator,
    dejitter_arrivals,
    fit_edges,
    fit_probes,
    refine_model,
)
from spotlab.acquisition.clocks.synthetic import (
    SyntheticClock,
    arrival_times,
    frame_times,
    probe_exchanges,
    timer_reference,
)

SCENARIOS: dict[str, SyntheticClock] = {
    "drift+500": SyntheticClock(offset_s=123.4, drift_ppm=500.0),
    "drift-500": SyntheticClock(offset_s=-7.0, drift_ppm=-500.0),
    "step+1ms": SyntheticClock(offset_s=5.0, drift_ppm=200.0, steps=[(30.0, 1e-3)]),
    "step-5ms": SyntheticClock(offset_s=5.0, drift_ppm=-150.0, steps=[(30.0, -5e-3)]),
    "reset": SyntheticClock(offset_s=50.0, drift_ppm=100.0, resets=[(30.0, 0.001)]),
    "wrap32": SyntheticClock(offset_s=4000.0, drift_ppm=-300.0, wraps=[(20.0, 1, 32)]),
}


def errors(
    model: Callable[[np.ndarray], np.ndarray], ticks: np.ndarray, truth: np.ndarray
) -> dict[str, float]:
    err = model(ticks) - truth
    return {
        "max_us": float(np.max(np.abs(err)) * 1e6),
        "rms_us": float(np.sqrt(np.mean(err**2)) * 1e6),
    }


Fitted = Callable[[np.ndarray], np.ndarray]


def fitters(
    clock: SyntheticClock, truth: np.ndarray, ticks: np.ndarray, ref: np.ndarray, seconds: float
) -> list[tuple[str, Callable[[], Fitted]]]:
    """(method, fit) for each fitting method on one scenario."""
    resets = bool(clock.resets)
    n = ticks.size

    def edges() -> ClockModel:
        return fit_edges(ticks, ref, clock.tick_hz, allow_resets=resets)

    def online() -> ClockModel:
        est = EdgeClockEstimator(clock.tick_hz, allow_resets=resets)
        for lo in range(0, n, 50):
            est.update(ticks[lo : lo + 50], ref[lo : lo + 50])
        return est.model

    def refined() -> Fitted:
        return refine_model(edges(), ticks, ref, ref_resolution_s=1e-7)

    def arrivals() -> ClockModel:
        arr = arrival_times(truth, seed=2)
        return dejitter_arrivals(ticks, arr, clock.tick_hz, allow_resets=resets).model

    def probes() -> ClockModel:
        log = probe_exchanges(
            clock, seconds, up_s=(100e-6, 200e-6), down_s=(300e-6, 200e-6), seed=3
        )
        return fit_probes(
            log.t0_s, log.t1_ticks, log.t2_ticks, log.t3_s, clock.tick_hz, allow_resets=resets
        )

    return [
        ("edges", edges),
        ("edges-online", online),
        ("edges+spline", refined),
        ("arrivals", arrivals),
        ("probes", probes),
    ]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--rate", type=float, default=100.0)
    parser.add_argument("--jitter", type=float, default=2e-6, help="frame trigger jitter, s")
    args = parser.parse_args(argv)
    n = int(args.seconds * args.rate)
    for name, clock in SCENARIOS.items():
        truth = frame_times(n, args.rate, seed=1, jitter_s=args.jitter)
        ticks = clock.ticks(truth)
        ref = timer_reference(truth)
        rows = fitters(clock, truth, ticks, ref, args.seconds)
        for method, fit in rows:
            start = time.perf_counter()
            try:
                model = fit()
            except Exception as exc:
                print(
                    json.dumps(
                        {
                            "bench": "clock_alignment",
                            "scenario": name,
                            "method": method,
                            "error": f"{type(exc).__name__}: {exc}",
                        }
                    )
                )
                continue
            elapsed = time.perf_counter() - start
            base = model.model if hasattr(model, "model") else model
            row: dict[str, object] = {
                "bench": "clock_alignment",
                "scenario": name,
                "method": method,
                "frames": n,
                **errors(model, ticks, truth),
                "drift_ppm": round(base.drift_ppm, 3),
                "jitter_us": round(base.jitter_s * 1e6, 3),
                "n_events": len(base.events),
                "events": [f"{e.kind}:{e.size_s * 1e3:+.3f}ms" for e in base.events[:4]],
                "fit_s": round(elapsed, 4),
            }
            print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
