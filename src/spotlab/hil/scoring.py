"""A scenario's figures, from the recording, its processing and the simulators' truth.

Nothing here runs while recording: the truth files and fault logs are read after
the simulators have stopped. Per device (docs/hil.md): the recording's counts
(:func:`spotlab.acquisition.summary.summarize`, what ``spotlab info`` prints), the
frames the simulator sent and the faults it injected (its fault log), and
``frames_missing``, frames the device sent intact that the recording lacks. For the
run: the largest error of the session times against the true instants after one
affine map shared by all streams (``sync_error_us``), and the 3-D error of a
reconstruction against the true marker positions (``error_3d_rms_mm``).
"""

from __future__ import annotations

import csv
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from spotlab.acquisition.replay import replay
from spotlab.acquisition.summary import summarize
from spotlab.processing.decoding import decoder_for
from spotlab.processing.session_times import recording_timebase, write_timestamps
from spotlab.processing.trajectories import reconstruct_file, write_trial
from spotlab.simulators.truth import read_truth_positions

F64 = npt.NDArray[np.float64]
#: Seconds at the start of a stream whose frames are not in the latency figures.
STARTUP_S = 1.0
#: The share of a stream's span whose latency is its start (and its end) figure.
DRIFT_WINDOW = 0.1
#: Windows of the latency timeline (``latency.csv``).
TIMELINE_WINDOWS = 60
_COUNTS = ("frames", "lost_frames", "crc_errors", "resyncs", "duplicates", "gaps", "reconnects")


def _fault_log(path: Path | None) -> dict[str, Any] | None:
    if path is None or not path.is_file():
        return None
    data: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    return data


def device_figures(
    journal: Path, fault_logs: Mapping[str, Path | None]
) -> dict[str, dict[str, float | None]]:
    """Per stream: the recording's counts, and what the simulator says it sent.

    ``frames_missing`` is the frames the device sent and a host should have decoded
    (sent, less those it damaged, lost in a disconnection or discarded at a reset)
    that the recording does not hold; None without a fault log.
    """
    summary = summarize(journal, decoder_for)
    out: dict[str, dict[str, float | None]] = {}
    for stream in summary.streams:
        figures: dict[str, float | None] = {k: float(getattr(stream, k)) for k in _COUNTS}
        figures["rate_hz"] = float(stream.rate_hz)
        figures.update(frames_sent=None, frames_missing=None, faults_injected=None)
        log = _fault_log(fault_logs.get(stream.name))
        if log is not None:
            totals = log.get("totals", {})
            sent = float(totals.get("frames_sent", 0))
            unusable = sum(float(totals.get(k, 0)) for k in
                           ("corrupted_frames", "lost_frames", "discarded_frames"))  # fmt: skip
            figures["frames_sent"] = sent
            figures["frames_missing"] = max(0.0, sent - unusable - float(stream.frames))
            figures["faults_injected"] = float(len(log.get("faults", [])))
        out[stream.name] = figures
    return out


