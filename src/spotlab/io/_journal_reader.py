"""Reader of the recording journal: lazy, checksummed, tolerant of damage.

The reader reads the file in chunks (memory constant in the file size),
checks every record's CRC, skips a damaged stretch by searching for the next
record magic (counting it as one corrupt record), and reports a cut-off tail —
what a killed recording leaves — as information, not as an error. Only a file
that is not a journal at all raises.
"""

from __future__ import annotations

import json
import os
import zlib
from collections.abc import Generator, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from spotlab.core.errors import RecordingError
from spotlab.io._journal_format import (
    FILE_HEADER,
    FILE_MAGIC,
    FORMAT_VERSION,
    MAX_PAYLOAD,
    RECORD_CRC,
    RECORD_HEAD,
    RECORD_HEADER_SIZE,
    RECORD_MAGIC,
    RECORD_TYPES,
    SESSION_STREAM,
    RecordType,
)

_HEAD = RECORD_HEAD.size


@dataclass(frozen=True, slots=True)
class Record:
    """One valid record of a journal.

    Attributes
    ----------
    type : RecordType
        META, RX, TX, EVENT or END.
    stream : int
        Stream index, or ``SESSION_STREAM`` (65535) for session-wide records.
    t_ns : int
        Host monotonic time in ns (arrival of RX bytes, sending of TX bytes).
    payload : bytes
        Raw wire bytes (RX, TX) or UTF-8 JSON (META, EVENT, END).
    offset : int
        Byte offset of the record in the file.
    """

    type: RecordType
    stream: int
    t_ns: int
    payload: bytes
    offset: int

    def json(self) -> Any:
        """The payload of a META, EVENT or END record, decoded.

        Raises
        ------
        RecordingError
            If the payload is not UTF-8 JSON.
        """
        try:
            return json.loads(self.payload)
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise RecordingError(
                f"{self.type.name} record at byte {self.offset} does not hold JSON: {exc}"
            ) from exc


@dataclass
class JournalFacts:
    """What one complete pass over a journal found.

    Attributes
    ----------
    session : dict
        The session description (first META record), empty if it was damaged.
    stream_names : dict of int to str
        Declared streams by index.
    streams : dict of str to dict
        Latest metadata of each stream, by name.
    complete : bool
        The END record was seen: the recording was closed cleanly.
    end : dict or None
        The END record's content.
    corrupt_records : int
        Damaged stretches skipped between valid records (each counted once).
    skipped_bytes : int
        Bytes in those stretches.
    truncated_bytes : int
        Bytes after the last valid record that start no valid record: the
        partial tail of a killed or still-running recording.
    records : int
        Valid records read.
    """

    session: dict[str, Any] = field(default_factory=dict)
    stream_names: dict[int, str] = field(default_factory=dict)
    streams: dict[str, dict[str, Any]] = field(default_factory=dict)
    complete: bool = False
    end: dict[str, Any] | None = None
    corrupt_records: int = 0
    skipped_bytes: int = 0
    truncated_bytes: int = 0
    records: int = 0

    def note(self, rec: Record) -> None:
        """Update the facts with a valid record."""
        self.records += 1
        if rec.type == RecordType.META:
            info = _json_or_none(rec)
            if rec.stream == SESSION_STREAM:
                if not self.session and isinstance(info, dict):
                    self.session = info
                return
            name = self.stream_names.get(rec.stream)
            if isinstance(info, dict) and isinstance(info.get("name"), str):
                name = name or info["name"]
                meta = info.get("metadata")
                self.streams[name] = meta if isinstance(meta, dict) else {}
            name = name or f"#{rec.stream}"
            self.stream_names[rec.stream] = name
            self.streams.setdefault(name, {})
        elif rec.type == RecordType.END:
            self.complete = True
            info = _json_or_none(rec)
            self.end = info if isinstance(info, dict) else {}


