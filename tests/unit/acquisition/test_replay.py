"""Replay and summary of recordings, with the toy decoder of acq_fakes."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from acq_fakes import FakeDevice, ToyDecoder, encode_frames, toy_decoder_for

from spotlab.acquisition.recorder import Recorder
from spotlab.acquisition.replay import replay, summarize
from spotlab.acquisition.session import Session
from spotlab.core.errors import RecordingError
from spotlab.io.journal import JournalWriter

TOY = {"family": "toy", "spec": {"tick_hz": 1000.0}}  # 5 ticks per frame: 200 Hz
FRAME_NS = 5_000_000


def _write(j: JournalWriter, s: int, wire: bytes, first_seq: int, chunk: int = 50) -> None:
    """RX records of ``wire`` in ``chunk``-byte pieces (cutting frames), stamped 200 Hz."""
    for k in range(0, len(wire), chunk):
        j.rx(s, wire[k : k + chunk], (first_seq + k // 13) * FRAME_NS + 1)


def _faulty_recording(path: Path) -> None:
    """Stream "cam": frames 0-99, 105-199 (5 lost), seq 150 with a bad checksum (lost),
    a disconnection, then 0-49 again after the device came back. Stream "clean": 0-39."""
    with JournalWriter(path, {"test": "faulty"}) as j:
        cam = j.add_stream("cam")
        j.rx(cam, b"OKAY\r", 0)  # start-up dialogue, before the metadata
        j.update_stream(cam, TOY)
        clean = j.add_stream("clean", TOY)
        _write(j, cam, encode_frames(range(100)), 0)
        _write(j, cam, encode_frames(range(105, 200), corrupt=150), 105)
        _write(j, clean, encode_frames(range(40)), 0, chunk=13)
        j.event(cam, "disconnected", {}, 1_100_000_000)
        j.event(cam, "reconnected", {}, 1_500_000_000)
        for k in range(0, 50 * 13, 26):
            j.rx(cam, encode_frames(range(50))[k : k + 26], 1_500_000_000 + k // 13 * FRAME_NS)
        j.event(cam, "link_stats", {"frames": 244}, 1_800_000_000)


def test_replay_feeds_every_stream_through_its_own_decoder(tmp_path: Path) -> None:
    path = tmp_path / "run.spj"
    _faulty_recording(path)
    made: list[ToyDecoder] = []

    def factory(meta: dict[str, Any]) -> ToyDecoder:
        made.append(ToyDecoder(meta))
        return made[-1]

    got: dict[str, list[int]] = {}
    stamps: list[int] = []
    for name, block in replay(path, factory):
        got.setdefault(name, []).extend(block.seq.tolist())
        if name == "clean":
            stamps.extend(block.arrival_ns.tolist())
    expected_cam = [*range(100), *(s for s in range(105, 200) if s != 150), *range(50)]
    assert got == {"cam": expected_cam, "clean": list(range(40))}
    assert stamps == [s * FRAME_NS + 1 for s in range(40)]  # the recorded arrival stamps
    assert len(made) == 2
    assert made[0].discontinuities == 2  # disconnected, reconnected
    assert made[1].discontinuities == 0


def test_summary_counts_losses_errors_gaps_and_rate(tmp_path: Path) -> None:
    path = tmp_path / "run.spj"
    _faulty_recording(path)
    summary = summarize(path, toy_decoder_for)
    assert summary.complete and summary.truncated_bytes == 0 and summary.corrupt_records == 0
    assert summary.session["test"] == "faulty"
    cam, clean = summary.streams
    assert (cam.name, cam.family) == ("cam", "toy")
    assert cam.frames == 244
    assert cam.lost_frames == 6  # 100-104, and 150 whose checksum failed
    assert cam.crc_errors == 1
    assert cam.resyncs >= 1
    assert cam.gaps == 3  # two lost-frame runs + one disconnection
    assert cam.reconnects == 1 and cam.disconnections == 1
    assert cam.undecoded_bytes == 5  # b"OKAY\r" came before the metadata
    assert cam.bytes == 5 + 245 * 13
    assert cam.duration_source == "arrival"  # the stream broke: ticks restart
    assert cam.duration_s == pytest.approx((1_500_000_000 + 48 * FRAME_NS - 1) / 1e9, abs=1e-3)
    assert cam.rate_hz == pytest.approx(200.0)  # lost frames count, the disconnection does not
    assert cam.live_stats == {"frames": 244}
    assert (clean.frames, clean.lost_frames, clean.gaps, clean.duration_source) == (
        40,
        0,
        0,
        "ticks",
    )
    assert clean.duration_s == pytest.approx(39 * 5 / 1000.0)
    assert clean.rate_hz == pytest.approx(200.0)


def test_summary_to_json(tmp_path: Path) -> None:
    path = tmp_path / "run.spj"
    _faulty_recording(path)
    summary = summarize(path, toy_decoder_for)
    data = json.loads(summary.to_json())
    assert data == summary.to_dict()
    assert {"complete", "truncated_bytes", "corrupt_records", "streams"} <= set(data)
    for stream in data["streams"]:
        for key in ("name", "frames", "lost_frames", "crc_errors", "resyncs", "gaps"):
            assert isinstance(stream[key], int | str)
        assert isinstance(stream["duration_s"], float) and isinstance(stream["rate_hz"], float)


def test_killed_recording_summarises_what_it_holds(tmp_path: Path) -> None:
    path = tmp_path / "run.spj"
    with JournalWriter(path, {}) as j:
        s = j.add_stream("cam", TOY)
        _write(j, s, encode_frames(range(100)), 0, chunk=130)  # 10 frames per record
    data = path.read_bytes()
    path.write_bytes(data[: len(data) - 60 - 24 - 130])  # cut inside the last RX record
    summary = summarize(path, toy_decoder_for)
    assert not summary.complete and summary.truncated_bytes > 0
    assert summary.streams[0].frames == 90


def test_undecodable_stream_is_reported_not_fatal_to_the_summary(tmp_path: Path) -> None:
    path = tmp_path / "run.spj"
    with JournalWriter(path, {}) as j:
        good = j.add_stream("cam", TOY)
        odd = j.add_stream("odd", {"family": "unheard-of"})
        j.rx(good, encode_frames(range(3)), 1)
        j.rx(odd, b"\x00" * 10, 2)
    cam, odd_summary = summarize(path, toy_decoder_for).streams
    assert cam.frames == 3
    assert odd_summary.frames == 0 and odd_summary.undecoded_bytes == 10
    assert "unheard-of" in odd_summary.undecodable
    with pytest.raises(RecordingError, match="stream 'odd' cannot be decoded: not a toy stream"):
        list(replay(path, toy_decoder_for))


def test_summary_of_a_file_that_is_not_a_recording(tmp_path: Path) -> None:
    path = tmp_path / "notes.txt"
    path.write_text("hello")
    with pytest.raises(RecordingError, match="not a spotlab journal"):
        summarize(path, toy_decoder_for)


def test_session_recording_replays_to_the_live_frames(tmp_path: Path) -> None:
    path = tmp_path / "run.spj"
    devices = [FakeDevice("cam"), FakeDevice("timer", period_s=0.004, frames_per_block=1)]
    session = Session(devices, [Recorder(path)])
    session.run_for(0.2)
    summary = {s.name: s for s in summarize(path, toy_decoder_for).streams}
    for device in devices:
        s = summary[device.name]
        assert s.frames == session.frames[device.name] == device.stats.frames
        assert (s.lost_frames, s.crc_errors, s.gaps) == (0, 0, 0)
        assert s.bytes == device.stats.bytes + len(b"OKAY\r")
        assert s.undecoded_bytes == len(b"OKAY\r")  # start-up reply, before the metadata
        assert s.live_stats == device.stats.as_dict()
    blocks = [b for name, b in replay(path, toy_decoder_for) if name == "cam"]
    seq = np.concatenate([b.seq for b in blocks])
    assert (seq == np.arange(len(seq))).all()
