"""Session: reader and dispatcher threads, bounded per-sink queues, errors, shutdown."""

from __future__ import annotations

import threading
import time

import pytest
from acq_fakes import FakeDevice, ListSink

from spotlab.acquisition.session import (
    Device,
    Session,
    SessionStatus,
    Sink,
    SinkBase,
    default_is_fatal,
)
from spotlab.core.errors import (
    ConfigurationError,
    DeviceDisconnected,
    DeviceError,
    DeviceTimeout,
    ProtocolError,
)
from spotlab.core.frames import FrameBlock


def _spotlab_threads() -> list[str]:
    return [t.name for t in threading.enumerate() if t.name.startswith("spotlab-")]


def test_fakes_satisfy_the_protocols() -> None:
    assert isinstance(FakeDevice("a"), Device)
    assert isinstance(ListSink(), Sink)


def test_every_sink_gets_every_block_and_all_threads_are_joined() -> None:
    devices = [FakeDevice("cam"), FakeDevice("timer", period_s=0.005, frames_per_block=1)]
    sinks = [ListSink("a"), ListSink("b")]
    session = Session(devices, sinks)
    session.start()
    names = _spotlab_threads()
    assert {
        "spotlab-reader-cam",
        "spotlab-reader-timer",
        "spotlab-sink-a",
        "spotlab-sink-b",
    } <= set(names)
    time.sleep(0.2)
    session.stop()
    assert _spotlab_threads() == []
    frames = session.frames
    assert frames["cam"] > 10 and frames["timer"] > 5
    for sink in sinks:
        assert sink.frames == frames
        assert sink.stopped and sink.started_with == devices
    assert session.overflows == {"a": 0, "b": 0}
    assert all(not d.started for d in devices) and not any(d.closed for d in devices)
    session.stop()  # twice is fine


def test_slow_sink_overflows_are_counted_and_others_are_unaffected() -> None:
    device = FakeDevice("cam", period_s=0.001, frames_per_block=1)
    fast, slow = ListSink("fast"), ListSink("slow", delay_s=0.02)
    status = Session([device], [fast, slow], queue_size=4).run_for(0.3)
    total = status.frames["cam"]
    assert total > 50
    assert fast.frames == {"cam": total}
    stats = {name: s for name, s in status.overflows.items()}
    assert stats["fast"] == 0
    assert stats["slow"] > 0
    assert slow.blocks + stats["slow"] == total  # one frame per block: nothing unaccounted
    assert slow.blocks > 0 and slow.stopped
    assert _spotlab_threads() == []


def test_sink_stats_detail() -> None:
    device = FakeDevice("cam", period_s=0.001, frames_per_block=3)
    slow = ListSink("slow", delay_s=0.01)
    session = Session([device], [slow], queue_size=2)
    session.run_for(0.15)
    st = session.sink_stats()["slow"]
    assert st.overflows > 0 and st.dropped_frames == 3 * st.overflows
    assert st.delivered == slow.blocks and st.peak_queue == 2
    assert st.delivered + st.overflows == session.frames["cam"] // 3


def test_transient_device_errors_reach_sinks_and_reading_goes_on() -> None:
    glitch = ProtocolError("bad frame header")
    device = FakeDevice("cam", errors={3: glitch, 5: DeviceTimeout("late")})
    sink = ListSink("s")
    session = Session([device], [sink], recv_timeout_s=0.01)
    session.run_for(0.15)
    assert [e for _, e in sink.errors][:1] == [glitch]
    assert [(r.stream, r.fatal) for r in session.errors] == [("cam", False), ("cam", False)]
    assert device.calls > 10  # kept reading after the errors
    assert sink.frames["cam"] == session.frames["cam"] > 0


def test_fatal_error_ends_only_that_reader() -> None:
    bad = FakeDevice("bad", errors={2: DeviceError("refused")})
    good = FakeDevice("good")
    sink = ListSink("s")
    session = Session([bad, good], [sink])
    session.start()
    time.sleep(0.15)
    alive = session.status().readers_alive
    session.stop()
    assert alive == 1
    assert bad.calls == 3 and good.calls > 10
    assert [(r.stream, r.fatal) for r in session.errors] == [("bad", True)]
    assert isinstance(sink.errors[0][1], DeviceError)
    assert sink.frames["good"] == session.frames["good"]


def test_run_for_returns_early_when_every_reader_died() -> None:
    dead = FakeDevice("dead", errors={0: RuntimeError("bug")})
    t0 = time.monotonic()
    status = Session([dead], []).run_for(30.0, progress_interval_s=0.02)
    assert time.monotonic() - t0 < 5.0
    assert status.readers_alive == 0 and status.errors == 1


def test_default_fatality() -> None:
    assert not default_is_fatal(ProtocolError("x"))
    assert not default_is_fatal(DeviceTimeout("x"))
    assert not default_is_fatal(DeviceDisconnected("x"))
    assert default_is_fatal(DeviceError("x"))
    assert default_is_fatal(ValueError("x"))


def test_failing_sink_is_counted_and_does_not_stop_others() -> None:
    bad, good = ListSink("bad", fail=True), ListSink("good")
    session = Session([FakeDevice("cam")], [bad, good])
    session.run_for(0.1)
    stats = session.sink_stats()
    assert stats["bad"].sink_errors == stats["bad"].delivered > 0
    assert good.frames["cam"] == session.frames["cam"]


def test_start_failure_undoes_everything() -> None:
    ok = FakeDevice("ok")
    broken = FakeDevice("broken", start_error=DeviceError("no answer"))
    sink = ListSink("s")
    session = Session([ok, broken], [sink])
    with pytest.raises(DeviceError, match="no answer"):
        session.start()
    assert not ok.started and sink.stopped
    assert _spotlab_threads() == []


def test_run_for_reports_progress_and_context_manager() -> None:
    seen: list[SessionStatus] = []
    with Session([FakeDevice("cam")], [ListSink()]) as session:
        final = session.run_for(0.2, progress=seen.append, progress_interval_s=0.05)
    assert len(seen) >= 3 and seen[-1] is final
    assert final.target_s == 0.2 and final.elapsed_s >= 0.2
    assert seen[0].frames["cam"] <= final.frames["cam"]
    with pytest.raises(ConfigurationError, match="runs once"):
        session.start()


def test_close_devices_option() -> None:
    device = FakeDevice("cam")
    Session([device], [], close_devices=True).run_for(0.02)
    assert device.closed


def test_sink_names_are_made_unique() -> None:
    session = Session([FakeDevice("cam")], [ListSink(), ListSink(), ListSink("x")])
    assert list(session.overflows) == ["ListSink", "ListSink#2", "x"]
    session.stop()


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"devices": []}, "at least one device"),
        ({"devices": [FakeDevice("a"), FakeDevice("a")]}, "unique"),
        ({"devices": [FakeDevice("a")], "queue_size": 0}, "queue_size"),
    ],
)
def test_bad_configuration(kwargs: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigurationError, match=message):
        Session(**kwargs)  # type: ignore[arg-type]


def test_sink_base_defaults() -> None:
    class Counter(SinkBase):
        name = "counter"

        def __init__(self) -> None:
            self.n = 0

        def on_block(self, stream: str, block: FrameBlock) -> None:
            self.n += len(block)

    counter = Counter()
    session = Session([FakeDevice("cam", errors={1: ProtocolError("x")})], [counter])
    session.run_for(0.05)
    assert counter.n == session.frames["cam"]
