"""What a started driver streams over a stretch of time, for the conformance suites."""

from __future__ import annotations

import time
from typing import Protocol

from spotlab.core.frames import FrameBlock

__all__ = ["Receiver", "collect"]


class Receiver(Protocol):
    """A started driver: :meth:`recv` gives a block, or None when nothing came in time."""

    def recv(self, timeout: float | None = ...) -> FrameBlock | None: ...


def collect(driver: Receiver, seconds: float) -> FrameBlock:
    """The frames a started driver receives in ``seconds`` s (AssertionError if none)."""
    blocks: list[FrameBlock] = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        block = driver.recv(timeout=0.2)
        if block is not None and len(block):
            blocks.append(block)
    assert blocks, f"no frame within {seconds} s"
    return FrameBlock.concat(blocks)
