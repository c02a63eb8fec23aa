"""Marker trajectories of a CSX scanner recording (docs/protocols/coda.md).

Two sources of 3-D, both in the scanner frame of
:mod:`spotlab.reconstruction.scanner` (x along the base, y depth, z up; mm):

* ``device``: the unit's own 3-D, computed from the three angles of one scan as
  measured, although each mirror crossed the marker at its own instant;
* ``angles``: ours, from the raw angles, each first carried from its own
  crossing instant (scan start + ``dt``) to one instant per frame, the middle of
  the sweep (scan start + 0.4 T), with the angle's rate of change over
  neighbouring scans, then the closed form
  :func:`~spotlab.reconstruction.scanner.scanner_position` with the mirror base
  the recording's metadata stores (the unit's ``VER:0`` geometry).

The precision model (:func:`~spotlab.reconstruction.scanner.scanner_precision`:
depth error growing as the square of range) is reported per marker for an angle
error of ``sigma_counts`` counts (default 1 count, 1/16000 of 40°).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from spotlab.acquisition._replay_engine import Walk
from spotlab.core.errors import RecordingError
from spotlab.core.frames import FrameBlock
from spotlab.io import Trial
from spotlab.io.journal import JournalReader
from spotlab.processing.decoding import decoder_for
from spotlab.processing.errors import InputError
from spotlab.reconstruction.scanner import scanner_position, scanner_precision

SCAN_KIND = "scan3"
SOURCES = ("angles", "device")
#: Rad per angle count: 40 degrees over 16 000 counts.
COUNT_RAD = math.radians(40.0) / 16_000
#: Part of the scan period the mirrors sweep (coda.md §1); frames are placed mid-sweep.
SWEEP_FRACTION = 0.8
F64 = NDArray[np.float64]


@dataclass
class ScannerRecording:
    """The decoded frames of one scanner stream, on its frame grid.

    Attributes
    ----------
    values : ndarray, shape (F, M, 10)
        The table markers' rows (``CodaDecoder`` values), NaN for lost frames.
    flags : ndarray, shape (F, M)
        Record flags (0: no record).
    ticks_us : ndarray, shape (F,)
        Scan starts (device µs); NaN for lost frames.
    rate_hz, base_mm : float
        Scan rate and the unit's mirror base.
    labels : list of str
        The markers' colour codes.
    stream : str
        Stream name.
    """

    values: F64
    flags: NDArray[np.uint8]
    ticks_us: F64
    rate_hz: float
    base_mm: float
    labels: list[str]
    stream: str


def read_scanner_recording(path: Path, stream: str | None = None) -> ScannerRecording:
    """Decode every frame of one scanner stream of a recording.

    Parameters
    ----------
    path : Path
        The journal.
    stream : str, optional
        The stream to read; needed when the recording holds several streams (other
        scanners, a timer).

    Raises
    ------
    InputError
        For several streams and no ``stream``, a stream that is not a scanner's, no
        frames, or no geometry in the metadata.
    """
    names: set[str] = set()
    blocks: list[FrameBlock] = []
    geometries: list[dict[str, Any]] = []
    try:
        declared = JournalReader(path).streams
        for kind, state, block in Walk(path, decoder_for).steps():
            if kind != "block" or block is None:
                continue
            names.add(state.name)
            if stream is None or state.name == stream:
                blocks.append(block)
                geometry = _geometry(state.metadata)
                if geometry not in geometries:
                    geometries.append(geometry)
    except RecordingError as exc:
        raise InputError(f"{path}: {exc}") from None
    if stream is None and len(names) != 1:
        raise InputError(
            f"{path}: {len(names)} streams ({', '.join(sorted(names))}); name the scanner's"
        )
    stream = stream if stream is not None else next(iter(names), "")
    if stream not in names or not blocks:
        raise InputError(f"{path}: no frames of a stream {stream!r}")
    spec = declared.get(stream, {}).get("spec") or {}
    if spec.get("kind") != SCAN_KIND:
        raise InputError(f"{path}: stream {stream!r} is not a scanner's ({SCAN_KIND})")
    meta = spec.get("metadata", {})
    geometry = meta.get("geometry")
    if not isinstance(geometry, dict) or "base_mm" not in geometry:
        raise InputError(f"{path}: the recording does not store the scanner's geometry")
    check_geometry(path, stream, [g for g in geometries if g] or [geometry], meta)
    labels = [str(c) for c in meta.get("config", {}).get("markers", [])]
    m = len(labels)
    seq = np.concatenate([b.seq for b in blocks])
    if not seq.size:
        raise InputError(f"{path}: the recording holds no frames")
    data = np.concatenate([b.data[:, :m, 0, :] for b in blocks])
    flags = np.concatenate([b.flags[:, :m, 0] for b in blocks])
    ticks = np.concatenate([b.ticks for b in blocks]).astype(np.float64)
    k = seq - seq[0]
    if np.any(np.diff(k) <= 0):
        raise InputError(f"{path}: the scanner stream restarted; one stretch at a time")
    n = int(k[-1]) + 1
    values = np.full((n, m, data.shape[-1]), np.nan)
    values[k] = data
    grid_flags = np.zeros((n, m), dtype=np.uint8)
    grid_flags[k] = flags
    grid_ticks = np.full(n, np.nan)
    grid_ticks[k] = ticks
    return ScannerRecording(
        values, grid_flags, grid_ticks, float(spec["rate_hz"]), float(geometry["base_mm"]),
        labels, stream,
    )  # fmt: skip


def _geometry(metadata: dict[str, Any]) -> dict[str, Any]:
    """The ``geometry`` a stream's metadata announces ({} without one)."""
    spec = metadata.get("spec")
    meta = spec.get("metadata") if isinstance(spec, dict) else None
    geometry = meta.get("geometry") if isinstance(meta, dict) else None
    return dict(geometry) if isinstance(geometry, dict) else {}


