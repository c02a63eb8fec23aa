"""Injected link faults: each kind on the wire, and the fault log matching the wire exactly."""

from __future__ import annotations

import csv
import itertools
import json
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import pytest
from _simwire import MS, Decoded, Host, cmd, decode, reply_text, spx

from spotlab.simulators import wire
from spotlab.simulators.faults import FaultInjector, FaultLog, FaultSpec, parse_schedule
from spotlab.simulators.selspot import SelspotDevice

FRAME_PAYLOAD = 16 + 5 * 8 * 4


def run(
    make_device: Callable[..., SelspotDevice],
    faults: str = "",
    rate: float = 0.0,
    seconds: float = 1.5,
    seed: int = 5,
    **kwargs: object,
) -> tuple[Host, Decoded]:
    """4 cameras x 8 LEDs at 200 Hz and 2 Mbaud, streamed for ``seconds`` in simulated time."""
    h = Host(make_device(faults=faults, rate=rate, seed=seed, **kwargs))
    h.configure(4, 8, 200_000)
    h.buf.clear()
    h.send(cmd("START:"), baud=2_000_000)
    for _ in range(round(seconds * 100)):
        h.wait(10 * MS)
    return h, decode(bytes(h.buf), spx_len=FRAME_PAYLOAD)


def data_frames(got: Decoded) -> list[dict[str, object]]:
    return [
        spx(f["payload"]) | {"seq": f["seq"], "hflags": f["flags"]}
        for f in got.frames
        if f["type"] == 1
    ]  # type: ignore[arg-type]


def seqs_of(log: FaultLog, kinds: tuple[str, ...], counter: str) -> Counter[int]:
    c: Counter[int] = Counter()
    for e in log.entries:
        if e.kind in kinds and getattr(e, counter):
            c.update(e.seq)
    return c


def check_wire_matches_log(got: Decoded, log: FaultLog) -> None:
    """The exact bookkeeping a host's counters can rely on (one stream, seq below 65536)."""
    frames = data_frames(got)
    totals = log.totals()
    copies = Counter(e.detail["copied_seq"] for e in log.entries if e.kind == "duplicate")
    corrupted = Counter[int]()
    for e in log.entries:
        if e.corrupted_frames:
            corrupted.update(e.seq)
    lost = seqs_of(log, ("disconnect",), "lost_frames")
    discarded = seqs_of(log, ("reset",), "discarded_frames")
    expected = Counter(range(totals["frames_sent"])) + copies
    expected.subtract(corrupted + lost + discarded)
    assert Counter(int(f["seq"]) for f in frames) == +expected  # type: ignore[call-overload]
    assert len(frames) == totals["frames_sent"] + sum(copies.values()) - (
        totals["corrupted_frames"] + totals["lost_frames"] + totals["discarded_frames"]
    )
    dups = sum(1 for a, b in itertools.pairwise(frames) if a["seq"] == b["seq"])
    assert dups == totals["duplicated_frames"]
    device_dropped = sum(
        (int(b["frame_no"]) - int(a["frame_no"])) - ((int(b["seq"]) - int(a["seq"])) % 65536)  # type: ignore[call-overload]
        for a, b in itertools.pairwise(frames)
        if a["seq"] != b["seq"]
    )
    assert device_dropped == totals["dropped_frames"]
    assert totals["garbage_bytes"] == 3 * sum(e.kind == "garbage" for e in log.entries)


