"""The timer simulator and the lab wiring: edges at the true instants of another device's frames."""

from __future__ import annotations

import csv
import time
from pathlib import Path

import numpy as np
import pytest
import serial

import spotlab.simulators  # noqa: F401  (sim:// URLs)
from spotlab.drivers.selspot import SelspotDriver
from spotlab.drivers.timer import TimerDriver, extract_edges
from spotlab.simulators import service
from spotlab.simulators.clock import DeviceClock
from spotlab.simulators.lab import LabPublisher, PulseSource, frame_start, lab_dir
from spotlab.testing.wire import ask, command, reset


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_lab_dir_follows_argument_then_environment(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("SPOTLAB_LAB", str(tmp_path / "env"))
    assert lab_dir() == tmp_path / "env"
    assert lab_dir(tmp_path / "arg") == tmp_path / "arg"
    monkeypatch.delenv("SPOTLAB_LAB")
    assert "spotlab-lab-" in lab_dir().name


def test_published_schedule_reproduces_the_frame_instants(tmp_path: Path) -> None:
    clock = DeviceClock(offset_s=2.0, drift_ppm=120.0, jitter_s=2e-6, seed=4, epoch_ns=10**12)
    pub = LabPublisher(tmp_path, "cam", clock, 10e-6)
    start_ns = 10**12 + 5 * 10**8
    start_osc = clock.osc_s(start_ns)
    pub.started(0, start_ns, start_osc, 0.005)
    pub.stopped(start_ns + 10**8)
    src = PulseSource(tmp_path, "cam", min_reload_s=0.0)
    src.refresh()
    pulses = [p for p in src.pulses(src.streams[0], 0.0, 1e20) if p.rising]
    # 100 ms of world time at 200 Hz on a clock 120 ppm fast: frames 0-20 start before the stop.
    assert [p.frame_no for p in pulses] == list(range(21))
    for p in pulses:
        _, osc0 = frame_start(clock, start_osc, 0.005, p.frame_no)
        expected = clock.world_ns(osc0) + clock.jitter_for(0, p.frame_no) * 1e9
        assert p.world_ns == pytest.approx(float(expected), abs=1.0)
    with pytest.raises(ValueError, match="plain file name"):
        LabPublisher(tmp_path, "../x", clock, 1e-6)


def test_timer_edges_match_the_selspot_truth_through_ptys(tmp_path: Path) -> None:
    sel = service.serve_pty(
        service.SelspotSimOptions(
            cameras=1, leds=4, rate_hz=200, lab_name="sel", lab=tmp_path,
            truth=tmp_path / "sel.csv", clock_offset_s=3.0, clock_drift_ppm=200.0,
            clock_jitter_s=5e-6,
        )
    )  # fmt: skip
    tmr = service.serve_timer_pty(
        service.TimerSimOptions(
            rate_hz=100, inputs="0=sel", lab=tmp_path, truth=tmp_path / "tmr.csv",
            clock_offset_s=100.0, clock_drift_ppm=-150.0, clock_jitter_s=50e-9,
        )
    )  # fmt: skip
    try:
        td = TimerDriver(str(tmr.path), rate_hz=100, inputs={0: "rising"})
        sd = SelspotDriver(str(sel.path), cameras=1, leds=4, rate_hz=200)
        blocks = []
        with td, sd:
            t_end = time.monotonic() + 1.5
            while time.monotonic() < t_end:
                b = td.recv(0.01)
                if b is not None:
                    blocks.append(b)
                sd.recv(0.01)
    finally:
        sel.stop()
        tmr.stop()
    edges = extract_edges(blocks).select(0)
    truth = {
        (int(r["source_stream"]), int(r["source_frame_no"])): r
        for r in _rows(tmp_path / "tmr.csv.edges.csv")
        if r["channel"] == "0" and r["rising"] == "1"
    }
    sel_truth = {(int(r["stream"]), int(r["frame_no"])): r for r in _rows(tmp_path / "sel.csv")}
    assert len(edges) > 150
    # Every frame the SELSPOT took while the timer listened has its edge, each once.
    frames = sorted(k for k in truth)
    assert frames == [(0, k) for k in range(frames[0][1], frames[0][1] + len(frames))]
    assert edges.edge_index.tolist() == list(range(len(edges)))
    by_index = {int(r["edge_index"]): r for r in truth.values()}
    # The edge truth's instant is the SELSPOT truth's; the tick is the timer clock's reading.
    for idx, tick in zip(edges.edge_index.tolist(), edges.tick.tolist(), strict=True):
        row = by_index[idx]
        src = sel_truth[(int(row["source_stream"]), int(row["source_frame_no"]))]
        assert float(row["true_time_s"]) == pytest.approx(float(src["true_time_s"]), abs=2e-9)
        assert int(row["timer_tick"]) == tick
    ticks = edges.tick.astype(np.float64)
    world = np.array([float(by_index[i]["true_time_s"]) for i in edges.edge_index.tolist()])
    # Timer counter vs true time is the timer's affine clock (offset, -150 ppm) + jitter.
    fit = np.polyfit(world - world[0], ticks, 1)
    resid_s = (ticks - np.polyval(fit, world - world[0])) / 1e7
    assert np.abs(resid_s).max() < 0.5e-6
    assert fit[0] / 1e7 - 1 == pytest.approx(-150e-6, abs=1e-6)


def test_timer_commands_over_sim_url(tmp_path: Path) -> None:
    url = service.timer_url_for(service.TimerSimOptions(rate_hz=50, seed=2))
    assert url.startswith("sim://timer?")
    port = serial.serial_for_url(url, baudrate=9600, timeout=0.05)
    try:
        reset(port)
        assert ask(port, "VER:0") == "TMR 1.0 SIM00077 8 4 10000000"
        assert ask(port, "EDGS:65") == "ERROR23"
        assert ask(port, "ARM:8,1") == "ERROR23"
        assert ask(port, "ARM:1") == "ERROR07"
        assert ask(port, "TCOD:1,29,0") == "ERROR23"
        assert ask(port, "POUT:0,50") == "ERROR23"
        first = int(ask(port, "PULS:1").split()[1], 16)
        second = int(ask(port, "PULS:1").split()[1], 16)
        assert first % 10 == 0 and 0 < second - first < 10_000_000
        assert ask(port, "START:") == "ERROR80"  # 140-byte frames at 50 Hz need > 9600 baud
    finally:
        port.write(command("RESET:"))
        port.close()