def _json_or_none(rec: Record) -> Any:
    # A CRC-valid record holding bad JSON is a writer bug; keep reading the rest.
    try:
        return rec.json()
    except RecordingError:
        return None


def _check_header(path: Path, head: bytes, size: int) -> int:
    """Validate the 16-byte file header; return the format version."""
    if size == 0:
        raise RecordingError(
            f"{path} is empty (0 bytes): not a spotlab journal "
            "(a recording killed before its first write leaves such a file)"
        )
    if len(head) < FILE_HEADER.size:
        if FILE_MAGIC.startswith(head[: len(FILE_MAGIC)]):
            raise RecordingError(
                f"{path} holds only {len(head)} bytes of a journal header "
                f"({FILE_HEADER.size} needed): nothing was recorded"
            )
        raise RecordingError(f"{path} is not a spotlab journal (too short, wrong magic)")
    magic, version, _flags, crc = FILE_HEADER.unpack(head)
    if magic != FILE_MAGIC:
        raise RecordingError(
            f"{path} is not a spotlab journal: it starts with {magic!r}, not {FILE_MAGIC!r}"
        )
    if zlib.crc32(head[:12]) != crc:
        raise RecordingError(f"{path}: the journal header is damaged (CRC mismatch)")
    if version > FORMAT_VERSION:
        raise RecordingError(
            f"{path} is a version-{version} journal; this spotlab reads versions 1 to "
            f"{FORMAT_VERSION}: update spotlab to read it"
        )
    if version < 1:
        raise RecordingError(f"{path} declares journal version {version}, which does not exist")
    return int(version)