def check_geometry(
    path: Path, stream: str, geometries: list[dict[str, Any]], meta: dict[str, Any]
) -> None:
    """Refuse a stream whose unit reported several geometries, or another mirror base than
    its configuration asked for (``base_um``).

    Raises
    ------
    InputError
        One line naming both geometries.
    """

    def text(g: dict[str, Any]) -> str:
        base = float(g.get("base_mm", math.nan))
        return f"a mirror base of {base:g} mm ({g.get('serial_number', '?')})"

    if len(geometries) > 1:
        raise InputError(
            f"{path}: stream {stream!r}: the unit reported {text(geometries[0])}, later "
            f"{text(geometries[1])}; another unit or another geometry than the recording's"
        )
    asked = meta.get("config", {}).get("base_um")
    if asked is not None and geometries and float(asked) / 1000 != float(geometries[0]["base_mm"]):
        raise InputError(
            f"{path}: stream {stream!r}: the recording asked for a mirror base of "
            f"{float(asked) / 1000:g} mm, the unit reported {text(geometries[0])}"
        )


def angles_at(angles: F64, times_us: F64, at_us: F64, window: int = 5) -> F64:
    """Angles carried from their own instants to ``at_us`` with their rate of change.

    Parameters
    ----------
    angles, times_us : ndarray, shape (F, M, 3)
        Each angle (rad) and the instant it was measured (µs); NaN where missing.
    at_us : ndarray, shape (F,)
        The instant of each frame to carry the angles to.
    window : int
        The rate is the difference over ``±window`` scans (±1, then one-sided, at the
        ends and next to gaps; an angle with no measured neighbour is left as it is).

    Returns
    -------
    ndarray, shape (F, M, 3)
        ``angle + rate * (at - time)``.
    """
    rate = np.full(angles.shape, np.nan)
    for w in (window, 1):
        if angles.shape[0] <= 2 * w:
            continue
        d_a = angles[2 * w :] - angles[: -2 * w]
        d_t = times_us[2 * w :] - times_us[: -2 * w]
        r = np.full(angles.shape, np.nan)
        r[w:-w] = d_a / d_t
        rate = np.where(np.isfinite(rate), rate, r)
    if angles.shape[0] > 1:  # one-sided at the ends and next to gaps
        step = (angles[1:] - angles[:-1]) / (times_us[1:] - times_us[:-1])
        for lo, hi in ((slice(None, -1), step), (slice(1, None), step)):
            r = np.full(angles.shape, np.nan)
            r[lo] = hi
            rate = np.where(np.isfinite(rate), rate, r)
    rate = np.where(np.isfinite(rate), rate, 0.0)
    return angles + rate * (at_us[:, None, None] - times_us)


def scanner_points(rec: ScannerRecording, source: str = "angles") -> F64:
    """Marker positions (F, M, 3) mm from the device's 3-D or from the raw angles."""
    if source not in SOURCES:
        raise InputError(f"scanner source must be one of {SOURCES}, got {source!r}")
    v = rec.values
    if source == "device":
        valid = (rec.flags & 0x01) != 0
        return np.where(valid[..., None], v[..., 1:4], np.nan)
    if not np.isfinite(v[..., 4:7]).any():
        raise InputError("the recording holds no raw angles (recorded with out=3D)")
    times = rec.ticks_us[:, None, None] + v[..., 7:10]
    at = rec.ticks_us + SWEEP_FRACTION / 2 * 1e6 / rec.rate_hz
    a = angles_at(v[..., 4:7], times, at)
    tl, tr = np.tan(a[..., 0]), np.tan(a[..., 1])
    a = np.where((tl > tr)[..., None], a, np.nan)
    return scanner_position(a, rec.base_mm)


def scanner_trial(
    rec: ScannerRecording, source: str = "angles", sigma_counts: float = 1.0
) -> tuple[Trial, dict[str, Any]]:
    """The trajectories of a scanner recording and a JSON-safe summary.

    The summary gives, per marker, the frames with a position and the precision
    model's median standard deviations (x, depth y, z; mm) for ``sigma_counts``.
    """
    points = scanner_points(rec, source)
    sigma = sigma_counts * COUNT_RAD
    markers = []
    for m, label in enumerate(rec.labels):
        seen = np.isfinite(points[:, m]).all(axis=1)
        sd = (
            np.median(scanner_precision(points[seen, m], sigma, rec.base_mm)[0], axis=0)
            if seen.any()
            else np.full(3, np.nan)
        )
        markers.append({
            "label": label, "frames": int(seen.sum()),
            "precision_sd_mm": [None if not np.isfinite(s) else round(float(s), 4) for s in sd],
        })  # fmt: skip
    trial = Trial(
        points=points, labels=list(rec.labels), point_rate=rec.rate_hz,
        metadata={"scanner": {"source": source, "base_mm": rec.base_mm}},
    )  # fmt: skip
    summary = {
        "stream": rec.stream, "source": source, "frames": int(points.shape[0]),
        "base_mm": rec.base_mm, "sigma_counts": sigma_counts, "markers": markers,
    }  # fmt: skip
    return trial, summary
