"""Synchroniser: resampling throughput and the slot-skew bias with and without correction.

Prints one JSON object per line.

``resample`` rows: one photodiode stream of 128 markers x 8 cameras x (x, y) at 300 Hz
with slot offsets and 5 % of its samples missing in runs of 10 frames, resampled at
300 Hz instants; ``in_samples_per_s`` counts the stream's values (F x 128 x 8 x 2) per
second of wall time, ``out_values_per_s`` the values given at the instants.

``synchronise`` row: the same stream with a 100 Hz 3-D stream and a 60 Hz 2-D stream
(different families and clocks) through :class:`Synchroniser`.

``slot_skew`` rows: the reference rig of TARGETS.md (8 cameras on a 4 m ring, 0.2 px
noise), 128 LEDs fired in 100 us slots at 75 Hz, a cluster moving in a straight line at
5 m/s for 1 s; every camera reads LED k at frame time + (k + 1/2) slot. Mean error
along the motion at the frame instants for LEDs 0, 63, 127, with and without slot
correction, against the truth; ``expected_mm`` is v (k + 1/2) slot.

Usage: ``python benchmarks/synchroniser.py [--seconds 10 60] [--repeat 3]``
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time

import numpy as np

from spotlab.acquisition.synchroniser import StreamInput, Synchroniser, resample
from spotlab.core import StreamSpec
from spotlab.reconstruction import triangulate
from spotlab.simulators.rigs import ring_rig

N_MARKERS, N_CAMERAS = 128, 8


def peak_rss_mb() -> float:
    """Peak resident set size of this process so far, MB."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3


