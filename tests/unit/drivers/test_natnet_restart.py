"""Motive's frame numbers going back (a take restarted): one gap, the frames kept.

A number at most ``REORDER_WINDOW`` behind the last is a stale datagram (a duplicate,
dropped, as before); further back it is a restart, and ``seq`` goes on after the last.
The simulator's ``restart``, ``late`` and ``slow`` faults parse and show in its truth.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spotlab.drivers.natnet import NatNetDecoder
from spotlab.drivers.natnet.decoding import REORDER_WINDOW
from spotlab.simulators.natnet import parse_faults
from spotlab.testing.golden import golden_vector

SPEC = Path(__file__).parents[3] / "docs" / "protocols" / "natnet.md"
FRAME = golden_vector(SPEC, "A frame with 2 labelled markers")


def _frame(number: int) -> bytes:
    out = bytearray(FRAME)
    out[4:8] = number.to_bytes(4, "little")
    return bytes(out)


def test_a_restart_keeps_its_frames_and_counts_one_gap() -> None:
    dec = NatNetDecoder((4, 1), "walker", ["A", "B"])
    numbers = [500, 501, 502, 502 - REORDER_WINDOW, 0, 1, 2]
    seq = np.concatenate([dec.feed(_frame(k), 0).seq for k in numbers])
    assert list(seq) == [500, 501, 502, 503, 504, 505]
    assert dec.stats.duplicates == 1 and dec.stats.gaps == 1 and dec.stats.lost_frames == 0
    assert dec.restarts == 1 and dec.summary()["restarts"] == 1


def test_simulator_fault_kinds_parse() -> None:
    faults = parse_faults("late@1:4,restart@2,slow@3:5,drop@0.5,disconnect@4:1")
    assert [(f.kind, f.n) for f in faults] == [
        ("late", 4), ("restart", 1), ("slow", 5), ("drop", 1), ("disconnect", 1)
    ]  # fmt: skip
    with pytest.raises(ValueError, match="restart@T"):
        parse_faults("restart@2:3")
