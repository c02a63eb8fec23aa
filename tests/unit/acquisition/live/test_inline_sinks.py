"""Session: inline sinks run in the reader thread, their errors are counted."""

from __future__ import annotations

import threading
from typing import Any

import numpy as np

from spotlab.acquisition.interfaces import InlineSink
from spotlab.acquisition.session import Session, SinkBase
from spotlab.core.errors import ProtocolError
from spotlab.core.frames import FrameBlock
from spotlab.core.stats import LinkStats
from spotlab.core.streams import StreamSpec
from spotlab.core.wire import WireTap


class CountingDevice:
    """Blocks of one frame, ``n`` of them, then None; ``fail_at``: recv raises once."""

    def __init__(self, name: str, n: int = 50, fail_at: int | None = None) -> None:
        self.name = name
        self.stats = LinkStats()
        self.n = n
        self.fail_at = fail_at
        self.calls = 0
        self.sent = 0

    @property
    def spec(self) -> StreamSpec:
        return StreamSpec(self.name, "image2d", 1, 1, 100.0, 1000.0)

    def start(self) -> None:
        pass

    def stop(self) -> None:
        pass

    def close(self) -> None:
        pass

    def add_tap(self, tap: WireTap) -> None:
        pass

    def metadata(self) -> dict[str, Any]:
        return {"family": "test"}

    def recv(self, timeout: float | None = None) -> FrameBlock | None:
        self.calls += 1
        if self.calls == self.fail_at:
            raise ProtocolError("bad header")
        if self.sent >= self.n:
            threading.Event().wait(0.001)
            return None
        s = self.sent
        self.sent += 1
        return FrameBlock(
            np.array([s]),
            np.array([s * 10]),
            np.array([0]),
            np.zeros((1, 1, 1, 1)),
            np.zeros((1, 1, 1), np.uint8),
            np.zeros(1, np.uint16),
        )


class ThreadSink(SinkBase):
    def __init__(self, name: str, inline: bool, fail_every: int = 0) -> None:
        self.name = name
        self.inline = inline
        self.fail_every = fail_every
        self.threads: set[str] = set()
        self.seqs: list[int] = []
        self.errors: list[BaseException] = []

    def on_block(self, stream: str, block: FrameBlock) -> None:
        self.threads.add(threading.current_thread().name)
        self.seqs.extend(int(s) for s in block.seq)
        if self.fail_every and len(self.seqs) % self.fail_every == 0:
            raise RuntimeError("sink bug")

    def on_error(self, stream: str, exc: BaseException) -> None:
        self.errors.append(exc)


def _run(devices: list[CountingDevice], sinks: list[ThreadSink]) -> Session:
    session = Session(devices, sinks, recv_timeout_s=0.01)
    session.start()
    for _ in range(2000):
        if all(d.sent >= d.n for d in devices):
            break
        threading.Event().wait(0.005)
    session.stop()
    return session


def test_inline_sink_runs_in_the_reader_and_queued_sink_in_its_dispatcher() -> None:
    inline, queued = ThreadSink("live", True), ThreadSink("mon", False)
    assert isinstance(inline, InlineSink)
    session = _run([CountingDevice("cam")], [inline, queued])
    assert inline.threads == {"spotlab-reader-cam"}
    assert queued.threads == {"spotlab-sink-mon"}
    assert inline.seqs == queued.seqs == list(range(50))
    stats = session.sink_stats()
    assert stats["live"].delivered == 50 and stats["live"].sink_errors == 0


def test_inline_sink_errors_are_counted_and_the_reader_goes_on() -> None:
    bad, good = ThreadSink("bad", True, fail_every=5), ThreadSink("good", True)
    device = CountingDevice("cam", n=40, fail_at=3)
    session = _run([device], [bad, good])
    assert good.seqs == bad.seqs == list(range(40))
    stats = session.sink_stats()
    assert stats["bad"].sink_errors == 8 and stats["bad"].delivered == 40
    # Every failure named and counted by kind (type and place), not only the first three.
    ((kind, n),) = stats["bad"].sink_failures.items()
    assert n == 8 and kind.startswith("RuntimeError at test_inline_sinks.py:"), kind
    assert stats["good"].sink_errors == 0 and stats["good"].sink_failures == {}
    assert [type(e) for e in good.errors] == [ProtocolError]
    assert stats["good"].errors_delivered == 1


def test_inline_sink_is_called_by_every_reader() -> None:
    sink = ThreadSink("live", True)
    _run([CountingDevice("a", n=20), CountingDevice("b", n=20)], [sink])
    assert sink.threads == {"spotlab-reader-a", "spotlab-reader-b"}
    assert sorted(sink.seqs) == sorted(list(range(20)) * 2)
    assert not any(t.name.startswith("spotlab-sink") for t in threading.enumerate())