def frame_latency(
    journal: Path, truths: Mapping[str, tuple[str, Path]], timeline: Path | None = None
) -> dict[str, Any]:
    """Age of every frame when the host read its last byte: its arrival stamp in the
    recording minus the true instant of its first sample (both on the host's monotonic
    clock, which every process shares), p50 / p99 / max in ms per stream.

    It holds the device's exposure and readout, the frame's time on the line and the
    host's read; not the decoding after it (``spotlab bench`` measures that). The
    frames of a stream's first :data:`STARTUP_S` are left out: the recorder starts its
    devices one after the other, and the first device's first frames wait in its port
    while the others start (``startup_backlog_ms``: the oldest of them).

    Whether it stays flat: ``latency_p50_start_ms`` / ``latency_p99_start_ms`` over the
    first tenth of the steady frames' span, ``..._end_ms`` over the last tenth, and
    ``latency_p50_growth_ms``; with ``timeline``, a CSV of the latency in
    :data:`TIMELINE_WINDOWS` windows of time per stream.
    """
    rows: list[list[str]] = []
    seqs: dict[str, list[Any]] = {}
    ticks: dict[str, list[Any]] = {}
    arrivals: dict[str, list[Any]] = {}
    for stream, block in replay(journal, decoder_for):
        if stream not in truths or not len(block):
            continue
        seqs.setdefault(stream, []).append(np.asarray(block.seq))
        ticks.setdefault(stream, []).append(np.asarray(block.ticks))
        arrivals.setdefault(stream, []).append(np.asarray(block.arrival_ns))
    out: dict[str, Any] = {}
    for stream, (family, truth) in truths.items():
        if stream not in seqs:
            continue
        seq = np.concatenate(seqs[stream]).astype(np.int64)
        tick = np.concatenate(ticks[stream]).astype(np.int64)
        arrival = np.concatenate(arrivals[stream]).astype(np.float64) / 1e9
        age_ms = (arrival - _true_times(truth, family, seq.tolist(), tick.tolist())) * 1e3
        early = arrival - arrival[0] < STARTUP_S
        ok = np.isfinite(age_ms)
        steady = age_ms[ok & ~early]
        figures: dict[str, float | None] = {
            "startup_backlog_ms": round(float(age_ms[ok & early].max()), 3)
            if (ok & early).any()
            else None
        }
        if steady.size:
            p50, p99 = np.percentile(steady, [50.0, 99.0])
            figures.update(latency_p50_ms=round(float(p50), 3),
                           latency_p99_ms=round(float(p99), 3),
                           latency_max_ms=round(float(steady.max()), 3))  # fmt: skip
            figures.update(_latency_drift(arrival[ok & ~early], steady))
            if timeline is not None:
                rows += _latency_windows(stream, arrival[ok & ~early] - arrival[0], steady)
        out[stream] = figures
    if timeline is not None:
        _write_rows(timeline, rows)
    return out


def _latency_drift(arrival_s: F64, age_ms: F64) -> dict[str, float]:
    """Latency at the start and at the end of a stream's steady frames: p50 and p99 of the
    first and of the last :data:`DRIFT_WINDOW` of their span (at least 1 s), and the p50's
    growth between them (whether latency stays flat over a long run)."""
    span = float(arrival_s[-1] - arrival_s[0])
    window = max(1.0, DRIFT_WINDOW * span)
    first = age_ms[arrival_s <= arrival_s[0] + window]
    last = age_ms[arrival_s >= arrival_s[-1] - window]
    s50, s99 = np.percentile(first, [50.0, 99.0])
    e50, e99 = np.percentile(last, [50.0, 99.0])
    return {
        "latency_p50_start_ms": round(float(s50), 3),
        "latency_p99_start_ms": round(float(s99), 3),
        "latency_p50_end_ms": round(float(e50), 3),
        "latency_p99_end_ms": round(float(e99), 3),
        "latency_p50_growth_ms": round(float(e50 - s50), 3),
    }


def _latency_windows(stream: str, t_s: F64, age_ms: F64) -> list[list[str]]:
    """p50 / p99 / max of a stream's latency in :data:`TIMELINE_WINDOWS` windows of time."""
    edges = np.linspace(float(t_s[0]), float(t_s[-1]), TIMELINE_WINDOWS + 1)
    which = np.clip(np.searchsorted(edges, t_s, side="right") - 1, 0, TIMELINE_WINDOWS - 1)
    rows = []
    for k in range(TIMELINE_WINDOWS):
        ages = age_ms[which == k]
        if ages.size:
            p50, p99 = np.percentile(ages, [50.0, 99.0])
            rows.append([stream, f"{edges[k]:.1f}", str(ages.size), f"{p50:.3f}", f"{p99:.3f}",
                         f"{ages.max():.3f}"])  # fmt: skip
    return rows


def _write_rows(path: Path, rows: list[list[str]]) -> None:
    with open(path, "w", newline="", encoding="utf-8") as fh:
        out = csv.writer(fh)
        out.writerow(["stream", "from_s", "frames", "latency_p50_ms", "latency_p99_ms",
                      "latency_max_ms"])  # fmt: skip
        out.writerows(rows)


