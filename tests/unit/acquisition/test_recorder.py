"""Recorder: every wire byte reaches the journal, whatever the sinks' queues do."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
from acq_fakes import FakeDevice, ListSink

from spotlab.acquisition.recorder import Recorder
from spotlab.acquisition.session import Session
from spotlab.core.errors import ProtocolError, RecordingError
from spotlab.io.journal import JournalReader, RecordType


def _records(path: Path, stream: str, rtype: RecordType) -> list[bytes]:
    reader = JournalReader(path)
    names = reader.stream_names
    return [r.payload for r in reader if r.type == rtype and names.get(r.stream) == stream]


def test_recorder_keeps_every_byte_while_a_slow_sink_overflows(tmp_path: Path) -> None:
    path = tmp_path / "run.spj"
    cam = FakeDevice("cam", period_s=0.001, frames_per_block=1)
    timer = FakeDevice("timer", period_s=0.003, frames_per_block=1)
    recorder = Recorder(path, {"operator": "test"})
    slow = ListSink("slow", delay_s=0.02)
    session = Session([cam, timer], [recorder, slow], queue_size=2)
    session.run_for(0.3)
    assert session.overflows["slow"] > 0
    # The recorder's own block queue may overflow too (it only counts frames
    # there); its bytes come from the taps, so the journal holds them all.
    rec_stats = session.sink_stats()["recorder"]
    assert sum(recorder.frames.values()) + rec_stats.dropped_frames == sum(session.frames.values())

    for device in (cam, timer):
        assert b"".join(_records(path, device.name, RecordType.RX)) == b"OKAY\r" + bytes(
            device.sent
        )
        assert _records(path, device.name, RecordType.TX) == [b"START\r"]
    reader = JournalReader(path)
    assert reader.complete and reader.corrupt_records == 0
    assert reader.session["operator"] == "test"
    assert reader.streams["cam"] == cam.metadata()
    events = [
        (reader.stream_name(r.stream), r.json()) for r in reader if r.type == RecordType.EVENT
    ]
    kinds = [(s, e["kind"]) for s, e in events]
    assert ("cam", "started") in kinds and ("cam", "stopped") in kinds
    final = {s: e["detail"] for s, e in events if e["kind"] == "link_stats"}
    assert final == {"cam": cam.stats.as_dict(), "timer": timer.stats.as_dict()}
    # The stopped events come before link_stats, which come before END.
    order = [e["kind"] for s, e in events if s == "cam"]
    assert order.index("stopped") < order.index("link_stats")


def test_device_errors_are_recorded_as_events(tmp_path: Path) -> None:
    path = tmp_path / "run.spj"
    device = FakeDevice("cam", errors={2: ProtocolError("bad header")})
    Session([device], [Recorder(path)]).run_for(0.05)
    reader = JournalReader(path)
    errors = [
        r.json() for r in reader if r.type == RecordType.EVENT and r.json()["kind"] == "error"
    ]
    assert errors == [
        {"kind": "error", "detail": {"type": "ProtocolError", "message": "bad header"}}
    ]


def test_refuses_an_existing_file_before_any_device_starts(tmp_path: Path) -> None:
    path = tmp_path / "run.spj"
    path.write_bytes(b"an earlier recording")
    with pytest.raises(RecordingError, match="already exists"):
        Recorder(path)
    assert path.read_bytes() == b"an earlier recording"


def test_recorder_without_a_session(tmp_path: Path) -> None:
    path = tmp_path / "run.spj"
    device = FakeDevice("cam")
    with Recorder(path) as recorder:
        recorder.attach([device])
        device.start()
        recorder.on_start([device])
        for _ in range(3):
            device.recv(0.1)
        device.stop()
    assert b"".join(_records(path, "cam", RecordType.RX)) == b"OKAY\r" + bytes(device.sent)
    # Taps after stop are counted, not written, and never raise into the driver.
    device.start()
    assert recorder.late_records == 3
    assert JournalReader(path).complete


def test_metadata_failure_keeps_the_bytes(tmp_path: Path) -> None:
    class NoMeta(FakeDevice):
        def metadata(self) -> dict[str, object]:
            raise RuntimeError("spec not known")

    path = tmp_path / "run.spj"
    device = NoMeta("cam")
    Session([device], [Recorder(path)]).run_for(0.03)
    reader = JournalReader(path)
    assert reader.streams["cam"] == {"metadata_error": "RuntimeError: spec not known"}
    assert b"".join(_records(path, "cam", RecordType.RX)) == b"OKAY\r" + bytes(device.sent)


def test_disk_full_does_not_disturb_acquisition_and_is_raised_at_stop(tmp_path: Path) -> None:
    if not os.path.exists("/dev/full"):
        pytest.skip("needs /dev/full")
    recorder = Recorder(tmp_path / "run.spj", flush_interval_s=0.01)
    journal = recorder._journal
    real_fd = journal._fd
    journal._fd = os.open("/dev/full", os.O_WRONLY)
    try:
        recorder.on_rx("cam", b"x" * 100, 1)  # never raises into the driver
        deadline = time.monotonic() + 5.0
        while recorder.error is None and time.monotonic() < deadline:
            time.sleep(0.01)
            recorder.on_rx("cam", b"x" * 100, 2)
        assert recorder.error is not None
        with pytest.raises(RecordingError, match=r"cannot write journal .*No space left"):
            recorder.stop()
        recorder.stop()  # raised once
    finally:
        os.close(real_fd)
