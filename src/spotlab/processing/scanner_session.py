"""Every CSX scanner of one recording in one frame and on one time base (issue 18).

A recording may hold several scanner streams (and a timer). The first scanner in
recording order is the **reference unit**: its frame is the output frame, its scans
the output frames. Each other unit's trajectories are put on session time
(:func:`~spotlab.processing.session_times.recording_timebase`: the timer's edges, or
host arrival stamps without a timer), interpolated at the reference unit's instants
(mid-sweep), only between two of its scans in a row, and carried into the reference
frame by the rigid motion that best maps its view of the **shared markers** onto the
reference unit's view at the same instants
(:func:`~spotlab.processing.scanner_alignment.align_pairs`), or, when at least three
of them stand still (a static object: an L-frame), by their mean positions in each
unit (:func:`~spotlab.processing.scanner_alignment.align_still`), which needs no time
base. The shared markers are the ones named (e.g. an L-frame's ``WR WO WY WG``) or, by
default, every marker code in both units' tables. No truth is used.

Markers are named ``<stream>.<code>`` when there are several units. The precision
model's standard deviations of an aligned unit are turned into the reference frame
(``R cov R'``).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.acquisition.timebase import StreamTiming
from spotlab.core.errors import SpotlabError
from spotlab.io import Trial
from spotlab.io.journal import JournalReader
from spotlab.processing.decoding import input_suffix
from spotlab.processing.errors import InputError
from spotlab.processing.scanner_alignment import (
    Alignment,
    align_pairs,
    align_still,
    points_at,
    still_markers,
)
from spotlab.processing.scanner_trajectories import (
    COUNT_RAD,
    SCAN_KIND,
    SWEEP_FRACTION,
    ScannerRecording,
    read_scanner_recording,
    scanner_points,
    scanner_trial,
)
from spotlab.processing.session_times import TIMER_FAMILY, recording_timebase
from spotlab.reconstruction.scanner import scanner_precision

F64 = NDArray[np.float64]


def scanner_streams(path: Path) -> list[str]:
    """Names of the scanner streams of a recording, in recording order ([] if unreadable)."""
    try:
        streams = JournalReader(path).streams
    except SpotlabError:
        return []
    out = []
    for name, meta in streams.items():
        spec = meta.get("spec")
        if isinstance(spec, dict) and spec.get("kind") == SCAN_KIND:
            out.append(name)
    return out


def is_scanner_session(path: Path) -> bool:
    """True for a ``.spj`` recording of scanners only, with or without a timer."""
    if input_suffix(path) != ".spj" or not path.is_file():
        return False
    try:
        streams = JournalReader(path).streams
    except SpotlabError:
        return False
    kinds = [
        "timer" if m.get("family") == TIMER_FAMILY else (m.get("spec") or {}).get("kind")
        for m in streams.values()
    ]
    return SCAN_KIND in kinds and all(k in (SCAN_KIND, "timer") for k in kinds)


def frame_times(rec: ScannerRecording, path: Path, timing: StreamTiming) -> F64:
    """Session time (s) of each scan's mid-sweep on the recording's frame grid, NaN where lost."""
    k = np.asarray(timing.seq - timing.seq[0], dtype=np.int64)
    n = rec.values.shape[0]
    if k.shape[0] == 0 or k[-1] >= n or np.any(np.diff(k) <= 0):
        raise InputError(f"{path}: stream {rec.stream!r}: its session times do not match its scans")
    out = np.full(n, np.nan)
    out[k] = timing.time_s + SWEEP_FRACTION / 2 / rec.rate_hz
    return out


def _precision(points: F64, rec: ScannerRecording, sigma: float, rotation: F64) -> list[Any]:
    """Median precision-model sd (x, y, z; mm) of one marker, turned into the output frame."""
    seen = np.isfinite(points).all(axis=1)
    if not seen.any():
        return [None, None, None]
    cov = scanner_precision(points[seen], sigma, rec.base_mm)[1]
    turned = rotation @ cov @ rotation.T
    sd = np.median(np.sqrt(np.diagonal(turned, axis1=-2, axis2=-1)), axis=0)
    return [round(float(s), 4) for s in sd]


def session_scanner_trial(
    path: Path,
    source: str = "angles",
    shared: Sequence[str] | None = None,
    sigma_counts: float = 1.0,
) -> tuple[Trial, dict[str, Any]]:
    """The trajectories of every scanner of a recording, in the first unit's frame.

    Parameters
    ----------
    path : Path
        The recording.
    source : str
        ``angles`` or ``device`` (:func:`~spotlab.processing.scanner_trajectories.scanner_points`).
    shared : sequence of str, optional
        Colour codes of the shared object's markers; default: every code in both tables.
    sigma_counts : float
        Angle error of the precision model (counts).

    Returns
    -------
    Trial
        ``(F, M, 3)`` mm on the reference unit's scans; one recording of one unit is
        :func:`~spotlab.processing.scanner_trajectories.scanner_trial`'s.
    dict
        JSON-safe summary; with several units ``units`` holds each one's alignment.

    Raises
    ------
    InputError
        No scanner stream, a shared code no unit has, too few shared markers seen by
        both units at common instants, or a stream that cannot be read.
    """
    names = scanner_streams(path)
    if not names:
        raise InputError(f"{path}: no scanner stream in the recording")
    if len(names) == 1:
        if shared:
            raise InputError(f"{path}: --align-markers needs a recording of several scanners")
        return scanner_trial(read_scanner_recording(path, names[0]), source, sigma_counts)
    recs = [read_scanner_recording(path, n) for n in names]
    if shared:
        unknown = [c for c in shared if not any(c in r.labels for r in recs)]
        if unknown:
            raise InputError(f"{path}: no scanner has the marker code(s) {', '.join(unknown)}")
    base = recording_timebase(path)
    times = [frame_times(r, path, base.streams[r.stream]) for r in recs]
    ref, at = recs[0], times[0]
    sigma = sigma_counts * COUNT_RAD
    columns: list[F64] = []
    labels: list[str] = []
    markers: list[dict[str, Any]] = []
    units: list[dict[str, Any]] = []
    for rec, t in zip(recs, times, strict=True):
        own = scanner_points(rec, source)
        if rec is ref:
            moved, rotation, fit = own, np.eye(3), None
        else:
            here = points_at(t, own, at, 1.0 / rec.rate_hz)
            codes = list(shared) if shared else [c for c in rec.labels if c in ref.labels]
            fit = _align(path, ref, columns[: len(ref.labels)], rec, own, here, codes)
            moved, rotation = fit.apply(here), fit.R
        for m, code in enumerate(rec.labels):
            column = moved[:, m]
            columns.append(column)
            labels.append(f"{rec.stream}.{code}")
            markers.append({
                "label": labels[-1], "frames": int(np.isfinite(column).all(axis=1).sum()),
                "precision_sd_mm": _precision(own[:, m], rec, sigma, rotation),
            })  # fmt: skip
        units.append(_unit_summary(rec, fit))
    points = np.stack(columns, axis=1)
    trial = Trial(
        points=points, labels=labels, point_rate=ref.rate_hz,
        metadata={"scanner": {"source": source, "reference": ref.stream, "units": units}},
    )  # fmt: skip
    summary = {
        "stream": ref.stream, "source": source, "frames": int(points.shape[0]),
        "base_mm": ref.base_mm, "sigma_counts": sigma_counts, "time_base": base.reference,
        "units": units, "markers": markers,
    }  # fmt: skip
    return trial, summary


def _align(
    path: Path,
    ref: ScannerRecording,
    ref_points: list[F64],
    rec: ScannerRecording,
    own: F64,
    here: F64,
    codes: Sequence[str],
) -> Alignment:
    """Fit ``rec``'s view onto the reference's: from the mean positions of the shared
    markers standing still when there are 3 (no time base needed), else from the
    positions at common instants (``here``: ``rec`` interpolated at the reference's)."""
    a = np.full((here.shape[0], len(codes), 3), np.nan)
    b = np.full(a.shape, np.nan)
    b_own = np.full((own.shape[0], len(codes), 3), np.nan)
    for i, code in enumerate(codes):
        if code in ref.labels and code in rec.labels:
            a[:, i] = ref_points[ref.labels.index(code)]
            b[:, i] = here[:, rec.labels.index(code)]
            b_own[:, i] = own[:, rec.labels.index(code)]
    try:
        still = still_markers(a, b_own, codes)
        if len(still) >= 3:
            return align_still(a, b_own, codes, still)
        return align_pairs(a, b, codes)
    except InputError as exc:
        raise InputError(f"{path}: {rec.stream!r} onto {ref.stream!r}: {exc}") from None


def _unit_summary(rec: ScannerRecording, fit: Alignment | None) -> dict[str, Any]:
    out: dict[str, Any] = {
        "stream": rec.stream, "frames": int(rec.values.shape[0]), "rate_hz": rec.rate_hz,
        "base_mm": rec.base_mm,
    }  # fmt: skip
    if fit is not None:
        out["alignment"] = {
            "method": fit.method, "markers": list(fit.labels), "pairs": fit.pairs,
            "rms_mm": round(fit.rms, 4),
            "rotation": np.round(fit.R, 9).tolist(), "translation_mm": np.round(fit.t, 4).tolist(),
        }  # fmt: skip
    return out
