"""One stream of a recording as a journal of its own, for the processing that reads one.

``spotlab reconstruct`` reads a recording of one device; a scenario records all its
devices into one journal. :func:`one_stream` copies one stream's records (its
metadata, wire bytes and events) and the session's description into a new journal.
"""

from __future__ import annotations

from pathlib import Path

from spotlab.io.journal import JournalReader, JournalWriter, RecordType

#: Session keys the writer sets itself.
_AUTO = ("journal_version", "spotlab_version", "host", "pid", "start_time_iso",
         "start_time_ns", "start_monotonic_ns")  # fmt: skip


def one_stream(journal: Path, name: str, out: Path) -> Path:
    """Write stream ``name`` of ``journal`` to ``out`` (replaced if it exists).

    Raises
    ------
    KeyError
        When the journal declares no such stream.
    """
    reader = JournalReader(journal)
    facts = reader.scan()
    index = {v: k for k, v in facts.stream_names.items()}[name]
    session = {k: v for k, v in facts.session.items() if k not in _AUTO}
    with JournalWriter(out, session, overwrite=True, fsync_on_close=False) as writer:
        mine = -1
        for rec in reader:
            if rec.stream != index or rec.type == RecordType.END:
                continue
            if rec.type == RecordType.META:
                meta = rec.json().get("metadata") or {}
                if mine < 0:
                    mine = writer.add_stream(name, meta)
                else:
                    writer.update_stream(mine, meta)
            elif mine < 0:
                continue
            elif rec.type == RecordType.RX:
                writer.rx(mine, rec.payload, rec.t_ns)
            elif rec.type == RecordType.TX:
                writer.tx(mine, rec.payload, rec.t_ns)
            elif rec.type == RecordType.EVENT:
                event = rec.json()
                writer.event(mine, str(event.get("kind")), event.get("detail"), rec.t_ns)
    return out


__all__ = ["one_stream"]
