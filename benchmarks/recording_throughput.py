"""Recording throughput and memory: the journal writer, the recorder tap, the reader.

Prints one JSON object per line. Target (TARGETS.md): recording sustained at
>= 50x the largest configuration's data rate, memory constant in recording
length. Reference rates:

* SELSPOT 4 cameras x 32 LEDs at 200 Hz: 668-byte frames, 133.6 kB/s (the
  largest configuration the SPX bandwidth rule admits at COMM:8);
* the fastest serial line, 3 Mbaud (8N1): 300 kB/s, an upper bound for any
  serial device.

Usage: ``python benchmarks/recording_throughput.py [--mb 256] [--soak-mb 1024] [--dir DIR]``
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

from spotlab.acquisition.recorder import Recorder
from spotlab.io.journal import JournalReader, JournalWriter, RecordType

SELSPOT_4X32_200HZ = 668 * 200  # bytes/s
LINE_3MBAUD = 300_000  # bytes/s
PAGE = os.sysconf("SC_PAGE_SIZE")


def rss_mb() -> float:
    """Current resident set size in MB."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * PAGE / 1e6


def peak_rss_mb() -> float:
    """Peak resident set size of this process in MB (ru_maxrss is in KiB on Linux)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 * 1.048576


def emit(**fields: object) -> None:
    print(json.dumps(fields), flush=True)


def ratios(bytes_per_s: float) -> dict[str, float]:
    return {
        "x_selspot_4x32_200hz": round(bytes_per_s / SELSPOT_4X32_200HZ, 1),
        "x_3mbaud_line": round(bytes_per_s / LINE_3MBAUD, 1),
        "target_x": 50,
    }


def bench_writer(folder: Path, chunk: int, total: int, report: bool = True) -> None:
    """JournalWriter.rx at full speed, close (flush) included, fsync excluded."""
    path = folder / f"w{chunk}.spj"
    data = os.urandom(chunk)
    n = max(1, total // chunk)
    t0 = time.perf_counter()
    with JournalWriter(path, {}, fsync_on_close=False) as j:
        s = j.add_stream("s")
        rx = j.rx
        for i in range(n):
            rx(s, data, i)
    dt = time.perf_counter() - t0
    rate = n * chunk / dt
    path.unlink()
    if not report:
        return
    emit(
        bench="journal_write",
        chunk_bytes=chunk,
        records=n,
        mb=round(n * chunk / 1e6, 1),
        seconds=round(dt, 3),
        mb_per_s=round(rate / 1e6, 1),
        us_per_record=round(dt / n * 1e6, 3),
        **ratios(rate),
    )


def bench_recorder(folder: Path, chunk: int, total: int) -> None:
    """Recorder.on_rx, the tap a driver calls from its reader thread."""
    path = folder / f"r{chunk}.spj"
    data = os.urandom(chunk)
    n = max(1, total // chunk)
    t0 = time.perf_counter()
    rec = Recorder(path, fsync_on_close=False)
    on_rx = rec.on_rx
    for i in range(n):
        on_rx("selspot0", data, i)
    rec.stop()
    dt = time.perf_counter() - t0
    rate = n * chunk / dt
    emit(
        bench="recorder_tap",
        chunk_bytes=chunk,
        records=n,
        mb_per_s=round(rate / 1e6, 1),
        us_per_record=round(dt / n * 1e6, 3),
        **ratios(rate),
    )
    path.unlink()


def bench_soak(folder: Path, chunk: int, total: int) -> None:
    """A long write and a full read: RSS sampled along the way must not grow."""
    path = folder / "soak.spj"
    data = os.urandom(chunk)
    n = max(10, total // chunk)
    samples: list[float] = []
    rss0, peak0 = rss_mb(), peak_rss_mb()
    t0 = time.perf_counter()
    with JournalWriter(path, {}, fsync_on_close=False) as j:
        s = j.add_stream("s")
        for i in range(n):
            j.rx(s, data, i)
            if i % (n // 10) == 0:
                samples.append(round(rss_mb() - rss0, 2))
    dt_write = time.perf_counter() - t0
    size = path.stat().st_size
    emit(
        bench="journal_soak_write",
        mb=round(size / 1e6, 1),
        mb_per_s=round(n * chunk / dt_write / 1e6, 1),
        rss_growth_mb_at_each_10pct=samples,
        rss_mb_start=round(rss0, 1),
        rss_growth_mb_end=round(rss_mb() - rss0, 2),
        peak_rss_growth_mb=round(peak_rss_mb() - peak0, 2),
        recording_minutes_at_selspot_4x32=round(size / SELSPOT_4X32_200HZ / 60, 1),
    )
    samples = []
    rss0, peak0 = rss_mb(), peak_rss_mb()
    t0 = time.perf_counter()
    reader = JournalReader(path)
    count = 0
    for rec in reader:
        if rec.type == RecordType.RX:
            count += 1
            if count % (n // 10) == 0:
                samples.append(round(rss_mb() - rss0, 2))
    dt_read = time.perf_counter() - t0
    emit(
        bench="journal_soak_read",
        mb=round(size / 1e6, 1),
        records=count,
        complete=reader.complete,
        rss_mb_start=round(rss0, 1),
        mb_per_s=round(size / dt_read / 1e6, 1),
        rss_growth_mb_at_each_10pct=samples,
        peak_rss_growth_mb=round(peak_rss_mb() - peak0, 2),
    )
    path.unlink()


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mb", type=float, default=128, help="MB per throughput run")
    parser.add_argument("--soak-mb", type=float, default=1024, help="MB of the memory soak")
    parser.add_argument("--dir", type=Path, default=None, help="folder for the scratch files")
    args = parser.parse_args(argv)
    total = int(args.mb * 1e6)
    with tempfile.TemporaryDirectory(dir=args.dir, prefix="spotlab-bench-") as tmp:
        folder = Path(tmp)
        emit(bench="setup", folder=str(folder), python=sys.version.split()[0], cpus=os.cpu_count())
        bench_writer(folder, 4096, total // 8, report=False)  # warm up file system and caches
        for chunk in (4096, 668, 64):
            bench_writer(folder, chunk, total if chunk >= 668 else total // 8)
        bench_recorder(folder, 4096, total)
        bench_recorder(folder, 668, total // 2)
        bench_soak(folder, 4096, int(args.soak_mb * 1e6))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
