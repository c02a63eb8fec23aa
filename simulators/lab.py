"""The lab: simulators on one machine that see each other's frame pulses.

Every simulated device with a name in the lab publishes the schedule of its
frame pulses — its :class:`~spotlab.simulators.clock.DeviceClock` parameters
and, per stream, the oscillator time of ``START:``, the frame period and the
world time it stopped — as a JSON file ``<lab>/<name>.json``. The pulse of
frame ``k`` rises at the true world instant of the frame's first sample (the
``true_time_s`` of the device's truth CSV, trigger jitter included, via
:meth:`DeviceClock.jitter_for`) and falls ``pulse_width_s`` later. A timer
simulator whose input is wired to ``name`` computes those instants from the
file (:class:`PulseSource`) and captures them with its own clock.

The lab folder is ``--lab DIR``, else ``$SPOTLAB_LAB``, else
``<tempdir>/spotlab-lab-<uid>``. A file whose process is gone and whose stream
never stopped counts as stopped when the file was last written.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from spotlab.simulators.clock import DeviceClock

ENV = "SPOTLAB_LAB"


def lab_dir(path: str | os.PathLike[str] | None = None) -> Path:
    """The lab folder: ``path``, else ``$SPOTLAB_LAB``, else a per-user folder in the temp dir."""
    if path is not None:
        return Path(path)
    env = os.environ.get(ENV)
    if env:
        return Path(env)
    uid = os.getuid() if hasattr(os, "getuid") else 0
    return Path(tempfile.gettempdir()) / f"spotlab-lab-{uid}"


def frame_start(clock: DeviceClock, start_osc: float, period_s: float, k: int) -> tuple[int, float]:
    """Tick (whole device µs) and true oscillator time of frame ``k`` of a stream.

    Frame ``k`` is due at oscillator time ``start_osc + k * period_s``; it starts
    on the nearest whole µs of the device counter, so its true start moves by
    the rounding (the tick names it exactly, before trigger jitter).
    """
    nominal = start_osc + k * period_s
    dev_us = clock.device_us_at_osc(nominal)
    tick = round(dev_us)
    return tick, nominal + (tick - dev_us) * 1e-6


def clock_to_dict(clock: DeviceClock) -> dict[str, Any]:
    """The parameters that rebuild ``clock`` (:func:`clock_from_dict`)."""
    return {
        "offset_s": clock.offset_s,
        "drift_ppm": clock.drift_ppm,
        "jitter_s": clock.jitter_s,
        "steps": [list(s) for s in clock.steps],
        "seed": clock.seed,
        "epoch_ns": clock.epoch_ns,
    }


def clock_from_dict(d: dict[str, Any]) -> DeviceClock:
    """Inverse of :func:`clock_to_dict`."""
    return DeviceClock(
        offset_s=float(d["offset_s"]),
        drift_ppm=float(d["drift_ppm"]),
        jitter_s=float(d["jitter_s"]),
        steps=[(float(a), float(b)) for a, b in d["steps"]],
        seed=int(d["seed"]),
        epoch_ns=int(d["epoch_ns"]),
    )


class LabPublisher:
    """Publishes one device's frame-pulse schedule to the lab folder.

    Parameters
    ----------
    directory : Path
        The lab folder (created if needed).
    name : str
        The device's name in the lab (file ``<name>.json``; a later device of
        the same name replaces it).
    clock : DeviceClock
        The device's clock.
    pulse_width_s : float
        Width of each frame pulse.
    """

    def __init__(
        self, directory: str | os.PathLike[str], name: str, clock: DeviceClock, pulse_width_s: float
    ) -> None:
        if not name or "/" in name or name.startswith("."):
            raise ValueError(f"a lab name must be a plain file name, got {name!r}")
        self.path = Path(directory) / f"{name}.json"
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._doc: dict[str, Any] = {
            "name": name,
            "pid": os.getpid(),
            "clock": clock_to_dict(clock),
            "pulse_width_s": pulse_width_s,
            "streams": [],
        }
        self._write()

    def started(self, index: int, start_ns: int, start_osc: float, period_s: float) -> None:
        """A stream started at world ``start_ns``: frame ``k`` due at ``start_osc + k period``."""
        self._doc["streams"].append(
            {
                "index": index,
                "start_ns": start_ns,
                "start_osc": start_osc,
                "period_s": period_s,
                "stop_ns": None,
            }
        )
        self._write()

    def stopped(self, stop_ns: int) -> None:
        """The running stream (if any) stopped at world ``stop_ns``."""
        streams = self._doc["streams"]
        if streams and streams[-1]["stop_ns"] is None:
            streams[-1]["stop_ns"] = stop_ns
            self._write()

    def _write(self) -> None:
        self._doc["written_ns"] = time.monotonic_ns()
        tmp = self.path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(json.dumps(self._doc), encoding="utf-8")
        os.replace(tmp, self.path)


@dataclass(frozen=True)
class Pulse:
    """One frame pulse edge of a source: world ns (float), polarity, stream and frame number."""

    world_ns: float
    rising: bool
    stream: int
    frame_no: int


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class PulseSource:
    """The frame pulses of one published device, read from the lab folder.

    Parameters
    ----------
    directory : Path
        The lab folder.
    name : str
        The device's lab name.
    min_reload_s : float
        The file is read again at most this often (when it changed).
    """

    def __init__(self, directory: str | os.PathLike[str], name: str, min_reload_s: float = 0.02):
        self.path = Path(directory) / f"{name}.json"
        self.name = name
        self.min_reload_s = min_reload_s
        self._mtime: int | None = None
        self._checked = -math.inf
        self.clock: DeviceClock | None = None
        self.width_ns = 0.0
        self.streams: list[dict[str, Any]] = []

    def refresh(self) -> None:
        """Read the file again if it changed (at most every ``min_reload_s``)."""
        now = time.monotonic()
        if now - self._checked < self.min_reload_s:
            return
        self._checked = now
        try:
            mtime = self.path.stat().st_mtime_ns
        except FileNotFoundError:
            return
        if mtime == self._mtime:
            return
        with contextlib.suppress(OSError, ValueError, KeyError):
            doc = json.loads(self.path.read_text(encoding="utf-8"))
            self.clock = clock_from_dict(doc["clock"])
            self.width_ns = float(doc["pulse_width_s"]) * 1e9
            streams = doc["streams"]
            if not _alive(int(doc["pid"])):
                for s in streams:
                    if s["stop_ns"] is None:
                        s["stop_ns"] = int(doc["written_ns"])
            self.streams = streams
            self._mtime = mtime

    def pulses(self, stream: dict[str, Any], w0: float, w1: float) -> list[Pulse]:
        """Pulse edges of ``stream`` with world time in ``(w0, w1]`` (and before its stop)."""
        clock = self.clock
        if clock is None:
            return []
        stop = stream["stop_ns"]
        hi_w = w1 if stop is None else min(w1, float(stop))
        if hi_w <= w0:
            return []
        period, start_osc = float(stream["period_s"]), float(stream["start_osc"])
        margin = 2 + (clock.jitter_s * 10 + self.width_ns * 1e-9) / period
        k0 = max(0, math.floor((clock.osc_s(w0) - start_osc) / period - margin))
        k1 = math.ceil((clock.osc_s(hi_w) - start_osc) / period + margin)
        out = []
        for k in range(k0, k1 + 1):
            _, osc0 = frame_start(clock, start_osc, period, k)
            rise = float(clock.world_ns(osc0)) + clock.jitter_for(int(stream["index"]), k) * 1e9
            if stop is not None and rise >= stop:
                break
            for w, rising in ((rise, True), (rise + self.width_ns, False)):
                if w0 < w <= hi_w:
                    out.append(Pulse(w, rising, int(stream["index"]), k))
        return out
