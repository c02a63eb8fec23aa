"""Crash-safe recording journal: raw wire bytes, events and metadata.

An append-only file of checksummed records (format in docs/journal.md):
:class:`JournalWriter` writes it from acquisition threads, cheaply and with
at most the last ~50 ms at risk if the process is killed; :class:`JournalReader`
reads it back lazily, skipping damage and accepting a cut-off tail.

Examples
--------
>>> import tempfile, pathlib
>>> path = pathlib.Path(tempfile.mkdtemp()) / "run.spj"
>>> with JournalWriter(path, {"operator": "ab"}) as journal:
...     cam = journal.add_stream("selspot0", {"family": "selspot"})
...     journal.rx(cam, b"\\x01\\x02\\x03", t_ns=1_000_000)
>>> reader = JournalReader(path)
>>> [r.payload for r in reader if r.type == RecordType.RX]
[b'\\x01\\x02\\x03']
>>> reader.complete, reader.streams
(True, {'selspot0': {'family': 'selspot'}})
"""

from __future__ import annotations

import os

from spotlab.io._journal_format import (
    FILE_MAGIC,
    FORMAT_VERSION,
    MAX_PAYLOAD,
    RECORD_HEADER_SIZE,
    RECORD_MAGIC,
    SESSION_STREAM,
    RecordType,
    encode_file_header,
    encode_record,
)
from spotlab.io._journal_reader import JournalFacts, JournalReader, Record
from spotlab.io._journal_writer import JournalWriter


def is_journal(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is a regular file that starts with the journal's magic bytes
    (:data:`FILE_MAGIC`), whatever its name ends in."""
    try:
        with open(path, "rb") as fh:
            return fh.read(len(FILE_MAGIC)) == FILE_MAGIC
    except OSError:
        return False


__all__ = [
    "FILE_MAGIC",
    "FORMAT_VERSION",
    "MAX_PAYLOAD",
    "RECORD_HEADER_SIZE",
    "RECORD_MAGIC",
    "SESSION_STREAM",
    "JournalFacts",
    "JournalReader",
    "JournalWriter",
    "Record",
    "RecordType",
    "encode_file_header",
    "encode_record",
    "is_journal",
]
