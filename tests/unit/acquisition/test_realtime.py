"""Session's real-time option: SCHED_FIFO for its threads where allowed, told where not."""

from __future__ import annotations

import os
import threading
import time

import pytest
from acq_fakes import FakeDevice, ListSink

from spotlab.acquisition.interfaces import SinkBase
from spotlab.acquisition.realtime import check_priority, current_policy, probe, raise_thread
from spotlab.acquisition.session import Session
from spotlab.core.errors import ConfigurationError
from spotlab.core.frames import FrameBlock


class PolicySink(SinkBase):
    """An inline sink noting the policy of the thread that calls it."""

    inline = True
    name = "policy"

    def __init__(self) -> None:
        self.policies: set[tuple[str, int]] = set()

    def on_block(self, stream: str, block: FrameBlock) -> None:
        self.policies.add(current_policy())


class QueuedPolicySink(ListSink):
    """A queued sink noting the policy of its dispatcher thread."""

    def __init__(self) -> None:
        super().__init__("queued")
        self.policies: set[tuple[str, int]] = set()

    def on_block(self, stream: str, block: FrameBlock) -> None:
        self.policies.add(current_policy())
        super().on_block(stream, block)


def _allowed() -> bool:
    return probe(3) is None


@pytest.mark.parametrize("bad", [0, 100, -1, 2.5, True])
def test_priorities_outside_1_to_99_are_refused(bad: object) -> None:
    with pytest.raises(ConfigurationError, match="priority"):
        check_priority(bad)  # type: ignore[arg-type]
    with pytest.raises(ConfigurationError, match="priority"):
        Session([FakeDevice("a")], realtime_priority=bad)  # type: ignore[arg-type]


def test_readers_and_dispatchers_run_under_sched_fifo_and_the_caller_does_not() -> None:
    inline, queued = PolicySink(), QueuedPolicySink()
    before = current_policy()
    session = Session([FakeDevice("cam")], [inline, queued], realtime_priority=7)
    session.start()
    time.sleep(0.15)
    session.stop()
    assert current_policy() == before  # the probe and the threads leave the caller alone
    if _allowed():
        assert session.realtime_refused is None
        assert inline.policies == {("fifo", 7)}
        assert queued.policies == {("fifo", 7)}
    else:  # an unprivileged machine: said once, in words, and the session still ran
        assert session.realtime_refused is not None
        assert "SCHED_FIFO priority 7 refused" in session.realtime_refused
        assert inline.policies == {before} and queued.frames["cam"] > 0


def test_without_the_option_threads_keep_the_normal_policy() -> None:
    inline = PolicySink()
    session = Session([FakeDevice("cam")], [inline])
    session.start()
    time.sleep(0.1)
    session.stop()
    assert session.realtime_refused is None
    assert {p for p, _ in inline.policies} == {"other"}


def test_a_refusal_is_a_reason_in_words_and_leaves_the_thread_as_it_was() -> None:
    # Judged unprivileged: as root, in a child process that first becomes "nobody" (no
    # CAP_SYS_NICE, and an RLIMIT_RTPRIO of 0 unless the machine raised it).
    if os.geteuid() != 0:
        why = raise_thread(5)
        assert why is not None and "RLIMIT_RTPRIO" in why
        assert current_policy()[0] == "other"
        return
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        try:
            try:
                os.setgid(65534)
                os.setuid(65534)  # nobody: no CAP_SYS_NICE; RLIMIT_RTPRIO is 0 by default
            except OSError:
                os.write(write, b"S")  # a root without the right to change user
                os._exit(0)
            why = raise_thread(5) or ""
            ok = "refused" in why and current_policy()[0] == "other"
            os.write(write, b"1" if ok else why.encode() or b"0")
        finally:
            os._exit(0)
    os.close(write)
    os.waitpid(pid, 0)
    answer = os.read(read, 4096)
    os.close(read)
    if answer == b"S":
        pytest.skip("this root cannot become another user to be judged unprivileged")
    assert answer == b"1", answer


def test_the_probe_runs_in_a_thread_of_its_own() -> None:
    before = threading.active_count()
    probe(2)
    names = [t.name for t in threading.enumerate()]
    assert "spotlab-rt-probe" not in names and threading.active_count() == before


def test_a_thread_started_from_a_raised_one_runs_at_the_normal_policy() -> None:
    """SCHED_RESET_ON_FORK resets every new task, threads too: a session raises each of
    its threads itself, and heavy work started from a raised thread is not raised."""
    if not _allowed():
        assert raise_thread(4) is not None
        return
    seen: list[tuple[str, int]] = []

    def raised() -> None:
        assert raise_thread(4) is None
        seen.append(current_policy())
        child = threading.Thread(target=lambda: seen.append(current_policy()))
        child.start()
        child.join()

    parent = threading.Thread(target=raised)
    parent.start()
    parent.join()
    assert seen == [("fifo", 4), ("other", 0)]
