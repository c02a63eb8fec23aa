"""Disruptive steps: how long a device takes to stream again after a reset or a pulled cable.

Each step streams the device on its own (a fresh driver), disrupts it and reads on
until frames come again after the outage:

* **reset** (MCS-1 families): ``RESET:`` sent while streaming (a BREAK cannot
  cross a pty or TCP); the device drops to 9600 baud and its banner, and the
  driver must find it and restart the stream by itself;
* **cable**: a ``sim://`` port gets the simulator's own ``disconnect`` fault
  (the link down for :data:`CABLE_OUTAGE_S`, 1 s after ``START:``); a Qualisys
  server is reached through a :class:`~spotlab.testing.tcp_cut.CuttableRelay`
  that drops the connection; on any other port a person pulls the cable when asked.

``recovery_s`` is the time from the end of the disruption (the reset sent, the
link back) to the first frame after the gap it made.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from spotlab.core.errors import DeviceError
from spotlab.drivers.base import Driver

#: Seconds the simulated cable stays pulled.
CABLE_OUTAGE_S = 0.5
#: Seconds after ``START:`` the simulated cable is pulled.
CABLE_AT_S = 1.0
#: Seconds to wait for frames after a disruption before calling it a failure.
RECOVERY_TIMEOUT_S = 15.0
MCS1_FAMILIES = ("selspot", "timer", "centroid")
DEFAULT_TCP_PORTS = {"qualisys": 22223}

#: ``(family, port) -> driver`` (not started).
DriverFactory = Callable[[str], Driver]
#: Asks a person a yes/no question.
Confirm = Callable[[str], bool]


@dataclass
class StepResult:
    """One disruptive step.

    Attributes
    ----------
    step : str
        ``"reset"`` or ``"cable"``.
    status : str
        ``"recovered"``, ``"failed"`` or ``"skipped"``.
    recovery_s : float or None
        Seconds from the end of the disruption to the first frame after it.
    gap_s : float or None
        Longest gap between frames after the disruption began, s.
    reason : str
        Why it failed or was skipped.
    counters : dict
        The driver's link counters at the end.
    """

    step: str
    status: str
    recovery_s: float | None = None
    gap_s: float | None = None
    reason: str = ""
    counters: dict[str, int] | None = None


def _counters(driver: Driver) -> dict[str, int]:
    keys = ("frames", "lost_frames", "crc_errors", "resyncs", "reconnects")
    return {k: int(getattr(driver.stats, k)) for k in keys}


def _stream_until(
    driver: Driver, deadline: float, arrivals: list[int], after_ns: int | None = None
) -> None:
    """Read frames until ``deadline`` (monotonic s), appending their arrival stamps;
    with ``after_ns``, stop early once frames have flowed for 0.5 s after that time and
    after a gap."""
    period_ns = 1e9 / driver.spec.rate_hz
    while time.monotonic() < deadline:
        try:
            block = driver.recv(timeout=0.2)
        except DeviceError:
            continue  # the driver reconnects by itself; a lost read is part of the outage
        if block is not None and len(block):
            arrivals.extend(int(t) for t in block.arrival_ns)
        if after_ns is not None and _resumed(arrivals, after_ns, period_ns):
            return


def _resumed(arrivals: list[int], after_ns: int, period_ns: float) -> bool:
    """Whether frames came for 0.5 s after a gap of 5 periods that ended after ``after_ns``."""
    for i in range(len(arrivals) - 1, 0, -1):
        if arrivals[i] <= after_ns:
            return False
        if arrivals[i] - arrivals[i - 1] > 5 * period_ns:
            return arrivals[-1] - arrivals[i] >= 5e8
    return False


def _outcome(
    step: str, driver: Driver, arrivals: list[int], end_ns: int, period_s: float, timed: bool = True
) -> StepResult:
    """Recovery figures from the arrivals and the end of the disruption (host ns);
    ``timed``: whether ``end_ns`` is known (else only the gap is given)."""
    after = [t for t in arrivals if t > end_ns]
    gaps = [(b - a) / 1e9 for a, b in itertools.pairwise(arrivals)]
    gap = max(gaps, default=None)
    if not after:
        return StepResult(
            step, "failed", None, gap, "no frame after the disruption", _counters(driver)
        )
    if gap is None or gap < 5 * period_s:
        return StepResult(
            step, "failed", None, gap, "no gap in the frames: the disruption did not happen",
            _counters(driver),
        )  # fmt: skip
    # Frames still queued when the disruption began may arrive after it: recovery is
    # the end of the longest gap that ends after the disruption.
    ends = [i + 1 for i in range(len(arrivals) - 1) if arrivals[i + 1] > end_ns]
    first = arrivals[max(ends, key=lambda i: arrivals[i] - arrivals[i - 1])] if ends else after[0]
    recovery = round((first - end_ns) / 1e9, 3) if timed else None
    return StepResult(step, "recovered", recovery, round(gap, 3), "", _counters(driver))


def reset_step(make: DriverFactory, port: str) -> StepResult:
    """``RESET:`` while streaming; the time until frames come again."""
    driver = make(port)
    if not hasattr(driver, "command"):
        return StepResult("reset", "skipped", reason=f"{driver.family} has no reset command")
    arrivals: list[int] = []
    try:
        driver.start()
        _stream_until(driver, time.monotonic() + 1.0, arrivals)
        sent_ns = time.monotonic_ns()
        try:
            driver.command("RESET")
        except DeviceError:
            pass  # no reply: the device reset
        _stream_until(driver, time.monotonic() + RECOVERY_TIMEOUT_S, arrivals, sent_ns)
        return _outcome("reset", driver, arrivals, sent_ns, 1.0 / driver.spec.rate_hz)
    finally:
        driver.close()


def _with_fault(url: str, fault: str) -> str:
    base, sep, query = url.partition("?")
    items = [item for item in query.split("&") if item] if sep else []
    for i, item in enumerate(items):
        if item.startswith("faults="):
            items[i] = f"{item},{fault}"
            break
    else:
        items.append(f"faults={fault}")
    return base + "?" + "&".join(items)


def cable_step(family: str, make: DriverFactory, port: str, confirm: Confirm | None) -> StepResult:
    """The cable pulled and put back; the time until frames come again.

    ``confirm`` asks a person to pull the cable of a real port (None: skipped there).
    """
    relay: Any = None
    if port.startswith("sim://"):
        target = _with_fault(port, f"disconnect@{CABLE_AT_S:g}:{CABLE_OUTAGE_S:g}")
    elif family in DEFAULT_TCP_PORTS:
        from spotlab.testing.tcp_cut import CuttableRelay

        host, sep, number = port.rpartition(":")
        if not sep or not number.isdigit():
            host, number = port, str(DEFAULT_TCP_PORTS[family])
        relay = CuttableRelay(host, int(number)).start()
        target = relay.address
    elif family in MCS1_FAMILIES and confirm is not None:
        target = port
    else:
        why = "cannot pull a cable of this port by itself"
        return StepResult("cable", "skipped", reason=f"{why}; run without --yes to do it by hand")
    driver = make(target)
    arrivals: list[int] = []
    try:
        driver.start()
        started = time.monotonic()
        if target is port:  # a person pulls it
            assert confirm is not None
            _stream_until(driver, started + 0.5, arrivals)
            if not confirm(f"pull the cable of {port} now and plug it back within 10 s"):
                return StepResult("cable", "skipped", reason="not confirmed")
            asked_ns = time.monotonic_ns()
            _stream_until(driver, time.monotonic() + 10.0 + RECOVERY_TIMEOUT_S, arrivals, asked_ns)
            rate = driver.spec.rate_hz
            return _outcome("cable", driver, arrivals, asked_ns, 1.0 / rate, timed=False)
        elif relay is not None:
            _stream_until(driver, started + CABLE_AT_S, arrivals)
            relay.cut(refuse_s=CABLE_OUTAGE_S)
            end_ns = time.monotonic_ns() + int(CABLE_OUTAGE_S * 1e9)
        else:
            end_ns = time.monotonic_ns() + int((CABLE_AT_S + CABLE_OUTAGE_S) * 1e9)
        _stream_until(driver, time.monotonic() + RECOVERY_TIMEOUT_S, arrivals, end_ns)
        return _outcome("cable", driver, arrivals, end_ns, 1.0 / driver.spec.rate_hz)
    finally:
        driver.close()
        if relay is not None:
            relay.stop()


__all__ = ["CABLE_OUTAGE_S", "StepResult", "cable_step", "reset_step"]
