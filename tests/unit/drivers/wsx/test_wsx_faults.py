"""The USB fault matrix (issue 17): stall, timeout, short packet, babble, unplug and
return, a refused set-up. The driver talks pyusb over the socket link to a simulator
served in this process; each fault is detected, counted, and streaming goes on. The
faulty run is recorded once; ``spotlab info`` and ``spotlab record``'s summary count
the same faults from the journal's events as the driver did live."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import pytest

from spotlab.acquisition.recorder import Recorder
from spotlab.acquisition.summary import summarize
from spotlab.console.cli import main
from spotlab.console.commands.record import _summary_lines
from spotlab.core.errors import ConfigurationError, DeviceNotFound
from spotlab.drivers.wsx import WsxDriver
from spotlab.processing.decoding import decoder_for
from spotlab.simulators.wsx_service import WsxSimOptions, serve_wsx

pytestmark = pytest.mark.xdist_group("wsx-faults")  # one worker records the faulty run once


@dataclass(frozen=True)
class FaultyRun:
    driver: WsxDriver
    seqs: list[int]
    journal: Path


@pytest.fixture(scope="module")
def faulty_run(tmp_path_factory: pytest.TempPathFactory) -> FaultyRun:
    """3.3 s of a hub with every USB fault, read by the driver and recorded."""
    faults = "stall@0.3,short@0.6,babble@0.8,timeout@1.0:0.7,unplug@2.0:0.4"
    server = serve_wsx(WsxSimOptions(markers=6, marker_rate_hz=2500, rate_hz=200, faults=faults))
    journal = tmp_path_factory.mktemp("wsx-faults") / "faults.spj"
    recorder = Recorder(journal)
    try:
        driver = WsxDriver(server.address, silence_timeout=0.3)
        recorder.attach([driver])
        driver.start()
        recorder.on_start([driver])
        seqs = []
        try:
            t0 = time.monotonic()
            while time.monotonic() - t0 < 3.3:
                block = driver.recv(0.2)
                if block is not None:
                    seqs.extend(block.seq.tolist())
        finally:
            driver.close()
            recorder.stop()
    finally:
        server.stop()
    return FaultyRun(driver, seqs, journal)


def test_every_fault_is_detected_counted_and_streaming_goes_on(faulty_run: FaultyRun) -> None:
    driver, seqs = faulty_run.driver, faulty_run.seqs
    faults = driver.usb_faults
    assert faults["stalls"] == 1 and faults["short"] == 1 and faults["babble"] == 1
    assert faults["timeouts"] >= 1 and faults["unplugs"] == 1
    assert driver.stats.reconnects == 1
    assert driver.stats.device_dropped + driver.stats.lost_frames > 0
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
    after = [s for s in seqs if s > max(seqs) - 50]
    assert len(after) == 50  # frames again, in order, after the unplug


def test_info_and_the_record_summary_count_the_journalled_faults(
    faulty_run: FaultyRun, capsys: pytest.CaptureFixture[str]
) -> None:
    live = faulty_run.driver.usb_faults
    stream = summarize(faulty_run.journal, decoder_for).to_dict()["streams"][0]
    assert stream["family"] == "wsx"
    assert stream["faults"] == {
        "stall": live["stalls"], "timeout": live["timeouts"], "short": live["short"],
        "babble": live["babble"],
    }  # fmt: skip
    assert stream["disconnections"] == live["unplugs"] == 1 and stream["reconnects"] == 1
    line = (
        f"USB faults: stalls 1, timeouts {live['timeouts']}, short packets 1, babble 1, "
        "unplugged 1 (returned 1)"
    )
    assert main(["info", str(faulty_run.journal)]) == 0
    out = capsys.readouterr().out
    assert out.count("USB faults:") == 1 and f"      {line}\n" in out
    assert f"wsx: {line}" in _summary_lines({"streams": [stream], "out": "x.spj"})


def test_a_set_up_the_bounds_refuse_names_the_device_error() -> None:
    server = serve_wsx(WsxSimOptions(markers=24, marker_rate_hz=4600))
    try:
        driver = WsxDriver(server.address, rate_hz=200.0)
        with pytest.raises(ConfigurationError, match=r"error 0x24 \(frame rate"):
            driver.start()
        assert driver.usb_faults["refused"] == 1
        driver.close()
        ok = WsxDriver(server.address, rate_hz=176.9, ports="8+8+8")
        ok.start()
        assert ok.recv(1.0) is not None
        ok.close()
    finally:
        server.stop()


def test_a_serial_that_is_not_there() -> None:
    server = serve_wsx(WsxSimOptions())
    try:
        address = server.address.rsplit("/", 1)[0] + "/WSX99999"
        with pytest.raises(DeviceNotFound, match=r"serial WSX99999.*found: WSX00042"):
            WsxDriver(address).start()
    finally:
        server.stop()
