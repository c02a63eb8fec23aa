"""End-to-end helpers: the real ``spotlab`` command line on real pseudo-terminals.

(A module of its own, not ``conftest.py``: with several ``conftest.py`` in folders
that are not packages, ``from conftest import ...`` finds whichever was loaded last.)

Every test here runs the simulator (``spotlab sim selspot --pty``) and the
recorder (``spotlab record``) as separate processes, as a lab runs them, and
reads what they leave: the journal (decoded again with ``spotlab info`` and
:func:`spotlab.acquisition.replay.replay`), the simulator's ground truth CSV
and fault log. Every process started here is stopped and waited for in a
``finally``.
"""

from __future__ import annotations

import csv
import json
import signal
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from spotlab.acquisition.replay import replay
from spotlab.io.journal import JournalReader, RecordType
from spotlab.processing.decoding import decoder_for
from spotlab.simulators.coda import SCANNER_FAULT_KINDS

CLI: tuple[str, ...] = (sys.executable, "-m", "spotlab.console.cli")
#: The system of the issue: 4 cameras x 32 LEDs at 200 Hz.
CAMERAS, LEDS, RATE_HZ = 4, 32, 200.0

I64 = npt.NDArray[np.int64]


def run_cli(*args: object, timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
    """Run ``spotlab ARGS...`` to its end (killed and waited for after ``timeout`` s)."""
    return subprocess.run(
        [*CLI, *(str(a) for a in args)],
        capture_output=True,
        text=True,
        timeout=timeout,
        stdin=subprocess.DEVNULL,
        check=False,
    )


def spawn_cli(args: Sequence[object], stdout: Path, stderr: Path) -> subprocess.Popen[bytes]:
    """Start ``spotlab ARGS...`` with its output going to files (no pipe to fill up)."""
    with open(stdout, "wb") as out, open(stderr, "wb") as err:
        return subprocess.Popen(
            [*CLI, *(str(a) for a in args)], stdout=out, stderr=err, stdin=subprocess.DEVNULL
        )


def stop_process(
    proc: subprocess.Popen[bytes], sig: int = signal.SIGTERM, wait: float = 15.0
) -> int:
    """Send ``sig`` (if still running) and wait; SIGKILL if it does not end. Returns the code."""
    if proc.poll() is None:
        proc.send_signal(sig)
        try:
            proc.wait(timeout=wait)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    return int(proc.returncode)


def error_lines(stderr: str) -> list[str]:
    """Lines of ``stderr`` that are spotlab's one-line error reports."""
    return [line for line in stderr.splitlines() if line.startswith("spotlab: error:")]


def assert_one_clear_error(result: subprocess.CompletedProcess[str], *needles: str) -> str:
    """Non-zero exit, exactly one ``spotlab: error:`` line (naming ``needles``), no traceback."""
    assert result.returncode != 0, result
    assert "Traceback" not in result.stderr, result.stderr
    lines = error_lines(result.stderr)
    assert len(lines) == 1, result.stderr
    for needle in needles:
        assert needle.lower() in lines[0].lower(), (needle, lines[0])
    return lines[0]


# -- the simulator -------------------------------------------------------------------


@dataclass
class Truth:
    """The simulator's ground truth, one entry per frame taken (first columns only)."""

    stream: I64
    seq: I64
    frame_no: I64
    sent: npt.NDArray[np.bool_]
    true_time_ns: I64
    device_tick: I64

    def __len__(self) -> int:
        return int(self.seq.shape[0])


def read_truth(path: Path) -> Truth:
    """Read ``stream, seq, frame_no, sent, true_time_s, device_tick`` of a truth CSV."""
    cols: list[list[float]] = [[] for _ in range(6)]
    with open(path, newline="") as f:
        reader = csv.reader(f)
        header = next(reader)
        assert header[:6] == ["stream", "seq", "frame_no", "sent", "true_time_s", "device_tick"]
        for row in reader:
            if len(row) < 6:  # a row cut by a killed simulator
                continue
            for i in range(6):
                cols[i].append(float(row[i]))
    stream, seq, frame_no, sent, t_s, tick = (np.asarray(c) for c in cols)
    return Truth(
        stream=stream.astype(np.int64),
        seq=seq.astype(np.int64),
        frame_no=frame_no.astype(np.int64),
        sent=sent.astype(bool),
        true_time_ns=np.round(t_s * 1e9).astype(np.int64),
        device_tick=tick.astype(np.int64),
    )


@dataclass
class Sim:
    """A running ``spotlab sim selspot --pty`` process."""

    proc: subprocess.Popen[bytes]
    path: str
    folder: Path
    truth_path: Path
    fault_log_path: Path
    stderr_path: Path

    def stop(self) -> int:
        """SIGTERM and wait: the simulator writes its truth and fault log, then exits."""
        return stop_process(self.proc)

    def kill(self) -> None:
        """SIGKILL and wait: the device vanishes for good."""
        stop_process(self.proc, signal.SIGKILL)

    def truth(self) -> Truth:
        """Ground truth (complete once stopped)."""
        return read_truth(self.truth_path)

    def fault_log(self) -> dict[str, Any]:
        """The fault log (complete once stopped)."""
        data: dict[str, Any] = json.loads(self.fault_log_path.read_text())
        return data


def _first_line(path: Path, proc: subprocess.Popen[bytes], err: Path, timeout: float) -> str:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        text = path.read_bytes()
        if b"\n" in text:
            return text.split(b"\n", 1)[0].decode()
        if proc.poll() is not None:
            break
        time.sleep(0.02)
    raise AssertionError(
        f"spotlab sim printed no device path (exit {proc.poll()}): {err.read_text()[-2000:]}"
    )


def record_simulator(
    folder: Path, sim_args: Sequence[object], family: str, seconds: float, out: Path
) -> subprocess.CompletedProcess[str]:
    """``spotlab sim SIM_ARGS`` as its own process, recorded by ``spotlab record --device
    FAMILY=ADDRESS --seconds S --out OUT --json`` (the address its first line names),
    then stopped; the simulator must exit cleanly. Returns the recording's result."""
    out_txt, err_txt = folder / "sim.stdout", folder / "sim.stderr"
    sim = spawn_cli(["sim", *sim_args], out_txt, err_txt)
    try:
        address = _first_line(out_txt, sim, err_txt, timeout=30.0)
        result = run_cli(
            "record", "--device", f"{family}={address}", "--seconds", seconds,
            "--out", out, "--json", timeout=seconds + 30,
        )  # fmt: skip
    finally:
        assert stop_process(sim) == 0
    return result


@contextmanager
def sim_pty(
    folder: Path,
    *,
    cameras: int = CAMERAS,
    leds: int = LEDS,
    rate: float = RATE_HZ,
    seed: int = 0,
    faults: str = "",
    name: str = "sim",
    transport: str = "pty",
    extra: Sequence[object] = (),
) -> Iterator[Sim]:
    """``spotlab sim selspot --pty`` (or ``--tcp``) with truth and fault log.

    ``extra`` arguments go to ``spotlab sim`` as they are (``--motion lframe``, ...).

    Yields once the device path (or ``socket://`` URL) is printed.

    Stopped (SIGTERM, wait) on exit, so that the truth and fault log are complete.
    """
    truth = folder / f"{name}-truth.csv"
    fault_log = folder / f"{name}-faults.json"
    out, err = folder / f"{name}.stdout", folder / f"{name}.stderr"
    args: list[object] = [
        "sim",
        "selspot",
        f"--{transport}",
        "--cameras",
        cameras,
        "--leds",
        leds,
        "--rate",
        rate,
        "--seed",
        seed,
        "--truth",
        truth,
        "--fault-log",
        fault_log,
    ]
    if faults:
        args += ["--faults", faults]
    args += list(extra)
    proc = spawn_cli(args, out, err)
    try:
        path = _first_line(out, proc, err, timeout=30.0)
        yield Sim(proc, path, folder, truth, fault_log, err)
    finally:
        stop_process(proc)


def record_args(
    port: str,
    out: Path,
    seconds: float,
    *,
    cameras: int = CAMERAS,
    leds: int = LEDS,
    rate: float = RATE_HZ,
) -> list[object]:
    """Arguments of ``spotlab record PORT --driver selspot ...``."""
    return [
        "record",
        port,
        "--driver",
        "selspot",
        "--cameras",
        cameras,
        "--leds",
        leds,
        "--rate",
        rate,
        "--seconds",
        seconds,
        "--out",
        out,
    ]


# -- what a journal holds ------------------------------------------------------------


@dataclass
class Decoded:
    """Every frame decoded again from a journal (one stream), in order."""

    seq: I64
    ticks: I64
    arrival_ns: I64

    def __len__(self) -> int:
        return int(self.seq.shape[0])


def decode(path: Path) -> Decoded:
    """Decode a journal's (single) stream with the driver table, as ``spotlab info`` does."""
    seqs, ticks, arrivals = [], [], []
    for _name, block in replay(path, decoder_for):
        seqs.append(block.seq)
        ticks.append(block.ticks)
        arrivals.append(block.arrival_ns)
    if not seqs:
        empty = np.zeros(0, np.int64)
        return Decoded(empty, empty.copy(), empty.copy())
    return Decoded(
        np.concatenate(seqs).astype(np.int64),
        np.concatenate(ticks).astype(np.int64),
        np.concatenate(arrivals).astype(np.int64),
    )


@dataclass
class Event:
    """A link event recorded in a journal."""

    t_ns: int
    kind: str
    detail: dict[str, Any] = field(default_factory=dict)


def events(path: Path) -> list[Event]:
    """The EVENT records of a journal, in order."""
    found = []
    for rec in JournalReader(path):
        if rec.type == RecordType.EVENT:
            info = json.loads(rec.payload)
            found.append(Event(rec.t_ns, info.get("kind", ""), info.get("detail") or {}))
    return found


def info(path: Path) -> dict[str, Any]:
    """``spotlab info PATH --json`` (it must succeed)."""
    result = run_cli("info", path, "--json")
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    data: dict[str, Any] = json.loads(result.stdout)
    return data


def match_to_truth(dec: Decoded, truth: Truth) -> npt.NDArray[np.intp]:
    """Index of each decoded frame's truth row, found by its device tick (u32).

    Asserts that every decoded frame is a frame the device sent, with the same seq.
    """
    sent = np.flatnonzero(truth.sent)
    ticks = truth.device_tick[sent]
    assert np.unique(ticks).size == ticks.size, "device ticks of sent frames must be unique"
    order = np.argsort(ticks)
    keys = dec.ticks % (1 << 32)
    pos = np.searchsorted(ticks[order], keys)
    pos = np.minimum(pos, ticks.size - 1)
    found = ticks[order][pos] == keys
    assert found.all(), f"{int((~found).sum())} decoded frames match no frame the device sent"
    rows = sent[order][pos]
    assert np.array_equal(truth.seq[rows], dec.seq % 65536), "decoded seq differs from the truth"
    return rows


# -- the fault matrix of TARGETS.md, judged against a simulator's fault log -------------

#: TARGETS.md: reconnected within 1 s of the device returning.
RECONNECT_TARGET_S = 1.0
#: Fault-log counters of frames a host cannot decode.
DAMAGE = ("corrupted_frames", "lost_frames", "discarded_frames")


def _stream_of(entry: dict[str, Any], truth: Truth) -> int:
    """The device stream a fault entry's frames belong to (the sent frame nearest in time)."""
    seq = entry["seq"][0]
    rows = np.flatnonzero(truth.sent & (truth.seq == seq))
    nearest = rows[np.argmin(np.abs(truth.true_time_ns[rows] - entry["world_ns"]))]
    return int(truth.stream[nearest])


def _damaged(log: dict[str, Any], truth: Truth) -> set[tuple[int, int]]:
    """``(stream, seq)`` of every frame the log says went out damaged, lost or cut."""
    out: set[tuple[int, int]] = set()
    for entry in log["faults"]:
        if not any(entry[k] for k in DAMAGE):
            continue
        assert len(entry["seq"]) == sum(entry[k] for k in DAMAGE), entry
        stream = _stream_of(entry, truth)
        out.update((stream, int(s)) for s in entry["seq"])
    return out


def check_fault_matrix(journal: Path, log: dict[str, Any], truth: Truth, schedule: str) -> None:
    """Judge a recording of one fault of every kind of ``schedule`` (a reset, then a
    disconnect, as ``test_e2e_fault_matrix.py`` schedules them) against the simulator's
    fault log and truth: ``spotlab info`` agrees with the log exactly, the two breaks are
    explicit with the driver streaming again within 1 s of the device being back, and no
    frame the device sent undamaged is missing."""
    totals = log["totals"]
    # The link faults (a scanner also logs its own: colour, alias, ghost; judged apart).
    link = [e for e in log["faults"] if e["kind"] not in SCANNER_FAULT_KINDS]
    fired = sorted(e["kind"] for e in link)
    assert fired == sorted(item.split("@")[0] for item in schedule.split(",")), fired

    summary = info(journal)
    assert summary["complete"]
    (s,) = summary["streams"]
    print("info:", json.dumps({k: v for k, v in s.items() if k != "live_stats"}))
    print("fault log totals:", json.dumps(totals))

    # The counts agree with what was injected (the demo's checks). A restart (reset,
    # reconnect) starts the stream from seq 0, so frames lost during the outage are a
    # gap + reconnect, not lost_frames.
    assert s["lost_frames"] - s["device_dropped"] == totals["corrupted_frames"]
    assert s["device_dropped"] == totals["dropped_frames"] == 3
    assert s["duplicates"] == totals["duplicated_frames"] == 1
    assert s["device_resets"] == totals["resets"] == 1
    assert s["disconnections"] == totals["disconnects"] == 1
    assert s["reconnects"] == 2
    # One gap per run of frames lost (a burst damages a few in a row) or dropped, one per
    # outage (disconnection or device reset), as the live driver counts them.
    runs = sum(1 for e in log["faults"] if e["corrupted_frames"] or e["dropped_frames"])
    assert s["gaps"] == runs + s["disconnections"] + s["device_resets"]
    assert s["gaps"] == s["live_stats"]["gaps"]
    assert s["crc_errors"] >= 1 and s["resyncs"] >= 1

    # Frame by frame: per device stream (one per START), every frame sent undamaged
    # from seq 0 to the last one decoded is in the journal, and no damaged one is.
    dec = decode(journal)
    assert len(dec) == s["frames"]
    rows = match_to_truth(dec, truth)
    damaged = _damaged(log, truth)
    streams = sorted(set(truth.stream[rows].tolist()))
    assert streams == [0, 1, 2], streams  # the first START, after the reset, after the return
    missing_after_return = 0
    for k in streams:
        got = np.sort(truth.seq[rows][truth.stream[rows] == k])
        assert np.all(np.diff(got) > 0), "each frame once"
        sent = truth.seq[truth.sent & (truth.stream == k)]
        last = int(got[-1])
        expected = np.array(
            sorted(int(q) for q in sent if q <= last and (k, int(q)) not in damaged)
        )
        missing = sorted(set(expected.tolist()) - set(got.tolist()))
        extra = sorted(set(got.tolist()) - set(expected.tolist()))
        assert not missing and not extra, (k, missing[:20], extra[:20])
        # What the device sent after the host's last frame of the stream.
        after = [int(q) for q in sent if q > last and (k, int(q)) not in damaged]
        if k == 0:
            assert after == [], after  # ended by the reset: only its cut frame, discarded
        elif k == 1:
            # Ended by the disconnect: frames sent after the port came back, before the
            # host reset the device, went to a port that was not reading at their rate.
            missing_after_return = len(after)
        else:
            assert after == [], after  # the last stream: STOP keeps every frame
    print("frames sent after the port returned, before the host's reset:", missing_after_return)

    # Decoded frames: everything sent, less what was damaged, less that one stretch.
    assert s["frames"] == (
        totals["frames_sent"]
        - totals["corrupted_frames"]
        - totals["lost_frames"]
        - totals["discarded_frames"]
        - missing_after_return
    )

    # Both breaks are explicit, and the driver streamed again within 1 s of the device
    # being back (CLOCK_MONOTONIC ns on both sides).
    ev = events(journal)
    kinds = [e.kind for e in ev]
    assert kinds.count("device_reset") == 1 and kinds.count("disconnected") == 1
    reconnected = [e.t_ns for e in ev if e.kind == "reconnected"]
    assert len(reconnected) == 2
    by_kind = {e["kind"]: e for e in log["faults"]}
    reset_ns = by_kind["reset"]["world_ns"]
    back_ns = by_kind["disconnect"]["world_ns"] + round(by_kind["disconnect"]["arg"] * 1e9)
    after_reset = (min(t for t in reconnected if t > reset_ns) - reset_ns) / 1e9
    after_return = (min(t for t in reconnected if t > back_ns) - back_ns) / 1e9
    print(f"streaming again {after_reset:.3f} s after the reset, {after_return:.3f} s after return")
    assert 0 < after_return <= RECONNECT_TARGET_S
    assert 0 < after_reset <= RECONNECT_TARGET_S
