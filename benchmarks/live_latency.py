"""Live pipeline host latency: 128 markers x 8 cameras at 300 Hz, last byte in to 3-D out.

Target (TARGETS.md): p99 <= 1 ms host processing. A SELSPOT-style system cannot do it
(128 LEDs in 100 us slots take 12.8 ms: at most 78 Hz, 4 cameras), so the frames are
those of :class:`spotlab.testing.synthetic_image2d.SyntheticImage2d`: the reference rig
of TARGETS.md (8 cameras 1280x1024 on a 4 m ring, distortion), 128 markers moving on
known paths, 0.2 px noise, 300 Hz. Each frame goes through a real :class:`Session`
into a :class:`LivePipeline` holding the rig loaded from TOML; latency = the instant the
3-D points are handed to the consumers minus the frame's arrival stamp.

Sources: by default the frames are made and paced in a process of their own
(:mod:`spotlab.testing.image2d_source`: raw float32 frames over a socketpair, as a
camera system on another machine would send them); the reader waits in the kernel
(``poll``) until bytes arrive, stamps ``arrival_ns`` when the read that completes a
frame returns and decodes with ``np.frombuffer``. ``-inproc`` configurations use the
in-process device instead (it sleeps in the reader until a frame is due and stamps it
then; its frames are computed in the benchmark process).

Configurations (``--configs``):

* ``inline``: one device of 8 cameras, the pipeline in the reader thread;
* ``dispatcher``: the same with the pipeline behind the session's queue and its own
  dispatcher thread (the hand-off issue 2 measured at 1.2-9 ms outliers);
* ``inline-inproc``, ``dispatcher-inproc``: the same with the in-process source;
* ``matched``: two in-process devices of 4 cameras each on one frame clock (two
  synchronised systems), their frames matched by time, inline.

Figures per configuration (one JSON line each): p50 / p99 / max / mean latency (us),
frames over 1 ms; wall time (p50, p99) and CPU time (mean) of ``on_block`` per call;
garbage-collector passes and the longest per generation; frames in and out, incomplete
groups; how far the reader fell behind (``reader_behind_us``: arrival stamp minus the
source's write instant, or minus the due instant in-process: not in the latency); the
3-D error against the true paths (RMS, mm); the 1-minute load average at the start,
lowest and highest during the run and at the end (other programs share the cores).
The first ``--warmup`` seconds are not measured. Options: ``--poll-us`` (the reader
polls with sleeps instead of waiting in the kernel), ``--gc-freeze``,
``--keep-points`` (a PointRecorder consumer too), ``--rt-priority`` (the session's
threads under SCHED_FIFO: ``Session(realtime_priority=...)``), ``--busy N`` (N other
processes each keeping a core busy during the run).

Usage: ``python benchmarks/live_latency.py [--seconds 60] [--configs inline ...]
[--warmup 1] [--rt-priority 10] [--busy 1]``
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from spotlab.acquisition.live import LatencyStats, LiveFrame, LivePipeline, PointRecorder
from spotlab.acquisition.realtime import raise_thread
from spotlab.acquisition.session import Session
from spotlab.geometry import Rig
from spotlab.simulators.rigs import ring_rig
from spotlab.testing.image2d_source import Image2dSourceDevice
from spotlab.testing.synthetic_image2d import SyntheticImage2d

CAMERAS, MARKERS, RATE = 8, 128, 300.0
CONFIGS = ("inline", "inline-inproc", "dispatcher", "dispatcher-inproc", "matched")


class ErrorMeter:
    """Consumer: 3-D error against the device's true paths, after the warm-up."""

    def __init__(self, device: SyntheticImage2d, warmup_frames: int) -> None:
        self.device = device
        self.warmup = warmup_frames
        self.sq = 0.0
        self.points = 0
        self.unseen = 0
        self.frames = 0

    def __call__(self, frame: LiveFrame) -> None:
        self.frames += 1
        if frame.seq < self.warmup:
            return
        err = frame.points - self.device.truth(frame.seq)
        ok = np.isfinite(err[:, 0])
        self.sq += float(np.sum(err[ok] ** 2))
        self.points += int(ok.sum())
        self.unseen += int((~ok).sum())


