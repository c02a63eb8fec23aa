"""A lab's session with a Qualisys QTM: the real command line, each device its own process.

``spotlab sim qualisys`` (8 cameras, 40 labelled markers, 300 Hz, truth file, its
clock 150 ppm fast, its synchronisation output published to the lab) and ``spotlab
sim timer --pty`` (input 0 wired to QTM's sync output) run as separate processes;
one ``spotlab record --device qualisys=ADDR --device timer=PORT`` records both into
one journal, with a third process's LSL stream (``--device lsl=NAME``, 4 channels at
100 Hz, found by unicast on 127.0.0.1; left out without pylsl). Every QTM frame the
simulator served must be in the journal (frame numbers contiguous, as many as the
truth holds), every LSL sample too, ``spotlab export --c3d`` must give the labelled
markers of the truth to float32 precision, and ``spotlab export --timestamps`` must
keep QTM's timestamps as the device time and recover QTM's clock drift from the
timer's edges within 1 ppm.
"""

from __future__ import annotations

import csv
import importlib.util
import json
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from _e2e import _first_line as first_line
from _e2e import run_cli, spawn_cli, stop_process

from spotlab.acquisition.replay import replay
from spotlab.core.frames import FrameBlock
from spotlab.io import read_c3d
from spotlab.processing.decoding import decoder_for

# one worker runs this module, so its session recordings are made once (make test: --dist loadgroup)
pytestmark = pytest.mark.xdist_group("qualisys-recording")

RATE_HZ = 300.0
DRIFT_PPM = 150.0
LSL_NAME = "spotlab-e2e-qualisys-emg"
#: An LSL outlet in a process of its own: 4 float32 channels at 100 Hz, sample k holding
#: k in every channel, until stdin closes (prints "ready" once the outlet exists).
LSL_OUTLET = f"""
import sys, threading, time
import pylsl
info = pylsl.StreamInfo({LSL_NAME!r}, "EMG", 4, 100.0, pylsl.cf_float32, "e2e-qualisys")
outlet = pylsl.StreamOutlet(info)
done = threading.Event()
threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
print("ready", flush=True)
k, t0 = 0, time.monotonic()
while not done.is_set():
    outlet.push_sample([float(k)] * 4)
    k += 1
    time.sleep(max(0.0, t0 + k / 100.0 - time.monotonic()))
"""


@dataclass
class LabRun:
    """What a session left: the journal, the QTM truth and ``record --json``."""

    folder: Path
    journal: Path
    truth: dict[str, Any]
    streams: dict[str, dict[str, Any]]
    seconds: float


def _session(folder: Path, seconds: float) -> LabRun:
    truth_path = folder / "qtm-truth.npz"
    journal = folder / "lab.spj"
    lab = folder / "lab"
    q_out, q_err = folder / "qtm.stdout", folder / "qtm.stderr"
    t_out, t_err = folder / "timer.stdout", folder / "timer.stderr"
    qtm = spawn_cli(
        ["sim", "qualisys", "--cameras", 8, "--markers", 40, "--rate", RATE_HZ, "--seed", 4,
         "--truth", truth_path, "--clock-drift-ppm", DRIFT_PPM, "--lab", lab, "--lab-name",
         "qtm"],
        q_out, q_err,
    )  # fmt: skip
    timer = spawn_cli(
        ["sim", "timer", "--pty", "--rate", 200, "--input", "0=qtm", "--lab", lab], t_out, t_err
    )
    lsl = _lsl_outlet(folder)
    cfg = folder / "lsl_api.cfg"
    cfg.write_text("[lab]\nKnownPeers = {127.0.0.1}\n[log]\nlevel = -3\n")
    try:
        address = first_line(q_out, qtm, q_err, timeout=30.0)
        timer_port = first_line(t_out, timer, t_err, timeout=30.0)
        devices = ["--device", f"qualisys={address}", "--device", f"timer={timer_port}"]
        if lsl is not None:
            first_line(folder / "lsl.stdout", lsl, folder / "lsl.stderr", timeout=30.0)
            devices += ["--device", f"lsl={LSL_NAME}"]
        with pytest.MonkeyPatch.context() as env:
            env.setenv("LSLAPICFG", str(cfg))
            result = run_cli(
                "record", *devices, "--seconds", seconds, "--out", journal, "--json",
                timeout=seconds + 40,
            )  # fmt: skip
    finally:
        if lsl is not None:
            assert lsl.stdin is not None
            lsl.stdin.close()
            assert stop_process(lsl) in (0, -15)
        assert stop_process(timer) == 0
        assert stop_process(qtm) == 0  # SIGTERM: the simulator writes its truth
    assert result.returncode == 0, result.stderr
    streams = {s["name"]: s for s in json.loads(result.stdout)["streams"]}
    return LabRun(folder, journal, dict(np.load(truth_path)), streams, seconds)


