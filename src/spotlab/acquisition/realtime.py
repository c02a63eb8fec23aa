"""Real-time scheduling of a session's threads (Linux ``SCHED_FIFO``), where allowed.

A session's readers wait in the kernel for a device's bytes and must run as soon as
they come. Under the normal policy (``SCHED_OTHER``) a reader that wakes competes for a
core with everything else on the machine: a browser drawing the console's 3-D view, a
compiler, another program keeping a core busy. Nice values do not help across programs
started from different sessions (the kernel's autogroups share the processor between
sessions first), so the tail of the live latency then follows the machine's load.

``SCHED_FIFO`` threads run before every normal thread whatever its group or nice value,
for as long as they do not block. A session's threads block almost all the time (in
``recv`` or on their queue), so raising them costs the rest of the machine only the
work they do. The policy is asked per thread, by the thread itself, with
``SCHED_RESET_ON_FORK``: no process or thread it starts inherits it (Linux resets every
new task, threads included). It needs root or
``CAP_SYS_NICE`` (or an ``RLIMIT_RTPRIO`` of at least the priority, e.g. the
``rtprio`` line of ``/etc/security/limits.conf``); where the system refuses, the thread
goes on at the normal policy and the refusal is reported once.

Python's interpreter lock is held by one thread at a time: a normal thread of the same
process holding it while other programs preempt it delays the raised ones (priority
inversion). :func:`raise_thread` is therefore also offered for a program's own busy
threads beside a session (``spotlab console --realtime`` raises its main thread, where
the web server runs).
"""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Callable

from spotlab.core.errors import ConfigurationError

__all__ = [
    "MAX_PRIORITY",
    "check_priority",
    "current_policy",
    "probe",
    "raise_thread",
    "runs_raised",
]

#: Highest ``SCHED_FIFO`` priority Linux takes (1 is the lowest).
MAX_PRIORITY = 99


def check_priority(priority: int | None) -> int | None:
    """``priority`` if it is None or a ``SCHED_FIFO`` priority (1-99).

    Raises
    ------
    ConfigurationError
        If it is outside 1-99.
    """
    if priority is None:
        return None
    if isinstance(priority, bool) or not isinstance(priority, int):
        raise ConfigurationError(f"a real-time priority is an integer 1-99, got {priority!r}")
    if not 1 <= priority <= MAX_PRIORITY:
        raise ConfigurationError(f"a real-time priority is 1-{MAX_PRIORITY}, got {priority}")
    return priority


def raise_thread(priority: int) -> str | None:
    """Put the calling thread under ``SCHED_FIFO`` at ``priority``.

    Parameters
    ----------
    priority : int
        1-99 (see :func:`check_priority`).

    Returns
    -------
    str or None
        None if it took; otherwise why not, in words (the thread is left as it was).
    """
    check_priority(priority)
    if not sys.platform.startswith("linux") or not hasattr(os, "SCHED_FIFO"):
        return f"real-time scheduling is not available on {sys.platform}"
    try:
        # pid 0: the calling thread (Linux applies the policy per thread)
        os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, os.sched_param(priority))
    except PermissionError:
        return (
            f"SCHED_FIFO priority {priority} refused: it needs root, CAP_SYS_NICE or an "
            f"RLIMIT_RTPRIO of at least {priority} (limits.conf 'rtprio')"
        )
    except OSError as exc:
        return f"SCHED_FIFO priority {priority} refused: {exc.strerror or exc}"
    return None


def probe(priority: int) -> str | None:
    """Whether threads may have ``SCHED_FIFO`` at ``priority``: a short-lived thread
    asks for it (the caller's own thread is left as it is).

    Returns
    -------
    str or None
        None if the system allows it; otherwise why not, in words.
    """
    check_priority(priority)
    answer: list[str | None] = []
    thread = threading.Thread(
        target=lambda: answer.append(raise_thread(priority)), name="spotlab-rt-probe"
    )
    thread.start()
    thread.join()
    return answer[0] if answer else "the probe thread did not answer"


def current_policy() -> tuple[str, int]:
    """The calling thread's policy name (``"fifo"``, ``"rr"``, ``"other"``, ...) and
    priority."""
    if not hasattr(os, "sched_getscheduler"):
        return "other", 0
    policy = os.sched_getscheduler(0) & ~getattr(os, "SCHED_RESET_ON_FORK", 0)
    names = {
        getattr(os, "SCHED_FIFO", -1): "fifo",
        getattr(os, "SCHED_RR", -1): "rr",
        getattr(os, "SCHED_OTHER", -1): "other",
        getattr(os, "SCHED_BATCH", -1): "batch",
        getattr(os, "SCHED_IDLE", -1): "idle",
    }
    return names.get(policy, str(policy)), os.sched_getparam(0).sched_priority


def runs_raised(
    target: Callable[..., None], priority: int | None, refused: Callable[[str], None]
) -> Callable[..., None]:
    """``target`` wrapped so that its thread first asks for ``SCHED_FIFO`` at ``priority``.

    Parameters
    ----------
    target : callable
        A thread's function.
    priority : int or None
        1-99; None returns ``target`` itself.
    refused : callable
        Called with the reason when the system refuses (the thread runs on regardless).
    """
    if priority is None:
        return target

    def run(*args: object) -> None:
        why = raise_thread(priority)
        if why is not None:
            refused(why)
        target(*args)

    return run
