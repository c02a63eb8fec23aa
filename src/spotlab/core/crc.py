"""Checksums computed in C by the standard library.

Two checksums serve every spotlab wire protocol and file:

* CRC-16/CCITT-FALSE (polynomial 0x1021, initial value 0xFFFF, not reflected,
  no final XOR; check value 0x29B1 for ``b"123456789"``), computed by
  :func:`binascii.crc_hqx`. Used in frame headers, frame payloads and ASCII
  commands and replies.
* CRC-32 (zlib), used by the recording journal.

A pure-Python CRC would cap decoding at a few MB/s; these run at memory speed.
"""

from __future__ import annotations

import binascii
import zlib

CRC16_INIT = 0xFFFF


def crc16(data: bytes | bytearray | memoryview, init: int = CRC16_INIT) -> int:
    """CRC-16/CCITT-FALSE of ``data``.

    Parameters
    ----------
    data : bytes-like
        The bytes to check.
    init : int, optional
        Initial register value; pass a previous result to continue a running CRC.

    Returns
    -------
    int
        The 16-bit CRC.
    """
    return binascii.crc_hqx(data, init)


def crc16_hex(text: str) -> str:
    """CRC-16/CCITT-FALSE of an ASCII text as four upper-case hex digits."""
    return f"{crc16(text.encode('ascii')):04X}"


def crc32(data: bytes | bytearray | memoryview, init: int = 0) -> int:
    """CRC-32 (as zlib computes it) of ``data``."""
    return zlib.crc32(data, init) & 0xFFFFFFFF
