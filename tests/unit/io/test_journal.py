"""Journal round trip, record types, damage, truncation and refusals."""

from __future__ import annotations

import os
import struct
import time
import zlib
from pathlib import Path

import pytest

from spotlab.core.errors import ConfigurationError, RecordingError
from spotlab.io.journal import (
    FILE_MAGIC,
    MAX_PAYLOAD,
    RECORD_HEADER_SIZE,
    RECORD_MAGIC,
    SESSION_STREAM,
    JournalReader,
    JournalWriter,
    RecordType,
    encode_file_header,
    encode_record,
)


def _write_small(path: Path) -> list[tuple[RecordType, int, int, bytes]]:
    """A small journal of every record type; returns what was written after the session META."""
    with JournalWriter(path, {"operator": "test"}) as j:
        a = j.add_stream("cam", {"family": "toy", "n": 1})
        b = j.add_stream("timer", {"family": "toy2"})
        j.tx(a, b"START:\r", 100)
        j.rx(a, b"OKAY\r", 200)
        for i in range(6):
            j.rx(b if i % 2 else a, bytes([i]) * (i + 3), 1000 + i)
        j.event(a, "disconnected", {"why": "cable"}, 2000)
        j.event(a, "reconnected", {}, 3000)
        j.update_stream(a, {"family": "toy", "n": 2})
        j.event(SESSION_STREAM, "note", {"text": "hello"}, 4000)
    return [(r.type, r.stream, r.t_ns, r.payload) for r in JournalReader(path)][1:]


def test_round_trip_every_record_type(tmp_path: Path) -> None:
    path = tmp_path / "run.spj"
    with JournalWriter(path, {"operator": "ab", "subject": 7}) as j:
        cam = j.add_stream("selspot0", {"family": "selspot", "spec": {"tick_hz": 1e6}})
        j.tx(cam, b"START:\r", 5)
        j.rx(cam, b"\x00\x01\xff", 10)
        j.event(cam, "device_reset", {"code": 3}, 20)
    reader = JournalReader(path)
    records = list(reader)
    kinds = [r.type for r in records]
    assert kinds == [
        RecordType.META,
        RecordType.META,
        RecordType.TX,
        RecordType.RX,
        RecordType.EVENT,
        RecordType.END,
    ]
    session = records[0].json()
    assert records[0].stream == SESSION_STREAM
    assert session["operator"] == "ab" and session["subject"] == 7
    for key in ("start_time_iso", "start_time_ns", "start_monotonic_ns", "spotlab_version", "host"):
        assert key in session
    assert abs(session["start_time_ns"] - time.time_ns()) < 60e9
    assert reader.session == session
    assert records[1].json() == {
        "name": "selspot0",
        "metadata": {"family": "selspot", "spec": {"tick_hz": 1e6}},
    }
    assert (records[2].payload, records[2].t_ns) == (b"START:\r", 5)
    assert (records[3].payload, records[3].t_ns, records[3].stream) == (b"\x00\x01\xff", 10, cam)
    assert records[4].json() == {"kind": "device_reset", "detail": {"code": 3}}
    assert "stop_time_iso" in records[5].json()
    assert reader.complete
    assert reader.streams == {"selspot0": {"family": "selspot", "spec": {"tick_hz": 1e6}}}
    assert reader.stream_name(cam) == "selspot0"
    assert reader.corrupt_records == 0 and reader.truncated_bytes == 0


def test_stream_metadata_update_and_numpy_values(tmp_path: Path) -> None:
    np = pytest.importorskip("numpy")
    path = tmp_path / "run.spj"
    with JournalWriter(path, {}) as j:
        i = j.add_stream("s")
        j.update_stream(i, {"rate": np.float64(200.0), "leds": np.arange(3), "raw": b"\x01"})
    assert JournalReader(path).streams == {"s": {"rate": 200.0, "leds": [0, 1, 2], "raw": "01"}}


def test_long_wire_chunk_is_split_not_refused(tmp_path: Path) -> None:
    path = tmp_path / "run.spj"
    data = os.urandom(MAX_PAYLOAD * 2 + 5)
    with JournalWriter(path, {}) as j:
        j.rx(j.add_stream("s"), data, 1)
    parts = [r for r in JournalReader(path) if r.type == RecordType.RX]
    assert [len(p.payload) for p in parts] == [MAX_PAYLOAD, MAX_PAYLOAD, 5]
    assert b"".join(p.payload for p in parts) == data


