"""A recording's streams come out in the order the devices were given (the journal's
stream indices), whichever device's first frame came in first: a rig's cameras follow
that order (a two-system export once triangulated system B's readings with A's
cameras, 370 px of ray residual, because B's first frame had come first)."""

from __future__ import annotations

import json
from pathlib import Path

import spotlab.simulators  # noqa: F401  (registers sim://)
from spotlab.console.cli import main
from spotlab.io.journal import JournalReader, JournalWriter, RecordType
from spotlab.processing.session_times import decode_streams


def _first_frames_swapped(src: Path, dst: Path) -> list[str]:
    """``src`` rewritten with every RX record of its first stream moved after the others'
    (same streams, same indices); the declared names in index order."""
    reader = JournalReader(src)
    names = [reader.stream_names[i] for i in sorted(reader.stream_names)]
    records = list(reader)
    first = min(reader.stream_names)
    late = [r for r in records if r.type == RecordType.RX and r.stream == first]
    with JournalWriter(dst, {"test": "stream order"}) as out:
        declared: set[int] = set()
        for rec in [r for r in records if r not in late] + late:
            if rec.stream not in reader.stream_names:
                continue  # the session's own records
            if rec.type == RecordType.META:
                meta = json.loads(rec.payload).get("metadata") or {}
                if rec.stream in declared:
                    out.update_stream(rec.stream, meta)
                else:
                    assert out.add_stream(reader.stream_names[rec.stream], meta) == rec.stream
                    declared.add(rec.stream)
            elif rec.type == RecordType.RX:
                out.rx(rec.stream, rec.payload, rec.t_ns)
            elif rec.type == RecordType.TX:
                out.tx(rec.stream, rec.payload, rec.t_ns)
    return names


def test_streams_come_in_the_order_of_the_journal_not_of_their_first_frames(
    tmp_path: Path,
) -> None:
    rec = tmp_path / "rec.spj"
    code = main([
        "record", "--device", "selspot=sim://selspot?seed=1,cameras=2,leds=4",
        "--device", "selspot=sim://selspot?seed=2,cameras=2,leds=4",
        "--seconds", "0.3", "--out", str(rec),
    ])  # fmt: skip
    assert code == 0
    swapped = tmp_path / "swapped.spj"
    names = _first_frames_swapped(rec, swapped)
    assert names == ["selspot0", "selspot1"]
    assert list(decode_streams(rec).blocks) == names
    decoded = decode_streams(swapped)
    first_rx = next(r.stream for r in JournalReader(swapped) if r.type == RecordType.RX)
    assert first_rx == 1  # selspot1's bytes, and so its first frame, come first
    assert list(decoded.blocks) == names and list(decoded.metadata) == names