def photodiode_stream(seconds: float, rng: np.random.Generator) -> StreamInput:
    """128 markers x 8 cameras x 2 at 300 Hz, 20 us slots, 5 % missing in runs of 10."""
    rate, slot = 300.0, 20e-6
    n = int(seconds * rate)
    t = 0.0123 + np.arange(n) / rate * (1 + 150e-6)
    phase = rng.uniform(0, 2 * np.pi, size=(1, N_MARKERS, N_CAMERAS, 2))
    ts = t[:, None, None, None] + ((np.arange(N_MARKERS) + 0.5) * slot)[None, :, None, None]
    data = 2048.0 + 800.0 * np.sin(2 * np.pi * 0.8 * ts + phase)
    starts = rng.integers(0, n - 10, size=(n * N_MARKERS * N_CAMERAS) // 200)
    marker = rng.integers(0, N_MARKERS, size=starts.size)
    camera = rng.integers(0, N_CAMERAS, size=starts.size)
    for run in range(10):
        data[starts + run, marker, camera, :] = np.nan
    spec = StreamSpec("psd", "image2d", N_CAMERAS, N_MARKERS, rate, 1e6, slot_period_s=slot)
    return StreamInput(spec, np.arange(n), t, data, clock_rate=1 + 150e-6)


def other_streams(seconds: float) -> list[StreamInput]:
    """A 100 Hz point3d stream of 20 markers and a 60 Hz blobs2d stream of 30."""
    out = []
    for name, kind, rate, m, v in (
        ("opto", "point3d", 100.0, 20, 3),
        ("video", "blobs2d", 60.0, 30, 2),
    ):
        n = int(seconds * rate)
        t = 0.004 + np.arange(n) / rate
        data = np.sin(t)[:, None, None, None] * np.ones((1, m, 1, v))
        spec = StreamSpec(name, kind, 1, m, rate, 1e6)  # type: ignore[arg-type]
        out.append(StreamInput(spec, np.arange(n), t, data))
    return out


def bench_resample(seconds: float, repeat: int) -> None:
    rng = np.random.default_rng(0)
    psd = photodiode_stream(seconds, rng)
    sync = Synchroniser([psd])
    instants = sync.instants()
    data = np.asarray(psd.data)
    offsets = (np.arange(N_MARKERS) + 0.5) * 20e-6 * psd.clock_rate
    best = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        r = resample(psd.frame_times, data, instants, offsets=offsets, seq=psd.seq)
        best = min(best, time.perf_counter() - start)
    given = int(np.count_nonzero(r.valid))
    row = {
        "bench": "synchroniser",
        "case": "resample",
        "seconds": seconds,
        "frames": int(data.shape[0]),
        "in_values": int(data.size),
        "instants": int(instants.size),
        "best_s": round(best, 4),
        "in_samples_per_s": round(data.size / best),
        "out_values_per_s": round(r.values.size / best),
        "given_fraction": round(given / r.values.size, 4),
        "missing_fraction_in": round(float(np.isnan(data).mean()), 4),
        "peak_rss_mb": round(peak_rss_mb(), 1),
    }
    print(json.dumps(row), flush=True)
    streams = [psd, *other_streams(seconds)]
    start = time.perf_counter()
    out = Synchroniser(streams).resample()
    took = time.perf_counter() - start
    row = {
        "bench": "synchroniser",
        "case": "synchronise",
        "seconds": seconds,
        "streams": {s.name: [s.spec.kind, s.spec.rate_hz] for s in streams},
        "instants": int(out.times.size),
        "time_s": round(took, 4),
        "valid_fraction": {k: round(v.valid_fraction, 4) for k, v in out.stats.items()},
        "peak_rss_mb": round(peak_rss_mb(), 1),
    }
    print(json.dumps(row), flush=True)


def bench_slot_skew() -> None:
    rng = np.random.default_rng(1)
    rig = ring_rig(8)
    rate, slot, speed = 75.0, 100e-6, 5000.0
    n = 76
    frame_t = 0.25 + np.arange(n) / rate
    offsets = (np.arange(N_MARKERS) + 0.5) * slot
    body = rng.uniform(-80.0, 80.0, size=(N_MARKERS, 3)) + np.array([0.0, 0.0, 900.0])

    def where(t: np.ndarray) -> np.ndarray:
        """Each LED at times ``t`` (..., M): a straight line along x, mm (..., M, 3)."""
        return body + (speed * (t - 0.75))[..., None] * np.array([1.0, 0.0, 0.0])

    X = where(frame_t[:, None] + offsets)  # (F, M, 3) at the slot times
    uv = rig.project(X) + rng.normal(0.0, 0.2, size=(len(rig), n, N_MARKERS, 2))
    spec = StreamSpec("sel", "image2d", len(rig), N_MARKERS, rate, 1e6, slot_period_s=slot)
    stream = StreamInput(spec, np.arange(n), frame_t, np.moveaxis(uv, 0, 2))
    instants = frame_t[1:-1]
    truth = where(np.broadcast_to(instants[:, None], (instants.size, N_MARKERS)))
    for corrected in (True, False):
        res = Synchroniser([stream], slot_correction=corrected).resample(instants)
        P = triangulate(rig, np.moveaxis(res.streams["sel"].values, 2, 0))
        along = (P - truth)[..., 0]  # error along the motion, mm (T, M)
        for k in (0, 63, 127):
            print(
                json.dumps(
                    {
                        "bench": "synchroniser",
                        "case": "slot_skew",
                        "slot_correction": corrected,
                        "led": k,
                        "mean_along_mm": round(float(along[:, k].mean()), 3),
                        "se_mm": round(float(along[:, k].std() / np.sqrt(along.shape[0])), 3),
                        "expected_mm": 0.0 if corrected else round(speed * offsets[k], 3),
                        "rms_3d_mm_all_leds": round(
                            float(np.sqrt(np.mean(np.sum((P - truth) ** 2, axis=-1)))), 3
                        ),
                    }
                ),
                flush=True,
            )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, nargs="+", default=[10.0, 60.0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    for seconds in args.seconds:
        bench_resample(seconds, args.repeat)
    bench_slot_skew()
    return 0


if __name__ == "__main__":
    sys.exit(main())