def test_schedule_parsing() -> None:
    specs = parse_schedule(
        "bitflip@1.5,drop@2.0,truncate@2.5,duplicate@3,garbage@3.5,burst@4,overflow@5:3,reset@6,disconnect@7:0.5"
    )
    kinds = "bitflip drop truncate duplicate garbage burst overflow reset disconnect"
    assert [s.kind for s in specs] == kinds.split()
    assert specs[5] == FaultSpec("burst", 4.0, 0.016)
    assert specs[6] == FaultSpec("overflow", 5.0, 3.0)
    assert specs[8] == FaultSpec("disconnect", 7.0, 0.5)
    assert [s.at_s for s in parse_schedule("drop@3, bitflip@1;")] == [1.0, 3.0]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("bitflop@1", "unknown kind"),
        ("drop", "needs a time"),
        ("drop@x", "must be numbers"),
        ("drop@-1", ">= 0"),
        ("overflow@1:2.5", "whole number"),
        ("disconnect@1:0", "> 0"),
    ],
)
def test_schedule_errors_name_the_item(text: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        parse_schedule(text)


def test_injector_arguments_are_checked() -> None:
    with pytest.raises(ValueError):
        FaultInjector(rate=1.5)
    with pytest.raises(ValueError):
        FaultInjector(kinds=("reset",))


@pytest.mark.parametrize("kind", ["bitflip", "drop", "truncate"])
def test_damaged_frame_is_one_crc_error_or_loss(
    make_device: Callable[..., SelspotDevice], kind: str
) -> None:
    h, got = run(make_device, f"{kind}@0.5")
    log = h.dev.fault_log
    (entry,) = log.entries
    assert (entry.kind, entry.corrupted_frames, entry.source) == (kind, 1, "schedule")
    seqs = [int(f["seq"]) for f in data_frames(got)]  # type: ignore[call-overload]
    hit = entry.seq[0]
    assert hit not in seqs and hit - 1 in seqs and hit + 1 in seqs
    assert 99 <= hit <= 102  # the first frame sent at or after 0.5 s
    assert got.crc_errors <= 2
    check_wire_matches_log(got, log)


def test_duplicate_frame(make_device: Callable[..., SelspotDevice]) -> None:
    h, got = run(make_device, "duplicate@0.5")
    (entry,) = h.dev.fault_log.entries
    assert entry.duplicated_frames == 1 and got.crc_errors == 0
    seqs = [int(f["seq"]) for f in data_frames(got)]  # type: ignore[call-overload]
    assert seqs.count(entry.seq[0]) == 2
    check_wire_matches_log(got, h.dev.fault_log)


def test_garbage_between_frames(make_device: Callable[..., SelspotDevice]) -> None:
    h, got = run(make_device, "garbage@0.5")
    (entry,) = h.dev.fault_log.entries
    assert entry.garbage_bytes == 3 and b"AT\r\xa5\x5a" in h.buf
    # START's bare OKAY (9 bytes) is the first skipped run, the garbage the second.
    assert got.resyncs == 2 and got.skipped == 9 + 3 and got.crc_errors == 0
    check_wire_matches_log(got, h.dev.fault_log)


def test_burst_damages_16_ms_of_line(make_device: Callable[..., SelspotDevice]) -> None:
    h, got = run(make_device, "burst@0.5")
    (entry,) = h.dev.fault_log.entries
    # 188-byte frames take 0.94 ms every 5 ms: a 16 ms window touches 4 frames.
    assert entry.corrupted_frames == 4
    assert entry.seq == list(range(entry.seq[0], entry.seq[0] + 4))
    check_wire_matches_log(got, h.dev.fault_log)


def test_fifo_overflow_drops_frames_in_the_device(
    make_device: Callable[..., SelspotDevice], tmp_path: Path
) -> None:
    truth = tmp_path / "t.csv"
    h, got = run(make_device, "overflow@0.5:3", truth=truth)
    (entry,) = h.dev.fault_log.entries
    assert entry.dropped_frames == 3 and entry.seq == [-1, -1, -1]
    frames = data_frames(got)
    flagged = [i for i, f in enumerate(frames) if f["status"] & wire.STATUS_FIFO_OVERFLOW]  # type: ignore[operator]
    (i,) = flagged
    a, b = frames[i - 1], frames[i]
    assert b["seq"] == a["seq"] + 1  # type: ignore[operator]
    assert b["frame_no"] == a["frame_no"] + 4  # type: ignore[operator]
    assert b["hflags"] & wire.HEADER_FLAG_OVERRUN  # type: ignore[operator]
    assert entry.frame_no == [a["frame_no"] + 1, a["frame_no"] + 2, a["frame_no"] + 3]  # type: ignore[operator]
    check_wire_matches_log(got, h.dev.fault_log)
    h.dev.close(h.t)
    rows = list(csv.DictReader(truth.read_text().splitlines()))
    unsent = [int(r["frame_no"]) for r in rows if r["sent"] == "0"]
    assert unsent == entry.frame_no
    assert all(r["seq"] == "-1" for r in rows if r["sent"] == "0")


def test_reset_fault_stops_the_stream_with_a_banner(
    make_device: Callable[..., SelspotDevice],
) -> None:
    h, got = run(make_device, "reset@0.5")
    (entry,) = h.dev.fault_log.entries
    assert entry.kind == "reset"
    assert not h.dev.streaming and h.dev.baud == 9600
    raw = bytes(h.buf)
    assert raw.endswith(wire.BANNER)  # sent at 9600: a host still at 2 Mbaud sees garbage
    frames = data_frames(got)
    assert entry.discarded_frames <= 1
    assert frames[-1]["seq"] == h.dev.fault_log.frames_sent - 1 - entry.discarded_frames
    check_wire_matches_log(got, h.dev.fault_log)
    assert h.ask("STAT:") == "STAT 0008"  # recovered from a fault
    assert h.ask("LEDQ:") == "ERROR82"  # configuration is gone


def test_reset_in_the_middle_of_a_frame_cuts_it(make_device: Callable[..., SelspotDevice]) -> None:
    # 1 camera x 8 LEDs at 50 Hz and 115200 baud: frame k is ready 0.9 ms after k * 20 ms
    # and its 68 bytes take 5.9 ms; a reset 2 ms into frame 15 cuts it.
    h = Host(make_device(faults="reset@0.302"))
    h.configure(1, 8, 50_000, comm=5)
    h.buf.clear()
    h.send(cmd("START:"), baud=115_200)
    for _ in range(60):
        h.wait(10 * MS)
    log = h.dev.fault_log
    (entry,) = log.entries
    assert entry.discarded_frames == 1 and entry.seq == [15]
    got = decode(bytes(h.buf), spx_len=16 + 40)
    assert [f["seq"] for f in got.frames] == list(range(15))
    cut = bytes(h.buf).split(b"\xa5\x5a\x01\x14\x0f\x00")[1]
    assert cut.endswith(wire.BANNER) and 0 < len(cut) - len(wire.BANNER) < 68 - 6
    check_wire_matches_log(got, log)


def test_disconnect_loses_frames_as_a_seq_gap(make_device: Callable[..., SelspotDevice]) -> None:
    h = Host(make_device(faults="disconnect@0.5:0.25"))
    h.configure(4, 8, 200_000)
    h.buf.clear()
    h.send(cmd("START:"), baud=2_000_000)
    down = []
    for _ in range(150):
        h.wait(10 * MS)
        down.append(h.dev.link_down(h.t))
    assert down.count(True) == 25 and h.dev.link_return_ns(h.t) is None
    got = decode(bytes(h.buf), spx_len=FRAME_PAYLOAD)
    (entry,) = h.dev.fault_log.entries
    assert entry.kind == "disconnect" and entry.lost_frames in (50, 51)
    seqs = [int(f["seq"]) for f in data_frames(got)]  # type: ignore[call-overload]
    gaps = [b - a - 1 for a, b in itertools.pairwise(seqs) if b != a + 1]
    assert gaps == [entry.lost_frames]
    check_wire_matches_log(got, h.dev.fault_log)
    # Host bytes sent while the link is down never arrive.
    assert h.dev.streaming


def test_random_faults_match_the_log_exactly(
    make_device: Callable[..., SelspotDevice], tmp_path: Path
) -> None:
    log_path = tmp_path / "faults.json"
    h, got = run(
        make_device,
        "bitflip@0.3,duplicate@0.6,burst@1.0,overflow@1.4:2",
        rate=0.03,
        seconds=4.0,
        seed=11,
        fault_log=log_path,
    )
    log = h.dev.fault_log
    kinds = Counter(e.kind for e in log.entries)
    assert sum(kinds.values()) >= 20 and len(kinds) >= 5
    assert sum(e.source == "random" for e in log.entries) >= 16
    check_wire_matches_log(got, log)
    h.dev.close(h.t)
    written = json.loads(log_path.read_text())
    assert written == json.loads(json.dumps(log.to_dict()))
    assert written["totals"]["frames_sent"] == log.frames_sent
    assert set(written["faults"][0]) >= {"kind", "t_s", "seq", "corrupted_frames", "dropped_frames"}


def test_same_seed_same_faults(make_device: Callable[..., SelspotDevice]) -> None:
    a, _got_a = run(make_device, rate=0.05, seconds=1.0, seed=3)
    b, _got_b = run(make_device, rate=0.05, seconds=1.0, seed=3)
    assert bytes(a.buf) == bytes(b.buf)
    assert a.dev.fault_log.to_dict() == b.dev.fault_log.to_dict()
    c, _ = run(make_device, rate=0.05, seconds=1.0, seed=4)
    assert bytes(c.buf) != bytes(a.buf)


def test_natural_fifo_overflow_from_replies(make_device: Callable[..., SelspotDevice]) -> None:
    # A small FIFO and a flood of commands while streaming: the device drops frames itself.
    h = Host(make_device(fifo_bytes=600))
    h.configure(4, 8, 200_000, comm=6)  # 921 600 baud: 188-byte frames take 2 ms of 5
    h.buf.clear()
    h.send(cmd("START:"), baud=921_600)
    h.wait(50 * MS)
    h.send(cmd("VER:0") * 40, baud=921_600)
    for _ in range(30):
        h.wait(10 * MS)
    log = h.dev.fault_log
    fifo = [e for e in log.entries if e.kind == "fifo"]
    assert fifo and all(e.source == "device" for e in fifo)
    got = decode(bytes(h.buf), spx_len=FRAME_PAYLOAD)
    assert sum(1 for f in got.frames if f["type"] == 0x7F) == 40
    texts = {reply_text(f["payload"]) for f in got.frames if f["type"] == 0x7F}  # type: ignore[arg-type]
    assert texts == {"SPX 1.0 SIM00042 4 128"}
    check_wire_matches_log(got, log)
    h.send(cmd("STAT:"), baud=921_600)
    h.buf.clear()
    h.wait(20 * MS)
    events = [f for f in decode(bytes(h.buf)).frames if f["type"] == 0x7F]
    # FIFO overflow, and the configuration change before START, each reported once.
    assert reply_text(events[0]["payload"]) == "STAT 0060"  # type: ignore[arg-type]