class CostMeter:
    """Wraps ``pipeline.on_block``: its wall and CPU time per call (the reader's thread)."""

    def __init__(self, pipeline: LivePipeline) -> None:
        self.inner = pipeline.on_block
        self.wall = LatencyStats()
        self.cpu_ns = 0
        self.calls = 0
        pipeline.on_block = self  # type: ignore[method-assign]

    def __call__(self, stream: str, block: Any) -> None:
        w, c = time.monotonic_ns(), time.thread_time_ns()
        self.inner(stream, block)
        self.cpu_ns += time.thread_time_ns() - c
        self.wall.add(time.monotonic_ns() - w)
        self.calls += 1

    def reset(self) -> None:
        self.wall, self.cpu_ns, self.calls = LatencyStats(), 0, 0


class GcMeter:
    """Garbage-collector passes during the run (``gc.callbacks``): count and longest, per
    generation."""

    def __init__(self) -> None:
        self.passes = [0, 0, 0]
        self.max_us = [0.0, 0.0, 0.0]
        self._t0 = 0

    def __call__(self, phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            self._t0 = time.perf_counter_ns()
            return
        gen = info["generation"]
        self.passes[gen] += 1
        self.max_us[gen] = max(self.max_us[gen], (time.perf_counter_ns() - self._t0) / 1e3)


def _devices(config: str, rig: Rig, poll_s: float | None) -> tuple[list[Any], SyntheticImage2d]:
    """The session's devices and the one whose truth the error is measured against."""
    if config == "matched":
        t0 = time.monotonic_ns() + 200_000_000
        halves = [Rig(rig.cameras[:4]), Rig(rig.cameras[4:])]
        centre = SyntheticImage2d(rig, MARKERS, RATE).centre  # one volume for both
        pair = [
            SyntheticImage2d(
                h, MARKERS, RATE, name=f"sys{i}", seed=i, paths_seed=0, t0_ns=t0, centre=centre
            )
            for i, h in enumerate(halves)
        ]
        return list(pair), pair[0]
    if config.endswith("-inproc"):
        device = SyntheticImage2d(rig, MARKERS, RATE, name="cams", seed=0)
        return [device], device
    source = Image2dSourceDevice(rig, MARKERS, RATE, name="cams", seed=0, poll_s=poll_s)
    return [source], source.truth_device


def _run(
    config: str,
    seconds: float,
    warmup_s: float,
    rig: Rig,
    poll_s: float | None,
    freeze: bool,
    keep: bool,
    rt_priority: int,
) -> dict[str, Any]:
    devices, truth = _devices(config, rig, poll_s)
    warm = int(warmup_s * RATE)
    meter = ErrorMeter(truth, warm)
    consumers: list[Any] = [meter, PointRecorder()] if keep else [meter]
    pipeline = LivePipeline(rig, consumers, inline=not config.startswith("dispatcher"))
    cost = CostMeter(pipeline)
    gc.collect()
    session = Session(devices, [pipeline], realtime_priority=rt_priority or None)
    gcm = GcMeter()
    loads = [os.getloadavg()[0]]
    try:
        if rt_priority:
            # The session's option raises its readers and dispatchers; the main thread
            # is raised too (as spotlab console --realtime does): a normal thread
            # holding the interpreter lock while other programs preempt it would stall
            # the readers (priority inversion).
            why = raise_thread(rt_priority)
            if why is not None:
                raise SystemExit(f"live_latency: --rt-priority: {why}")
        session.start()
        # Latency of the warm-up frames is not counted: reset once they are through.
        time.sleep(warmup_s)
        if freeze:
            gc.freeze()  # what exists now (modules, rig, frames) is never scanned again
        gc.callbacks.append(gcm)
        pipeline.reset_latency()
        cost.reset()
        for device in devices:
            device.behind = LatencyStats()
        status = session.run_for(
            seconds,
            lambda _: loads.append(os.getloadavg()[0]),
            progress_interval_s=5.0,
        )
    finally:
        if gcm in gc.callbacks:
            gc.callbacks.remove(gcm)
        session.stop()
        for device in devices:
            device.close()
        if freeze:
            gc.unfreeze()
        if rt_priority:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    stats = pipeline.stats()
    lat = stats.latency
    wall = cost.wall.summary()
    return {
        "config": config,
        "source": "process" if isinstance(devices[0], Image2dSourceDevice) else "in-process",
        "reader": "kernel-wait" if poll_s is None else f"poll-{poll_s * 1e6:.0f}us",
        "gc_freeze": freeze,
        "rt_priority": rt_priority,
        "keep_points": keep,
        "cameras": CAMERAS,
        "markers": MARKERS,
        "rate_hz": RATE,
        "seconds": seconds,
        "frames_in": stats.frames_in,
        "frames_out": stats.frames_out,
        "measured": lat.frames,
        "p50_us": lat.p50_us,
        "p99_us": lat.p99_us,
        "max_us": round(lat.max_us, 1),
        "mean_us": round(lat.mean_us, 1),
        "over_1ms": lat.over_1ms,
        "on_block_wall_us_p50": wall.p50_us,
        "on_block_wall_us_p99": wall.p99_us,
        "on_block_cpu_us_mean": round(cost.cpu_ns / max(cost.calls, 1) / 1e3, 1),
        "gc_passes": gcm.passes,
        "gc_max_us": [round(v, 1) for v in gcm.max_us],
        "incomplete": stats.incomplete,
        "reader_behind_us_p50": max(d.behind.summary().p50_us for d in devices),
        "reader_behind_us_p99": max(d.behind.summary().p99_us for d in devices),
        "reader_behind_us_max": round(max(d.behind.max_ns for d in devices) / 1e3, 1),
        "failed": stats.failed,
        "overflows": sum(status.overflows.values()),
        "rms_error_mm": round(float(np.sqrt(meter.sq / max(meter.points, 1))), 4),
        "unseen_points": meter.unseen,
        "loadavg_1min": {
            "start": round(loads[0], 2),
            "min": round(min(loads), 2),
            "max": round(max(loads), 2),
            "end": round(os.getloadavg()[0], 2),
        },
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--warmup", type=float, default=1.0)
    parser.add_argument("--configs", nargs="+", choices=CONFIGS, default=list(CONFIGS))
    parser.add_argument(
        "--poll-us",
        type=float,
        default=None,
        help="the out-of-process reader polls with sleeps of this many us (default: waits "
        "in the kernel until bytes arrive)",
    )
    parser.add_argument("--gc-freeze", action="store_true", help="gc.freeze() after warm-up")
    parser.add_argument(
        "--rt-priority",
        type=int,
        default=0,
        help="run the session's threads under SCHED_FIFO at this priority (1-99; needs "
        "the right to, for example root or CAP_SYS_NICE); 0: normal scheduling",
    )
    parser.add_argument(
        "--keep-points",
        action="store_true",
        help="a PointRecorder consumer too (keeps every frame: the garbage collector runs)",
    )
    parser.add_argument(
        "--busy",
        type=int,
        default=0,
        metavar="N",
        help="N other processes, each keeping one core busy (a spinning Python loop) for "
        "the whole run: issue 19's load",
    )
    args = parser.parse_args()
    poll_s = None if args.poll_us is None else args.poll_us / 1e6
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "rig.toml"
        ring_rig(CAMERAS).save(path)
        rig = Rig.load(path)
    # started from another session, as a program a user runs beside the acquisition
    spin = [sys.executable, "-c", "while True: pass"]
    busy = [subprocess.Popen(spin, start_new_session=True) for _ in range(args.busy)]
    try:
        for config in args.configs:
            result = _run(
                config,
                args.seconds,
                args.warmup,
                rig,
                poll_s,
                args.gc_freeze,
                args.keep_points,
                args.rt_priority,
            )
            print(json.dumps({**result, "busy_processes": args.busy}), flush=True)
    finally:
        for proc in busy:
            proc.kill()
            proc.wait()


if __name__ == "__main__":
    main()
