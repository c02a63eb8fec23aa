"""The device never sends faster than its baud rate: 10 bit times per byte, in simulated time."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from _simwire import MS, T0, Host, cmd, decode

from spotlab.simulators import wire
from spotlab.simulators.line import BIT_NS, TxLine, garble
from spotlab.simulators.selspot import SelspotDevice


@pytest.mark.parametrize("baud", [9_600, 115_200, 921_600, 2_000_000, 3_000_000])
def test_n_bytes_take_n_times_10_over_baud(baud: int) -> None:
    line = TxLine(lambda c, o: None, free_ns=T0)
    n = 5000
    line.enqueue(bytes(range(256)) * 19 + bytes(136), T0, baud, "reply")
    assert line.chunks[0].end_ns == T0 + n * BIT_NS // baud
    got, times = 0, []
    step = max(1, BIT_NS // baud // 3)
    t = T0
    while got < n:
        t += step
        seg = line.release(t)
        k = sum(len(s.data) for s in seg)
        got += k
        if k:
            times.append((t, got))
    # After every release, exactly the bytes whose 10 bit times have elapsed are out
    # (byte i is complete at floor((i + 1) * 10 / baud) in whole ns).
    for t, count in times:
        assert count == min(n, ((t - T0 + 1) * baud - 1) // BIT_NS)
    duration = times[-1][0] - T0
    assert duration == pytest.approx(n * 10 / baud * 1e9, abs=step + 1)


def test_chunks_queue_behind_each_other() -> None:
    line = TxLine(lambda c, o: None, free_ns=T0)
    a = line.enqueue(b"x" * 100, T0, 115_200, "reply")
    b = line.enqueue(b"y" * 10, T0 + 1000, 115_200, "reply")
    assert b.start_ns == a.end_ns
    assert line.backlog(T0) == 110
    assert line.backlog(a.end_ns) == 10
    c = line.enqueue(b"z", b.end_ns + 5 * MS, 115_200, "reply")
    assert c.start_ns == b.end_ns + 5 * MS  # an idle line starts at once


def test_stream_output_is_limited_by_the_line(make_device: Callable[..., SelspotDevice]) -> None:
    # 4 x 32 at 200 Hz needs 1.336 Mbit/s of the 2 Mbaud line: each 668-byte frame takes 3.34 ms.
    h = Host(make_device())
    h.configure(4, 32, 200_000)
    h.buf.clear()
    h.send(cmd("START:"), baud=2_000_000)
    counts = []
    for _ in range(2000):
        got = h.wait(100_000)  # 0.1 ms steps
        counts.append(len(got))
    c = np.array(counts)
    # Never more than 20 bytes (10 bit times at 2 Mbaud = 5 us each) per 0.1 ms.
    assert c.max() == 20
    frames = decode(bytes(h.buf)).frames
    assert len(frames) == 39
    # START's last byte arrives 55 us after the write; its OKAY (9 bytes) goes out at once;
    # frame k is ready (33 slots later) at 55 us + k * 5 ms + 3.3 ms and takes 3.34 ms:
    # by 200 ms frames 0-38 are out and 329 bytes of frame 39.
    assert c.sum() == 9 + 39 * 668 + 329
    busy = (c[100:1900] > 0).mean()
    assert busy == pytest.approx(3.34 / 5, abs=0.02)  # bins partly busy count as busy


def test_comm_9600_reply_timing(make_device: Callable[..., SelspotDevice]) -> None:
    h = Host(make_device())
    h.wait(20 * MS)
    h.buf.clear()
    raw = cmd("VER:0")  # 10 bytes in, 27 bytes out: (10 + 27) * 10 / 9600 = 38.54 ms
    h.send(raw)
    h.wait(38 * MS)
    assert len(h.buf) == 26
    h.wait(600_000)
    assert bytes(h.buf) == wire.reply("SPX 1.0 SIM00042 4 128")


def test_garble_models_a_rate_mismatch() -> None:
    rng = np.random.default_rng(0)
    data = wire.BANNER * 10
    assert garble(data, 9600, 9600, rng) == data
    fast_reader = garble(data, 9600, 2_000_000, rng)
    assert len(fast_reader) == len(data) and fast_reader != data
    slow_reader = garble(data, 2_000_000, 9600, rng)
    assert len(slow_reader) == round(len(data) * 9600 / 2_000_000)