class JournalReader:
    """Read a journal written by :class:`JournalWriter`.

    Parameters
    ----------
    path : str or Path
        The journal.
    chunk_size : int, optional
        Bytes read at a time (default 1 MiB). Memory use is about
        ``chunk_size + MAX_PAYLOAD`` whatever the file size.

    Raises
    ------
    RecordingError
        If the file does not exist, cannot be read, is empty, is not a journal,
        has a damaged header, or is of a newer format version.

    Notes
    -----
    Iterating yields the valid records in file order. :attr:`streams`,
    :attr:`complete`, :attr:`corrupt_records` and :attr:`truncated_bytes` need
    a pass over the whole file; the first access makes one (constant memory)
    unless an iteration already ran to the end. A file still being written is
    read up to its current end; its partial last record counts as truncated.
    """

    def __init__(self, path: str | os.PathLike[str], *, chunk_size: int = 1 << 20) -> None:
        self.path = Path(path)
        self._chunk = max(4096, int(chunk_size))
        try:
            with open(self.path, "rb") as f:
                size = os.fstat(f.fileno()).st_size
                head = f.read(FILE_HEADER.size)
        except FileNotFoundError:
            raise RecordingError(f"{self.path}: no such recording") from None
        except IsADirectoryError:
            raise RecordingError(f"{self.path} is a directory, not a recording") from None
        except OSError as exc:
            raise RecordingError(f"cannot read {self.path}: {exc.strerror or exc}") from exc
        self.version = _check_header(self.path, head, size)
        self._facts: JournalFacts | None = None
        first = JournalFacts()
        records = self._records(first)
        for rec in records:
            first.note(rec)
            break
        records.close()
        self.session: dict[str, Any] = first.session
        """The session description written at creation (empty if damaged)."""

    # -- facts of a whole pass -------------------------------------------------
    def scan(self) -> JournalFacts:
        """Facts of the whole file (one pass, constant memory; cached)."""
        if self._facts is None:
            for _ in self:
                pass
        assert self._facts is not None
        return self._facts

    @property
    def streams(self) -> dict[str, dict[str, Any]]:
        """Latest metadata of each declared stream, by name."""
        return self.scan().streams

    @property
    def stream_names(self) -> dict[int, str]:
        """Declared stream names, by index."""
        return self.scan().stream_names

    @property
    def complete(self) -> bool:
        """Whether the recording was closed cleanly (END record present)."""
        return self.scan().complete

    @property
    def corrupt_records(self) -> int:
        """Damaged stretches skipped between valid records."""
        return self.scan().corrupt_records

    @property
    def truncated_bytes(self) -> int:
        """Bytes of partial record at the end of the file (0 for a clean file)."""
        return self.scan().truncated_bytes

    # -- iteration --------------------------------------------------------------
    def __iter__(self) -> Iterator[Record]:
        facts = JournalFacts()
        for rec in self._records(facts):
            facts.note(rec)
            yield rec
        self._facts = facts

    def _records(self, facts: JournalFacts) -> Generator[Record, None, None]:
        """Valid records in file order; damage and the tail are counted in ``facts``."""
        chunk = self._chunk
        try:
            f = open(self.path, "rb")  # closed in finally, across yields
        except OSError as exc:
            raise RecordingError(f"cannot read {self.path}: {exc.strerror or exc}") from exc
        try:
            f.seek(FILE_HEADER.size)
            buf = bytearray()
            base = FILE_HEADER.size  # file offset of buf[0]
            pos = 0
            eof = False
            bad_at: int | None = None  # file offset where the current damage began
            while True:
                avail = len(buf) - pos
                if avail < RECORD_HEADER_SIZE and not eof:
                    del buf[:pos]
                    base += pos
                    pos = 0
                    eof = self._fill(f, buf, chunk)
                    continue
                if avail == 0:
                    break
                end = -1
                if avail >= RECORD_HEADER_SIZE and buf.startswith(RECORD_MAGIC, pos):
                    _, rtype, flags, stream, length, t_ns = RECORD_HEAD.unpack_from(buf, pos)
                    if rtype in RECORD_TYPES and flags == 0 and length <= MAX_PAYLOAD:
                        end = pos + RECORD_HEADER_SIZE + length
                        if end > len(buf) and not eof:
                            del buf[:pos]
                            base += pos
                            pos = 0
                            eof = self._fill(f, buf, max(chunk, RECORD_HEADER_SIZE + length))
                            continue
                if 0 <= end <= len(buf):
                    payload = bytes(buf[pos + RECORD_HEADER_SIZE : end])
                    (crc,) = RECORD_CRC.unpack_from(buf, pos + _HEAD)
                    if zlib.crc32(payload, zlib.crc32(buf[pos : pos + _HEAD])) == crc:
                        if bad_at is not None:
                            facts.corrupt_records += 1
                            facts.skipped_bytes += base + pos - bad_at
                            bad_at = None
                        yield Record(RecordType(rtype), stream, t_ns, payload, base + pos)
                        pos = end
                        continue
                # Damage (or a cut-off tail): look for the next record magic.
                if bad_at is None:
                    bad_at = base + pos
                nxt = buf.find(RECORD_MAGIC, pos + 1)
                if nxt >= 0:
                    pos = nxt
                elif eof:
                    pos = len(buf)
                else:
                    # Keep the last bytes: a magic may straddle the chunk boundary.
                    pos = max(pos + 1, len(buf) - (len(RECORD_MAGIC) - 1))
                    del buf[:pos]
                    base += pos
                    pos = 0
                    eof = self._fill(f, buf, chunk)
            if bad_at is not None:
                facts.truncated_bytes = base + len(buf) - bad_at
        finally:
            f.close()

    def _fill(self, f: Any, buf: bytearray, n: int) -> bool:
        """Append up to ``n`` bytes of the file to ``buf``; return True at end of file."""
        try:
            data = f.read(n)
        except OSError as exc:
            raise RecordingError(f"cannot read {self.path}: {exc.strerror or exc}") from exc
        buf += data
        return not data

    def stream_name(self, index: int) -> str:
        """Name of stream ``index`` (``"session"`` for ``SESSION_STREAM``)."""
        if index == SESSION_STREAM:
            return "session"
        return self.stream_names.get(index, f"#{index}")