def test_refuses_to_overwrite(tmp_path: Path) -> None:
    path = tmp_path / "run.spj"
    path.write_bytes(b"precious")
    with pytest.raises(RecordingError, match="already exists"):
        JournalWriter(path, {})
    assert path.read_bytes() == b"precious"
    with JournalWriter(path, {}, overwrite=True):
        pass
    assert JournalReader(path).complete


def test_cannot_create_names_the_cause(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match=r"cannot create journal .*No such file"):
        JournalWriter(tmp_path / "missing" / "run.spj", {})


def test_writer_refuses_bad_use(tmp_path: Path) -> None:
    with pytest.raises(ConfigurationError, match="may not set"):
        JournalWriter(tmp_path / "a.spj", {"host": "x"})
    with JournalWriter(tmp_path / "b.spj", {}) as j:
        j.add_stream("s")
        with pytest.raises(ConfigurationError, match="already declared"):
            j.add_stream("s")
        with pytest.raises(ConfigurationError, match="not declared"):
            j.rx(3, b"x", 1)
        with pytest.raises(ConfigurationError, match="int64"):
            j.rx(0, b"x", 2**63)
    with pytest.raises(RecordingError, match="closed"):
        j.rx(0, b"x", 1)
    j.close()  # twice is fine


def test_records_reach_the_os_within_the_flush_interval(tmp_path: Path) -> None:
    path = tmp_path / "run.spj"
    with JournalWriter(path, {}, flush_interval_s=0.02) as j:
        j.rx(j.add_stream("s"), b"abc", 1)
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline:
            reader = JournalReader(path)
            if any(r.type == RecordType.RX for r in reader):
                break
            time.sleep(0.01)
        assert [r.payload for r in reader if r.type == RecordType.RX] == [b"abc"]
        assert not reader.complete and reader.truncated_bytes == 0


def test_periodic_fsync_option(tmp_path: Path) -> None:
    path = tmp_path / "run.spj"
    with JournalWriter(path, {}, flush_interval_s=0.01, fsync_interval_s=0.01) as j:
        j.rx(j.add_stream("s"), b"abc", 1)
        time.sleep(0.05)
    assert JournalReader(path).complete


def test_crc_damage_in_the_middle_resyncs(tmp_path: Path) -> None:
    path = tmp_path / "run.spj"
    written = _write_small(path)
    data = bytearray(path.read_bytes())
    offsets = [r.offset for r in JournalReader(path)]
    victim = 6  # an RX record in the middle
    data[offsets[victim] + RECORD_HEADER_SIZE] ^= 0x40  # flip a payload bit
    path.write_bytes(data)
    reader = JournalReader(path)
    got = [(r.type, r.stream, r.t_ns, r.payload) for r in reader][1:]
    assert got == written[: victim - 1] + written[victim:]
    assert reader.corrupt_records == 1
    assert reader.scan().skipped_bytes == offsets[victim + 1] - offsets[victim]
    assert reader.complete and reader.truncated_bytes == 0


def test_damaged_length_field_and_garbage_between_records(tmp_path: Path) -> None:
    path = tmp_path / "run.spj"
    written = _write_small(path)
    offsets = [r.offset for r in JournalReader(path)]
    data = bytearray(path.read_bytes())
    # Length field of record 4 claims a huge payload; garbage with a fake magic after record 8.
    struct.pack_into("<I", data, offsets[4] + 8, 0x7FFFFFFF)
    garbage = b"\x00junk" + RECORD_MAGIC + b"\x02\x00\x00\x00garbage-garbage-garbage"
    data[offsets[8] : offsets[8]] = garbage
    path.write_bytes(data)
    reader = JournalReader(path, chunk_size=4096)
    got = [(r.type, r.stream, r.t_ns, r.payload) for r in reader][1:]
    assert got == written[:3] + written[4:]
    assert reader.corrupt_records == 2
    assert reader.complete


