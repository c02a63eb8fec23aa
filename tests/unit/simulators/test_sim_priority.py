"""Serving threads take SPOTLAB_SIM_NICE where the system allows (simulators/priority.py)."""

from __future__ import annotations

import os
import threading

import pytest

from spotlab.simulators.priority import ENV, raise_serving_priority


def _in_thread() -> tuple[bool, int]:
    out: list[tuple[bool, int]] = []

    def run() -> None:
        took = raise_serving_priority()
        out.append((took, os.getpriority(os.PRIO_PROCESS, threading.get_native_id())))

    t = threading.Thread(target=run)
    t.start()
    t.join()
    return out[0]


def test_a_serving_thread_takes_the_nice_value_and_the_process_keeps_its_own(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    before = os.getpriority(os.PRIO_PROCESS, 0)
    wanted = before + 3  # raising a nice value needs no privilege
    monkeypatch.setenv(ENV, str(wanted))
    assert _in_thread() == (True, wanted)
    assert os.getpriority(os.PRIO_PROCESS, 0) == before


@pytest.mark.parametrize("value", ["", "soon", " "])
def test_unset_or_malformed_leaves_the_thread_as_it_is(
    monkeypatch: pytest.MonkeyPatch, value: str
) -> None:
    monkeypatch.setenv(ENV, value)
    before = os.getpriority(os.PRIO_PROCESS, 0)
    assert _in_thread() == (False, before)
