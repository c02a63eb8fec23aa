"""Decode speed of the SPX host side: bytes in, numpy frames out, on one core.

Builds a realistic SPX byte stream (4 cameras x 32 LEDs, 668-byte frames, about
50 MB, some LEDs unseen) with numpy and the standard library's CRC — not with
the decoder's code — then measures with ``time.perf_counter``:

* throughput: the whole stream fed in reads of ``--chunk`` bytes (default 4096,
  a pty or USB-serial read) and of 64 KiB;
* per-frame host latency: one frame per ``feed`` call, as on a live link at
  low rate; p50 and p99 in µs.

Prints one JSON line. Figures, never pass/fail (see shared/design/TARGETS.md).
"""

from __future__ import annotations

import argparse
import binascii
import json
import os
import time

import numpy as np

from spotlab.drivers.selspot import SelspotDecoder

N_CAMS, N_LEDS = 4, 32
FRAME_BYTES = 28 + 5 * N_LEDS * N_CAMS


def build_stream(n_frames: int, seed: int = 0) -> bytes:
    """``n_frames`` consecutive SPX data frames (seq and frame_no from 0, 200 Hz ticks)."""
    rng = np.random.default_rng(seed)
    n_rec = N_LEDS * N_CAMS
    frames = np.zeros((n_frames, FRAME_BYTES), dtype=np.uint8)
    i = np.arange(n_frames, dtype=np.uint32)
    payload_len = FRAME_BYTES - 12
    frames[:, 0], frames[:, 1], frames[:, 2], frames[:, 3] = 0xA5, 0x5A, 0x01, 0x10
    frames[:, 4:6] = (i & 0xFFFF).astype("<u2").view(np.uint8).reshape(-1, 2)
    frames[:, 6:8] = np.frombuffer(np.uint16(payload_len).astype("<u2").tobytes(), np.uint8)
    frames[:, 10:14] = i.astype("<u4").view(np.uint8).reshape(-1, 4)
    frames[:, 14:18] = (i * 5000).astype("<u4").view(np.uint8).reshape(-1, 4)
    frames[:, 20:22] = np.frombuffer(np.uint16(n_rec).astype("<u2").tobytes(), np.uint8)
    frames[:, 22:24] = np.frombuffer(np.uint16(100).astype("<u2").tobytes(), np.uint8)
    frames[:, 24], frames[:, 25] = N_LEDS, N_CAMS
    x = rng.integers(0, 4095, (n_frames, n_rec), dtype=np.uint32)
    y = rng.integers(0, 4095, (n_frames, n_rec), dtype=np.uint32)
    seen = rng.random((n_frames, n_rec)) > 0.1
    x[~seen], y[~seen] = 0xFFF, 0xFFF
    w = x | (y << 12)
    rec = frames[:, 26:-2].reshape(n_frames, n_rec, 5)
    rec[..., 0], rec[..., 1], rec[..., 2] = w & 0xFF, (w >> 8) & 0xFF, w >> 16
    rec[..., 3] = rng.integers(0, 256, (n_frames, n_rec), dtype=np.uint8)
    rec[..., 4] = np.where(seen, 0x01, 0x04)
    hcrc = np.empty(n_frames, dtype="<u2")
    pcrc = np.empty(n_frames, dtype="<u2")
    for k in range(n_frames):
        hcrc[k] = binascii.crc_hqx(frames[k, :8].tobytes(), 0xFFFF)
        pcrc[k] = binascii.crc_hqx(frames[k, 10:-2].tobytes(), 0xFFFF)
    frames[:, 8:10] = hcrc.view(np.uint8).reshape(-1, 2)
    frames[:, -2:] = pcrc.view(np.uint8).reshape(-1, 2)
    return frames.tobytes()


def throughput(data: bytes, chunk: int, repeats: int) -> float:
    """Best wall time (s) to decode ``data`` fed in ``chunk``-byte reads."""
    best = float("inf")
    for _ in range(repeats):
        dec = SelspotDecoder(N_CAMS, N_LEDS, 100)
        dec.mark_discontinuity()
        t0 = time.perf_counter()
        frames = 0
        for pos in range(0, len(data), chunk):
            frames += len(dec.feed(data[pos : pos + chunk], pos))
        elapsed = time.perf_counter() - t0
        expected = len(data) // FRAME_BYTES
        if frames != expected or dec.stats.crc_errors or dec.stats.lost_frames:
            raise SystemExit(f"decoding is wrong: {frames} of {expected} frames, {dec.stats}")
        best = min(best, elapsed)
    return best


def latency_us(data: bytes, n: int) -> tuple[float, float]:
    """p50 and p99 of the time (µs) to decode one frame fed on its own."""
    dec = SelspotDecoder(N_CAMS, N_LEDS, 100)
    times = np.empty(n)
    for k in range(n):
        frame = data[k * FRAME_BYTES : (k + 1) * FRAME_BYTES]
        t0 = time.perf_counter()
        block = dec.feed(frame, k)
        times[k] = time.perf_counter() - t0
        if len(block) != 1:
            raise SystemExit("decoding is wrong: one frame in, not one frame out")
    p50, p99 = np.percentile(times[n // 10 :] * 1e6, [50, 99])  # skip warm-up
    return float(p50), float(p99)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--megabytes", type=float, default=50.0)
    parser.add_argument("--chunk", type=int, default=4096)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one core
    n_frames = int(args.megabytes * 1e6 // FRAME_BYTES)
    data = build_stream(n_frames)
    t_chunk = throughput(data, args.chunk, args.repeats)
    t_big = throughput(data, 65536, args.repeats)
    p50, p99 = latency_us(data, min(n_frames, 20_000))
    print(
        json.dumps(
            {
                "benchmark": "decode_selspot",
                "mb_per_s": round(len(data) / t_chunk / 1e6, 1),
                "frames_per_s": round(n_frames / t_chunk),
                "bytes": len(data),
                "frame_bytes": FRAME_BYTES,
                "chunk_bytes": args.chunk,
                "mb_per_s_64k_chunks": round(len(data) / t_big / 1e6, 1),
                "latency_us_p50": round(p50, 1),
                "latency_us_p99": round(p99, 1),
                "cores": 1,
            }
        )
    )


if __name__ == "__main__":
    main()