def _lsl_outlet(folder: Path) -> subprocess.Popen[bytes] | None:
    """The LSL outlet process, or None without pylsl."""
    try:
        import pylsl  # noqa: F401
    except ImportError:
        return None
    with open(folder / "lsl.stdout", "wb") as out, open(folder / "lsl.stderr", "wb") as err:
        return subprocess.Popen(
            [sys.executable, "-c", LSL_OUTLET], stdin=subprocess.PIPE, stdout=out, stderr=err
        )


def check_every_frame_kept(run: LabRun) -> None:
    with_lsl = importlib.util.find_spec("pylsl") is not None
    assert set(run.streams) == {"qualisys", "timer", *(["lsl"] if with_lsl else [])}
    assert run.streams["qualisys"]["lost_frames"] == 0 and run.streams["qualisys"]["gaps"] == 0
    assert run.streams["timer"]["lost_frames"] == 0
    truth = run.truth
    block = FrameBlock.concat(
        [b for name, b in replay(run.journal, decoder_for) if name == "qualisys" and len(b)]
    )
    # every frame the simulator served (to its only client, the recorder) was kept
    assert len(block) >= 0.8 * RATE_HZ * run.seconds
    assert np.array_equal(block.seq, truth["frame"]), (len(block), len(truth["frame"]))
    assert np.array_equal(block.ticks, truth["timestamp_us"])
    markers32 = truth["markers_mm"].astype(np.float32)
    assert np.array_equal(block.data[:, :, 0, :], markers32)
    if "lsl" in run.streams:  # every LSL sample kept: sample k holds k
        lsl = FrameBlock.concat(
            [b for name, b in replay(run.journal, decoder_for) if name == "lsl" and len(b)]
        )
        k = lsl.data[:, 0, 0, 0]
        assert len(lsl) >= 0.8 * 100 * run.seconds and run.streams["lsl"]["lost_frames"] == 0
        assert np.array_equal(np.diff(k), np.ones(len(k) - 1)), "an LSL sample was lost"

    c3d = run.folder / "lab.c3d"
    exported = run_cli("export", run.journal, "--c3d", c3d, timeout=120)
    assert exported.returncode == 0, exported.stderr
    trial = read_c3d(c3d)
    assert trial.labels == truth["labels"].tolist() and trial.point_rate == RATE_HZ
    assert trial.n_frames == len(truth["frame"])
    assert np.array_equal(trial.points.astype(np.float32), markers32)


def check_clock_drift(run: LabRun) -> None:
    csv_path = run.folder / "times.csv"
    out = run_cli(
        "export", run.journal, "--timestamps", csv_path, "--wiring", "qualisys=0", "--json",
        timeout=120,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    sync = json.loads(out.stdout.strip().splitlines()[-1])["sync"]
    assert sync["reference"] == "timer"
    qtm = next(s for s in sync["streams"] if s["stream"] == "qualisys")
    assert qtm["channel"] == 0 and qtm["methods"].get("edge", 0) > 0.8 * qtm["frames"], qtm
    assert abs(qtm["drift_ppm"] - DRIFT_PPM) < 1.0, qtm  # the timer's clock is exact
    with open(csv_path, newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if r["stream"] == "qualisys"]
    # the stream's device time is QTM's timestamp (µs)
    row_of = {int(n): i for i, n in enumerate(run.truth["frame"])}
    idx = np.array([row_of[int(r["seq"])] for r in rows])
    ticks = np.array([int(r["device_ticks"]) for r in rows])
    assert np.array_equal(ticks, run.truth["timestamp_us"][idx])
    # session times are the true capture times up to one offset and scale, within 2 µs
    t_true = run.truth["time_s"][idx]
    t_sess = np.array([float(r["time_s"]) for r in rows])
    fit = np.polyval(np.polyfit(t_true, t_sess, 1), t_true)
    assert np.max(np.abs(t_sess - fit)) < 2e-6


@pytest.fixture(scope="session")
def lab_run(tmp_path_factory: pytest.TempPathFactory) -> LabRun:
    return _session(tmp_path_factory.mktemp("qtm-lab"), 8.0)


@pytest.mark.timeout(60)
def test_qualisys_and_timer_recorded_together_every_frame_kept(lab_run: LabRun) -> None:
    check_every_frame_kept(lab_run)


@pytest.mark.timeout(60)
def test_qtm_timestamps_are_the_device_time_and_its_drift_is_recovered(lab_run: LabRun) -> None:
    check_clock_drift(lab_run)


@pytest.mark.long
@pytest.mark.timeout(180)
def test_qualisys_and_timer_60_s(tmp_path: Path) -> None:
    run = _session(tmp_path, 60.0)
    check_every_frame_kept(run)
    check_clock_drift(run)