def _true_times(truth: Path, family: str, seq: Sequence[int], ticks: Sequence[int]) -> F64:
    """True instant of each frame, matched by its 16-bit seq and 32-bit device tick (the
    timer's truth counts µs where its frames count 100 ns)."""
    div = 10 if family == "timer" else 1
    with open(truth, newline="") as fh:
        table = {
            (int(r["seq"]), int(r["device_tick"]) % 2**32): float(r["true_time_s"])
            for r in csv.DictReader(fh)
            if r.get("sent") == "1"
        }
    return np.array(
        [table.get((s % 65536, t // div % 2**32), np.nan) for s, t in zip(seq, ticks, strict=True)]
    )


def sync_error(
    journal: Path, truths: Mapping[str, tuple[str, Path]], wiring: Mapping[str, int], out: Path
) -> dict[str, Any]:
    """Session times of the recording (written to ``out`` as ``export --timestamps``
    does) against the truth: the largest residual after one affine map of all streams
    (``sync_error_us``), and the same of the frames timed by the timer's edges alone
    (``sync_error_timed_us``: not those extrapolated after the timer stopped).

    Parameters
    ----------
    truths : mapping
        Stream name -> (family, truth CSV) of the streams to score.
    """
    timebase = recording_timebase(journal, wiring)
    rows = write_timestamps(out, timebase)
    found: dict[str, Any] = {"timestamps": str(out), "rows": rows, "notes": list(timebase.notes)}
    for key, methods in (("", None), ("_timed", ("edge", "reference"))):
        t_all, s_all, who = [], [], []
        for name, timing in timebase.streams.items():
            if name not in truths:
                continue
            family, truth = truths[name]
            t = _true_times(truth, family, timing.seq.tolist(), timing.ticks.tolist())
            s = np.asarray(timing.time_s, dtype=np.float64)
            ok = np.isfinite(t) & np.isfinite(s)
            if methods is not None:
                ok &= np.isin(np.asarray(timing.method).astype(str), methods)
            t_all.append(t[ok])
            s_all.append(s[ok])
            who += [name] * int(ok.sum())
        found[f"sync_error{key}_us"], found[f"per_stream{key}_us"] = _affine_error(
            t_all, s_all, who
        )
    return found


def _affine_error(
    t_all: list[F64], s_all: list[F64], who: list[str]
) -> tuple[float | None, dict[str, float]]:
    """Largest |session time - true time| after one affine map of all, in µs; per stream."""
    if len(who) < 3:
        return None, {}
    t = np.concatenate(t_all)
    s = np.concatenate(s_all)
    a = np.c_[t - t.mean(), np.ones_like(t)]
    coef = np.linalg.lstsq(a, s, rcond=None)[0]
    residual = np.abs(s - a @ coef) * 1e6
    names = np.array(who)
    per = {n: round(float(residual[names == n].max()), 2) for n in dict.fromkeys(who)}
    return round(float(residual.max()), 2), per


def score_reconstruction(
    journal: Path, rig: Path, truth: Path, c3d: Path | None = None
) -> dict[str, Any]:
    """Reconstruct a recording with a rig (``spotlab reconstruct``'s path), optionally
    write the trial as C3D, and score its markers against the simulator's truth CSV."""
    result = reconstruct_file(journal, rig)
    if c3d is not None:
        write_trial(c3d, result.trial)
    ticks = result.ticks if result.ticks is not None else np.zeros(0, np.int64)
    true = read_truth_positions(truth).at_ticks(ticks)
    error = np.linalg.norm(result.trial.points - true, axis=-1)
    error = error[np.isfinite(error)]
    return {
        "c3d": str(c3d) if c3d is not None else None,
        "markers_reconstructed": result.summary["markers_reconstructed"],
        "rms_ray_px": result.summary["rms_ray_px"],
        "error_rms_mm": float(np.sqrt(np.mean(error**2))) if error.size else None,
        "error_max_mm": float(error.max()) if error.size else None,
    }


__all__ = ["device_figures", "frame_latency", "score_reconstruction", "sync_error"]
