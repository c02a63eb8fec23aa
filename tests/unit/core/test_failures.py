"""Failures counted by kind: every one counted, the first of each kind reported."""

from __future__ import annotations

from spotlab.core.failures import FailureTally, failure_kind


def _raise(kind: type[Exception]) -> Exception:
    try:
        raise kind("boom")
    except Exception as exc:
        return exc


def test_every_failure_is_counted_under_its_kind() -> None:
    tally = FailureTally()
    firsts = [tally.add(_raise(ValueError)) for _ in range(5)]
    firsts.append(tally.add(_raise(KeyError)))
    assert firsts == [True, False, False, False, False, True]
    assert tally.total == 6 and len(tally.counts) == 2
    assert tally.snapshot()[failure_kind(_raise(ValueError))] == 5
    assert failure_kind(ValueError("never raised")) == "ValueError"