def test_truncated_at_every_byte_offset(tmp_path: Path) -> None:
    """A journal cut anywhere after its header opens with every complete record before the cut."""
    full_path = tmp_path / "full.spj"
    _write_small(full_path)
    full = full_path.read_bytes()
    records = list(JournalReader(full_path))
    ends = [r.offset + RECORD_HEADER_SIZE + len(r.payload) for r in records]
    cut_path = tmp_path / "cut.spj"
    for cut in range(16, len(full) + 1):
        cut_path.write_bytes(full[:cut])
        reader = JournalReader(cut_path)
        got = list(reader)
        n_complete = sum(e <= cut for e in ends)
        assert [(r.offset, r.payload) for r in got] == [
            (r.offset, r.payload) for r in records[:n_complete]
        ], cut
        last_end = ends[n_complete - 1] if n_complete else 16
        assert reader.truncated_bytes == cut - last_end, cut
        assert reader.corrupt_records == 0, cut
        assert reader.complete == (cut == len(full)), cut
        if n_complete:
            assert reader.session["operator"] == "test"


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"", "is empty"),
        (FILE_MAGIC[:5], "only 5 bytes of a journal header"),
        (b"PK\x03\x04 this is a zip file, not a journal", "not a spotlab journal: it starts with"),
        (b"short", "not a spotlab journal"),
        (os.urandom(4096).replace(b"\x89", b"\x88"), "not a spotlab journal"),
        (encode_file_header(version=2), "version-2 journal; this spotlab reads versions 1 to 1"),
        (encode_file_header(version=0), "version 0, which does not exist"),
        (FILE_MAGIC + b"\x01\x00\x00\x00\x00\x00\x00\x00", "header is damaged"),
    ],
    ids=["empty", "partial-header", "zip", "short", "random", "future", "zero", "bad-crc"],
)
def test_not_a_journal_raises_naming_cause_and_path(
    tmp_path: Path, content: bytes, message: str
) -> None:
    path = tmp_path / "x.spj"
    path.write_bytes(content)
    with pytest.raises(RecordingError, match=message) as info:
        JournalReader(path)
    assert str(path) in str(info.value)


def test_missing_file_and_directory(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="no such recording"):
        JournalReader(tmp_path / "nope.spj")
    with pytest.raises(RecordingError, match="is a directory"):
        JournalReader(tmp_path)


def test_header_only_is_an_empty_incomplete_journal(tmp_path: Path) -> None:
    path = tmp_path / "x.spj"
    path.write_bytes(encode_file_header())
    reader = JournalReader(path)
    assert list(reader) == []
    assert reader.session == {} and not reader.complete and reader.truncated_bytes == 0


def test_golden_record_bytes() -> None:
    """The worked example of docs/journal.md."""
    assert encode_file_header().hex(" ") == "89 53 50 4f 54 4a 52 0a 01 00 00 00 96 63 85 5d"
    rec = encode_record(RecordType.RX, 0, 1_000_000_000, b"\x01\x02\x03")
    assert rec.hex(" ") == (
        "a5 53 4a 52 02 00 00 00 03 00 00 00 00 ca 9a 3b 00 00 00 00 1c 81 ad b7 01 02 03"
    )
    assert struct.unpack_from("<I", rec, 20)[0] == zlib.crc32(rec[:20] + rec[24:])
    meta = encode_record(RecordType.META, 0, 1000, b'{"name":"cam","metadata":{"family":"toy"}}')
    assert meta[:24].hex(" ") == (
        "a5 53 4a 52 01 00 00 00 2a 00 00 00 e8 03 00 00 00 00 00 00 4b 2f 90 49"
    )
    event = encode_record(RecordType.EVENT, 0, 2 * 10**9, b'{"kind":"disconnected","detail":{}}')
    assert event[:24].hex(" ") == (
        "a5 53 4a 52 04 00 00 00 23 00 00 00 00 94 35 77 00 00 00 00 0f bc 76 b4"
    )


def test_large_file_is_read_in_chunks(tmp_path: Path) -> None:
    path = tmp_path / "run.spj"
    chunk = os.urandom(4096)
    with JournalWriter(path, {}) as j:
        s = j.add_stream("s")
        for i in range(300):
            j.rx(s, chunk, i)
    reader = JournalReader(path, chunk_size=4096)
    n = sum(1 for r in reader if r.type == RecordType.RX and r.payload == chunk)
    assert n == 300 and reader.complete
