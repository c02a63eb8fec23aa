"""CEN data frames cut out of a byte stream: MCS-1 framing with a variable ``len`` (centroid.md §3).

:class:`VariableFrameDecoder` is the MCS-1 :class:`FrameDecoder` (resynchronisation,
event frames, banner detection, arrival stamps, counters: all inherited) with
one change: a data frame's ``len`` may be anything from ``min_payload`` to
``max_payload`` bytes, so frames are checked one at a time (no fixed-length
trains) and handed out zero-padded to the longest frame of the batch. Each
row's own length is its header's ``len`` (bytes 6-7) plus 12.
"""

from __future__ import annotations

import binascii

import numpy as np

from spotlab.core.crc import CRC16_INIT
from spotlab.core.errors import ConfigurationError
from spotlab.core.stats import LinkStats
from spotlab.drivers.mcs1.framing import (
    EVENT_TYPE,
    HEADER_BYTES,
    MAX_PAYLOAD,
    OVERHEAD,
    PROTOCOL_VERSION,
    SYNC,
    EventFrame,
    FrameBatch,
    FrameDecoder,
)

_crc = binascii.crc_hqx


class VariableFrameDecoder(FrameDecoder):
    """Cuts checked MCS-1 frames of varying length out of a byte stream.

    Parameters
    ----------
    frame_type : int
        The family's data frame type (``0x05`` for CEN).
    min_payload, max_payload : int
        Accepted range of a data frame's ``len`` (1 to 65535).
    stats : LinkStats, optional
        Counters to update.
    """

    def __init__(
        self,
        frame_type: int,
        min_payload: int,
        max_payload: int,
        stats: LinkStats | None = None,
    ) -> None:
        if not 1 <= min_payload <= max_payload <= 0xFFFF:
            raise ConfigurationError(
                f"payload range must satisfy 1 <= min <= max <= 65535, got {min_payload}, "
                f"{max_payload}"
            )
        super().__init__(frame_type, min(min_payload, MAX_PAYLOAD), stats)
        self.min_payload = min_payload
        self.max_payload = max_payload

    def _parse(self, final: bool) -> FrameBatch:
        view = bytes(self._buf)
        n = len(view)
        spans: list[tuple[int, int]] = []  # (start, length) of accepted data frames
        pos = need = 0
        with memoryview(view) as mv:
            while True:
                i = view.find(SYNC, pos)
                if i < 0:
                    keep = 1 if (not final and n > pos and view[-1] == 0xA5) else 0
                    self._skip(view, pos, n - keep)
                    pos = n - keep
                    need = n - pos + 1 if keep else 0
                    break
                self._skip(view, pos, i)
                pos = i
                avail = n - pos
                if avail < HEADER_BYTES:
                    if final:
                        self._skip(view, pos, n)
                        pos = n
                    else:
                        need = HEADER_BYTES
                    break
                ctype, clen = view[pos + 2], view[pos + 6] | (view[pos + 7] << 8)
                header_ok = (
                    _crc(mv[pos : pos + 8], CRC16_INIT) == (view[pos + 8] | (view[pos + 9] << 8))
                    and view[pos + 3] >> 4 == PROTOCOL_VERSION
                    and (
                        (ctype == self.frame_type and self.min_payload <= clen <= self.max_payload)
                        or (ctype == EVENT_TYPE and 1 <= clen <= MAX_PAYLOAD)
                    )
                )
                if not header_ok:
                    self.stats.crc_errors += 1
                    self._skip(view, pos, pos + 1)
                    pos += 1
                    continue
                end = pos + clen + OVERHEAD
                if n < end:
                    if not final:
                        need = end - pos
                        break
                    self.stats.crc_errors += 1  # truncated by the end of input
                    self._skip(view, pos, pos + 2)
                    pos += 2
                    continue
                if _crc(mv[pos + HEADER_BYTES : end - 2], CRC16_INIT) != (
                    view[end - 2] | (view[end - 1] << 8)
                ):
                    self.stats.crc_errors += 1
                    self._skip(view, pos, pos + 2)
                    pos += 2
                    continue
                self._accepted(end - pos)
                if ctype == EVENT_TYPE:
                    stamp = self._arrival(np.array([self._base + end - 1], dtype=np.int64))
                    self.events.append(
                        EventFrame(view[pos + HEADER_BYTES : end - 2], int(stamp[0]))
                    )
                else:
                    spans.append((pos, end - pos))
                pos = end
        batch = self._rows(view, spans)
        self._consume(pos)
        self._need = need
        return batch

    def _rows(self, view: bytes, spans: list[tuple[int, int]]) -> FrameBatch:
        if not spans:
            return self._empty()
        width = max(length for _, length in spans)
        rows = np.zeros((len(spans), width), dtype=np.uint8)
        for k, (start, length) in enumerate(spans):
            rows[k, :length] = np.frombuffer(view, np.uint8, length, start)
        last = np.array([self._base + s + length - 1 for s, length in spans], dtype=np.int64)
        return FrameBatch(rows, self._arrival(last))
