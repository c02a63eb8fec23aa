"""Scheduling priority of a simulator's serving thread.

A simulator stands in for a device, and a device has its own processor: a busy host
delays the host's reading, never the device's frames. A simulator runs on the host's
cores, so a busy machine (a test suite on two cores, a benchmark beside it) can starve
its serving thread, and its device clock then falls behind the wall's: frames come late
and in bursts, which no real device does. ``SPOTLAB_SIM_NICE`` (an integer, e.g.
``-10``) asks for that nice value for every serving thread (per thread on Linux; a
negative value needs root or CAP_SYS_NICE). Unset, or where the system refuses, the
thread keeps the process's priority; the simulator works the same, only more starved
under load. The test suite sets it (tests/conftest.py).
"""

from __future__ import annotations

import contextlib
import os
import threading

__all__ = ["ENV", "raise_serving_priority"]

#: Environment variable with the nice value of serving threads.
ENV = "SPOTLAB_SIM_NICE"


def raise_serving_priority() -> bool:
    """Give the calling thread the nice value of ``SPOTLAB_SIM_NICE``; whether it took.

    Call it first thing in a serving thread. A missing or malformed value, or a system
    that refuses (no permission, no per-thread priority), leaves the thread as it is.
    """
    raw = os.environ.get(ENV, "").strip()
    if not raw:
        return False
    try:
        nice = int(raw)
    except ValueError:
        return False
    with contextlib.suppress(OSError, AttributeError):
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), nice)
        return True
    return False
