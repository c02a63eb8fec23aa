"""Host processing latency per frame of the live SPX path, last byte in to a sink.

For each configuration a :class:`~spotlab.drivers.selspot.SelspotDriver` streams
from the simulator inside a running :class:`~spotlab.acquisition.session.Session`
and a sink stamps ``time.monotonic_ns()`` in ``on_block``. A frame's latency is
that stamp minus ``block.arrival_ns`` (the serial link's stamp, taken as the
read that brought the frame's last byte returned). It covers the wire taps
(the recorder's ``on_rx`` when recording), the decoder, the driver's
bookkeeping, the session's reader, its per-sink queue and the wake-up of the
sink's dispatcher thread. It does not cover the kernel, the pty or the USB
adapter before the read returned.

Configurations: 4 cameras x 32 LEDs at 200 Hz (668-byte frames, 2 Mbaud) and
4 x 128 at 70 Hz (2588-byte frames, 3 Mbaud); transports:

* ``pty``: a real pseudo-terminal served by ``serve_pty`` in a child process
  (as a real device is outside the host process: the simulator's physics
  never competes with the host for the GIL);
* ``pty-inproc``: the same, with ``serve_pty`` in this process (``--inproc``);
  shows what an in-process simulator costs the host;
* ``sim``: the in-process ``sim://`` URL (the device advances inside the
  reader's own reads, before the arrival stamp).

Each with and without a :class:`~spotlab.acquisition.recorder.Recorder` taking
the raw bytes. The first ``--warmup`` seconds of frames are not measured.

Besides the total, the parts (p50 / p99 / max in µs):

* ``tap_us``: arrival stamp to the start of ``decoder.feed`` (the taps);
* ``decode_us``: ``decoder.feed`` of the read that completed the frame(s);
* ``handoff_us``: end of ``feed`` to ``on_block`` (driver, session queue, thread switch).

``worst_frame`` splits the slowest frame into those parts; ``loadavg_1min`` is
the machine's load before and after the run (other programs share the cores);
``reads_per_frame`` how many reads the link made per frame (the recorder
journals each one).

Prints one JSON line per configuration. Figures, never pass/fail (TARGETS.md);
``overflows`` (blocks a sink's queue dropped) and ``lost_frames`` must be 0.

Usage: ``python benchmarks/latency_selspot.py [--seconds 10] [--transport pty sim]
[--config 4x32@200 4x128@70] [--inproc]``
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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

import spotlab.simulators  # noqa: F401  (registers sim:// with pyserial)
from spotlab.acquisition.recorder import Recorder
from spotlab.acquisition.session import Session, SinkBase
from spotlab.core.frames import FrameBlock
from spotlab.drivers.selspot import SelspotDriver
from spotlab.simulators.service import SelspotSimOptions, serve_pty, url_for

CONFIGS = {"4x32@200": (4, 32, 200.0), "4x128@70": (4, 128, 70.0)}
TRANSPORTS = ("pty", "sim")


@dataclass
class Config:
    name: str
    cameras: int
    leds: int
    rate_hz: float

    def sim_options(self, seed: int) -> SelspotSimOptions:
        return SelspotSimOptions(
            cameras=self.cameras, leds=self.leds, rate_hz=self.rate_hz, seed=seed
        )


class LatencySink(SinkBase):
    """Stamps every block on delivery; keeps per-frame latencies after the warm-up."""

    name = "latency"

    def __init__(self, capacity: int, warmup_ns: int, decode_marks: dict[int, tuple[int, int]]):
        self.total = np.zeros(capacity, dtype=np.int64)
        self.tap = np.zeros(capacity, dtype=np.int64)
        self.decode = np.zeros(capacity, dtype=np.int64)
        self.handoff = np.zeros(capacity, dtype=np.int64)
        self.n = 0
        self.frames_seen = 0
        self.blocks = 0
        self.frames_per_block_max = 0
        self.warmup_ns = warmup_ns
        self.t_first: int | None = None
        self._marks = decode_marks
        self.unmarked = 0
        self.overcapacity = 0

    def on_block(self, stream: str, block: FrameBlock) -> None:
        t = time.monotonic_ns()
        mark = self._marks.pop(id(block), None)
        k = len(block)
        self.frames_seen += k
        self.blocks += 1
        self.frames_per_block_max = max(self.frames_per_block_max, k)
        arrival = block.arrival_ns
        if self.t_first is None:
            self.t_first = int(arrival[0])
        if int(arrival[0]) - self.t_first < self.warmup_ns:
            return
        if mark is None:
            self.unmarked += 1
            return
        if self.n + k > self.total.shape[0]:
            self.overcapacity += k
            return
        start, end = mark
        sl = slice(self.n, self.n + k)
        self.total[sl] = t - arrival
        self.tap[sl] = start - arrival
        self.decode[sl] = end - start
        self.handoff[sl] = t - end
        self.n += k


class GcWatch:
    """Pauses of Python's cyclic garbage collector while measuring."""

    def __init__(self) -> None:
        self.pauses_ns: list[int] = []
        self._t0 = 0

    def __call__(self, phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            self._t0 = time.perf_counter_ns()
        else:
            self.pauses_ns.append(time.perf_counter_ns() - self._t0)

    def __enter__(self) -> GcWatch:
        gc.callbacks.append(self)
        return self

    def __exit__(self, *exc: object) -> None:
        gc.callbacks.remove(self)


def percentiles_us(values_ns: np.ndarray, prefix: str = "") -> dict[str, float | None]:
    if not values_ns.shape[0]:
        return {f"{prefix}p50_us": None, f"{prefix}p90_us": None, f"{prefix}p99_us": None}
    p50, p90, p99 = np.percentile(values_ns, [50, 90, 99]) / 1e3
    out = {f"{prefix}p50_us": round(p50, 1), f"{prefix}p90_us": round(p90, 1)}
    out[f"{prefix}p99_us"] = round(p99, 1)
    out[f"{prefix}max_us"] = round(float(values_ns.max()) / 1e3, 1)
    return out


def instrument_decoder(driver: SelspotDriver, marks: dict[int, tuple[int, int]]) -> list[int]:
    """Time ``decoder.feed`` in the live path; blocks are matched to sinks by identity.

    Returns a one-element list counting the reads (calls of ``feed``).
    """
    decoder = driver.decoder
    feed = decoder.feed
    clock = time.monotonic_ns
    reads = [0]

    def timed_feed(data: Any, arrival_ns: int) -> FrameBlock:
        reads[0] += 1
        start = clock()
        block = feed(data, arrival_ns)
        if len(block):
            marks[id(block)] = (start, clock())
        return block

    decoder.feed = timed_feed
    return reads


class ChildPty:
    """``serve_pty`` in a child process (this script with ``--serve``)."""

    def __init__(self, options: SelspotSimOptions) -> None:
        fields = ("cameras", "leds", "rate_hz", "seed")
        spec = json.dumps({name: getattr(options, name) for name in fields})
        self.proc = subprocess.Popen(
            [sys.executable, __file__, "--serve", spec],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline().strip()
        if not line:
            raise SystemExit("the simulator child did not print its device path")
        self.path = line
        self.stats: dict[str, Any] = {}

    def stop(self) -> None:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.close()
        rest = self.proc.stdout.read().strip()
        self.proc.wait(timeout=30)
        if rest:
            self.stats = json.loads(rest.splitlines()[-1])


def serve_child(spec: str) -> int:
    """Child process: serve one simulated device on a pty until stdin closes."""
    with serve_pty(SelspotSimOptions(**json.loads(spec))) as server:
        print(server.path, flush=True)
        sys.stdin.read()
        stats = dict(server.stats)
    print(json.dumps(stats), flush=True)
    return 0


def run_one(
    config: Config, transport: str, recorder: bool, seconds: float, warmup: float, seed: int
) -> dict[str, Any]:
    load_before = round(os.getloadavg()[0], 2)
    options = config.sim_options(seed)
    child: ChildPty | None = None
    inproc_server = None
    if transport == "pty":
        child = ChildPty(options)
        port = child.path
    elif transport == "pty-inproc":
        inproc_server = serve_pty(options)
        port = str(inproc_server.path)
    else:
        port = url_for(options)
    marks: dict[int, tuple[int, int]] = {}
    capacity = int(config.rate_hz * (seconds + warmup + 5) * 1.2) + 100
    sink = LatencySink(capacity, int(warmup * 1e9), marks)
    try:
        with tempfile.TemporaryDirectory(prefix="spotlab-latency-") as tmp:
            driver = SelspotDriver(
                port,
                cameras=config.cameras,
                leds=config.leds,
                rate_hz=config.rate_hz,
                baud="auto",
            )
            reads = instrument_decoder(driver, marks)
            sinks: list[Any] = [sink]
            rec = None
            if recorder:
                rec = Recorder(Path(tmp) / "run.spj")
                sinks.append(rec)
            session = Session([driver], sinks, close_devices=True)
            with GcWatch() as gcw:
                status = session.run_for(seconds + warmup)
            journal_bytes = rec.bytes_written if rec is not None else 0
    finally:
        if child is not None:
            child.stop()
        if inproc_server is not None:
            inproc_server.stop()
    stats = driver.stats
    n = sink.n
    total = sink.total[:n]
    worst: dict[str, float] = {}
    if n:
        w = int(np.argmax(total))
        parts = (("total", sink.total), ("tap", sink.tap), ("decode", sink.decode))
        worst = {f"{k}_us": round(float(v[w]) / 1e3, 1) for k, v in parts}
        worst["handoff_us"] = round(float(sink.handoff[w]) / 1e3, 1)
    result: dict[str, Any] = {
        "benchmark": "latency_selspot",
        "transport": transport,
        "config": config.name,
        "recorder": recorder,
        **percentiles_us(total),
        "frames_measured": n,
        "frames": stats.frames,
        "blocks": sink.blocks,
        "max_frames_per_block": sink.frames_per_block_max,
        "reads_per_frame": round(reads[0] / max(stats.frames, 1), 2),
        "decode_us": percentiles_us(sink.decode[:n], ""),
        "tap_us": percentiles_us(sink.tap[:n], ""),
        "handoff_us": percentiles_us(sink.handoff[:n], ""),
        "worst_frame": worst,
        "over_1ms": int((total > 1_000_000).sum()),
        "overflows": sum(status.overflows.values()),
        "lost_frames": stats.lost_frames,
        "crc_errors": stats.crc_errors,
        "reconnects": stats.reconnects,
        "device_errors": status.errors,
        "gc_pauses": len(gcw.pauses_ns),
        "gc_max_us": round(max(gcw.pauses_ns, default=0) / 1e3, 1),
        "baud": driver.config.baud,
        "frame_bytes": driver.decoder.frame_bytes,
        "seconds": seconds,
        "switch_interval_ms": round(sys.getswitchinterval() * 1e3, 3),
        "loadavg_1min": [load_before, round(os.getloadavg()[0], 2)],
    }
    if recorder:
        result["journal_mb"] = round(journal_bytes / 1e6, 2)
    if child is not None:
        result["pty_overrun_bytes"] = child.stats.get("overrun_bytes")
    if sink.unmarked or sink.overcapacity:
        result["unmeasured_blocks"] = sink.unmarked + sink.overcapacity
    return result


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="measured seconds per run")
    parser.add_argument("--warmup", type=float, default=1.0, help="seconds not measured")
    parser.add_argument("--transport", nargs="+", choices=TRANSPORTS, default=list(TRANSPORTS))
    parser.add_argument("--config", nargs="+", choices=sorted(CONFIGS), default=list(CONFIGS))
    parser.add_argument("--recorder", choices=("both", "on", "off"), default="both")
    parser.add_argument(
        "--inproc", action="store_true", help="also run pty with the simulator in this process"
    )
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument(
        "--switch-interval-ms",
        type=float,
        help="set sys.setswitchinterval (Python's default is 5 ms) to see its share of outliers",
    )
    parser.add_argument("--serve", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve:
        return serve_child(args.serve)
    if args.switch_interval_ms is not None:
        sys.setswitchinterval(args.switch_interval_ms / 1e3)
    transports = list(args.transport)
    if args.inproc and "pty" in transports:
        transports.insert(transports.index("pty") + 1, "pty-inproc")
    recorders = {"both": (False, True), "on": (True,), "off": (False,)}[args.recorder]
    for name in args.config:
        config = Config(name, *CONFIGS[name])
        for transport in transports:
            for recorder in recorders:
                result = run_one(config, transport, recorder, args.seconds, args.warmup, args.seed)
                print(json.dumps(result), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
