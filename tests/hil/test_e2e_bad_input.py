"""Bad input: one clear error line, a non-zero exit, no traceback, nothing recorded lost."""

from __future__ import annotations

import json
import os
import select
import shutil
import signal
import threading
import time
import tty
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from _e2e import (
    assert_one_clear_error,
    decode,
    info,
    record_args,
    run_cli,
    sim_pty,
    spawn_cli,
    stop_process,
)

from spotlab.core.crc import crc16_hex
from spotlab.io.journal import JournalReader, RecordType

BANNER = b"RESET7DB2\r"


# -- spotlab info ----------------------------------------------------------------------


def test_info_on_garbage_empty_and_missing_files(tmp_path: Path) -> None:
    garbage = tmp_path / "garbage.spj"
    garbage.write_bytes(np.random.default_rng(0).bytes(4096))
    assert_one_clear_error(run_cli("info", garbage), "garbage.spj", "not a spotlab journal")
    empty = tmp_path / "empty.spj"
    empty.touch()
    assert_one_clear_error(run_cli("info", empty, "--json"), "empty.spj", "empty")
    missing = tmp_path / "missing.spj"
    assert_one_clear_error(run_cli("info", missing), "missing.spj", "no such")


def test_info_on_a_cut_journal_opens_with_what_it_holds(
    short_recording: Path, tmp_path: Path
) -> None:
    data = short_recording.read_bytes()
    full = decode(short_recording)
    assert len(full) > 100
    # (end offset, time, is RX) of every record (24-byte header + payload).
    records = [
        (rec.offset + 24 + len(rec.payload), rec.t_ns, rec.type == RecordType.RX)
        for rec in JournalReader(short_recording)
    ]
    # Inside the file header: nothing to open.
    cut = tmp_path / "cut.spj"
    cut.write_bytes(data[:10])
    assert_one_clear_error(run_cli("info", cut), "cut.spj", "header")
    held = -1
    for offset in (16, 100, len(data) // 5, len(data) // 2 + 7, len(data) - 30, len(data) - 1):
        cut.write_bytes(data[:offset])
        summary = info(cut)
        assert not summary["complete"], offset
        frames = sum(s["frames"] for s in summary["streams"])
        assert frames >= held, "a longer piece holds no fewer frames"
        held = frames
        got = decode(cut)
        assert np.array_equal(got.seq, full.seq[: len(got)]), "the frames held are the first ones"
        # Every frame whose bytes were wholly in records kept whole is held.
        kept = [t for end, t, rx in records if rx and end <= offset]
        if kept:
            assert len(got) == int(np.sum(full.arrival_ns <= kept[-1])), offset
        else:
            assert len(got) == 0
        # The partial last record is reported as such, not as damage.
        whole = max([16] + [end for end, _t, _rx in records if end <= offset])
        assert summary["truncated_bytes"] == offset - whole, offset
        assert summary["corrupt_records"] == 0
    assert held >= len(full) - 1


# -- spotlab record ----------------------------------------------------------------------


def test_record_on_a_missing_port_names_it(tmp_path: Path) -> None:
    port = tmp_path / "no-such-tty"
    result = run_cli(*record_args(str(port), tmp_path / "a.spj", 1.0))
    assert_one_clear_error(result, str(port), "no device")
    assert not (tmp_path / "a.spj").exists(), "a failed start leaves no file to block a retry"


def test_record_on_a_silent_pty_says_the_device_never_answered(tmp_path: Path) -> None:
    master, slave = os.openpty()
    try:
        t0 = time.monotonic()
        result = run_cli(*record_args(os.ttyname(slave), tmp_path / "a.spj", 5.0), timeout=30)
        elapsed = time.monotonic() - t0
        line = assert_one_clear_error(result, os.ttyname(slave), "no answer", "RESET:")
        assert elapsed < 20, "a silent port is given up after its reply timeout"
        # It did talk to the port: the reset command reached the other side.
        os.set_blocking(master, False)
        assert b"RESET:" in os.read(master, 4096)
        print(f"{line} ({elapsed:.1f} s)")
    finally:
        os.close(master)
        os.close(slave)


def test_record_refuses_a_configuration_the_line_cannot_carry(tmp_path: Path) -> None:
    result = run_cli(
        "record",
        tmp_path / "no-such-tty",
        "--driver",
        "selspot",
        "--cameras",
        4,
        "--leds",
        128,
        "--rate",
        70,
        "--baud",
        115200,
        "--seconds",
        1,
        "--out",
        tmp_path / "a.spj",
    )
    line = assert_one_clear_error(result, "Mbit/s", "115200 baud", "lower the rate")
    assert "baud=" in line  # and the baud rate that would carry it
    assert not (tmp_path / "a.spj").exists()


def test_record_with_an_unknown_driver_or_a_malformed_device(tmp_path: Path) -> None:
    out = tmp_path / "a.spj"
    result = run_cli("record", "/dev/null", "--driver", "nosuch", "--seconds", 1, "--out", out)
    assert_one_clear_error(result, "nosuch", "selspot")
    for bad in ("selspot", "=/dev/ttyUSB0", "selspot="):
        result = run_cli("record", "--device", bad, "--seconds", 1, "--out", out)
        assert_one_clear_error(result, "FAMILY=PORT", repr(bad))
    assert not out.exists()


@contextmanager
def scripted_peer(answer: str) -> Iterator[str]:
    """A pty whose other end answers ``RESET:`` with the banner and anything else ``answer``."""
    master, slave = os.openpty()
    tty.setraw(slave)
    stop = threading.Event()
    reply = answer.encode() + crc16_hex(answer).encode() + b"\r"

    def serve() -> None:
        buf = b""
        while not stop.is_set():
            if not select.select([master], [], [], 0.02)[0]:
                continue
            try:
                buf += os.read(master, 4096)
            except OSError:
                return
            while b"\r" in buf:
                line, buf = buf.split(b"\r", 1)
                if line.startswith(b"RESET"):
                    os.write(master, BANNER)
                elif line:
                    os.write(master, reply)

    thread = threading.Thread(target=serve, name="scripted-peer", daemon=True)
    thread.start()
    try:
        yield os.ttyname(slave)
    finally:
        stop.set()
        thread.join(timeout=5)
        os.close(master)
        os.close(slave)


def test_record_on_a_device_giving_an_unknown_reply(tmp_path: Path) -> None:
    with scripted_peer("HELLO THERE") as port:
        result = run_cli(*record_args(port, tmp_path / "a.spj", 2.0), timeout=30)
    assert_one_clear_error(result, port, "unexpected reply", "HELLO THERE")


@pytest.mark.timeout(90)
def test_device_gone_for_good_keeps_what_was_recorded(tmp_path: Path) -> None:
    journal = tmp_path / "gone.spj"
    with sim_pty(tmp_path, seed=9) as sim:
        proc = spawn_cli(
            [*record_args(sim.path, journal, 4.0), "--json"],
            tmp_path / "rec.out",
            tmp_path / "rec.err",
        )
        try:
            deadline = time.monotonic() + 30.0
            while not (journal.exists() and journal.stat().st_size > 100_000):
                assert proc.poll() is None, (tmp_path / "rec.err").read_text()
                assert time.monotonic() < deadline, "the recording never started"
                time.sleep(0.01)
            sim.kill()  # SIGKILL: the device and its port vanish for good
            shutil.rmtree(Path(sim.path).parent, ignore_errors=True)  # what it cannot clean up
            code = proc.wait(timeout=60)  # the recording still ends, after its --seconds
        finally:
            stop_process(proc, signal.SIGKILL)
    stderr = (tmp_path / "rec.err").read_text()
    print(f"exit {code}; stderr: {stderr.strip()}")
    assert "Traceback" not in stderr
    assert sim.path in stderr and "went away" in stderr  # the loss is reported as it happens
    errors = [ln for ln in stderr.splitlines() if ln.startswith("spotlab: error:")]
    # ... and again at the end, as the reason for a non-zero exit.
    assert code == 1 and len(errors) == 1, stderr
    assert "device gone when the recording ended" in errors[0] and str(journal) in errors[0]
    report = json.loads((tmp_path / "rec.out").read_text())
    assert list(report["away_at_end"]) == ["selspot"]
    live = report["streams"][0]

    summary = info(journal)
    assert summary["complete"]  # closed cleanly by the recorder
    (s,) = summary["streams"]
    assert s["frames"] > 100 and s["lost_frames"] == 0 and s["crc_errors"] == 0
    assert s["disconnections"] == 1 and s["reconnects"] == 0
    dec = decode(journal)
    assert np.array_equal(dec.seq, np.arange(len(dec)) + dec.seq[0]), "contiguous"
    assert s["frames"] == live["frames"]
