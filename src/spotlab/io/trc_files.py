"""TRC files (Motion Analysis / OpenSim marker trajectories, tab-separated text).

Layout: a ``PathFileType 4 (X/Y/Z) name`` line; a line of header keys (DataRate,
CameraRate, NumFrames, NumMarkers, Units, OrigDataRate, OrigDataStartFrame,
OrigNumFrames) and a line of their values; a line ``Frame# Time name<TAB><TAB><TAB>...``;
a line ``<TAB><TAB>X1 Y1 Z1 X2 ...``; then one row per frame: frame number, time in
seconds, X Y Z per marker, an empty field where a marker is missing.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from spotlab.io.trial import MM_PER_UNIT, FileFormatError, Trial

_KEYS = (
    "DataRate",
    "CameraRate",
    "NumFrames",
    "NumMarkers",
    "Units",
    "OrigDataRate",
    "OrigDataStartFrame",
    "OrigNumFrames",
)


def read_trc(path: str | Path) -> Trial:
    """Read a TRC file; points in millimetres (m and cm converted), NaN where missing.

    Raises
    ------
    FileFormatError
        The file cannot be opened or does not follow the TRC layout.
    """
    try:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise FileFormatError(path, f"cannot read the file: {exc.strerror or exc}") from exc
    lines = text.splitlines()
    if len(lines) < 5 or not lines[0].startswith("PathFileType"):
        raise FileFormatError(path, "not a TRC file (no 'PathFileType' first line)")
    keys = [k.strip() for k in lines[1].split("\t")]
    values = [v.strip() for v in lines[2].split("\t")]
    header = dict(zip(keys, values, strict=False))
    try:
        rate = float(header["DataRate"])
        n_markers = int(header["NumMarkers"])
        n_declared = int(header["NumFrames"])
    except (KeyError, ValueError) as exc:
        raise FileFormatError(path, f"bad header line 3 ({exc!r})") from exc
    if not rate > 0 or n_markers < 0:
        raise FileFormatError(path, f"bad DataRate {rate} or NumMarkers {n_markers}")
    file_units = header.get("Units", "mm").lower()
    names = lines[3].rstrip("\r\n").split("\t")[2:]
    labels = [n.strip() for n in names[::3] if n.strip()][:n_markers]
    if len(labels) != n_markers:
        raise FileFormatError(path, f"{len(labels)} marker names for NumMarkers {n_markers}")

    rows = [(number, line) for number, line in enumerate(lines[5:], start=6) if line.strip()]
    n_cols = 2 + 3 * n_markers
    table = np.full((len(rows), n_cols), np.nan)
    time_text = []
    for i, (number, line) in enumerate(rows):
        fields = line.rstrip("\r\n").split("\t")[:n_cols]
        time_text.append(fields[1].strip() if len(fields) > 1 else "")
        try:
            table[i, : len(fields)] = [float(v) if v.strip() else math.nan for v in fields]
        except ValueError as exc:
            raise FileFormatError(path, f"line {number}: {exc}") from exc
    if len(rows) != n_declared:
        raise FileFormatError(path, f"NumFrames says {n_declared}, the file has {len(rows)} rows")
    points = table[:, 2:].reshape(len(rows), n_markers, 3)
    points[~np.isfinite(points).all(axis=2)] = np.nan
    units = "mm"
    if file_units in MM_PER_UNIT:
        points *= MM_PER_UNIT[file_units]
    else:
        units = file_units
    first = int(table[0, 0]) if len(rows) and np.isfinite(table[0, 0]) else 1
    return Trial(
        points=points,
        labels=labels,
        point_rate=rate,
        first_frame=first,
        units=units,
        metadata={
            "format": "trc",
            "file_units": file_units,
            "header": header,
            "times": table[:, 1].copy(),
            "time_text": time_text,
        },
    )


def write_trc(path: str | Path, trial: Trial) -> None:
    """Write the trial's points as a TRC file (PathFileType 4, tab-separated, mm).

    Missing samples are written as empty fields; analog data and events are not
    part of the TRC format and are left out. A trial read from a TRC file keeps its
    Time column and its header values as the file wrote them (``0.017`` stays
    ``0.017`` at 60 Hz, ``150.00`` stays ``150.00``) while they still describe the
    trial (as many times as frames; rates equal to ``trial.point_rate``). Otherwise
    frame ``f`` is at time ``(f - 1) / rate`` (the C3D convention: a trial that starts
    at ``first_frame`` 11 starts at 10 / rate s), written with 6 decimals.
    """
    trial.check(path)
    n_frames, n_markers = trial.n_frames, trial.n_markers
    for label in trial.labels:
        if not label or any(c in label for c in "\t\r\n"):
            raise FileFormatError(path, f"marker name {label!r} cannot be written to a TRC file")
    values = _header_values(trial)
    head = [
        f"PathFileType\t4\t(X/Y/Z)\t{Path(path).name}",
        "\t".join(_KEYS),
        "\t".join(values[k] for k in _KEYS),
        "\t".join(["Frame#", "Time", *(f"{name}\t\t" for name in trial.labels)]).rstrip("\t"),
        "\t\t" + "\t".join(f"X{i}\tY{i}\tZ{i}" for i in range(1, n_markers + 1)),
        "",
    ]
    frames = trial.first_frame + np.arange(n_frames)
    times = _time_column(trial)
    coords = trial.points.reshape(n_frames, 3 * n_markers)
    body = []
    for i in range(n_frames):
        cells = ["" if not math.isfinite(v) else repr(float(v)) for v in coords[i]]
        body.append(f"{frames[i]}\t{times[i]}\t" + "\t".join(cells))
    try:
        with open(path, "w", encoding="utf-8", newline="\n") as handle:
            handle.write("\n".join(head + body) + "\n")
    except OSError as exc:
        raise FileFormatError(path, f"cannot write the file: {exc.strerror or exc}") from exc


def _number(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:
        return None


def _header_values(trial: Trial) -> dict[str, str]:
    """Header line 3: the read file's texts where they still hold, else from the trial."""
    rate = f"{trial.point_rate:.6g}"
    values = {
        "DataRate": rate,
        "CameraRate": rate,
        "NumFrames": str(trial.n_frames),
        "NumMarkers": str(trial.n_markers),
        "Units": trial.units,
        "OrigDataRate": rate,
        "OrigDataStartFrame": "1",
        "OrigNumFrames": str(trial.n_frames),
    }
    read = trial.metadata.get("header") if trial.metadata.get("format") == "trc" else None
    if not isinstance(read, dict):
        return values
    for key in ("DataRate", "CameraRate", "OrigDataRate"):  # "150.00" stays "150.00"
        if _number(str(read.get(key, ""))) == trial.point_rate:
            values[key] = str(read[key])
    for key, count in (("NumFrames", trial.n_frames), ("NumMarkers", trial.n_markers)):
        if _number(str(read.get(key, ""))) == count:
            values[key] = str(read[key])
    for key in ("OrigDataStartFrame", "OrigNumFrames"):  # about the original capture
        if _number(str(read.get(key, ""))) is not None:
            values[key] = str(read[key])
    return values


def _time_column(trial: Trial) -> list[str]:
    """The Time cells: as read when there is one number per frame, else (f - 1) / rate."""
    read = trial.metadata.get("time_text") if trial.metadata.get("format") == "trc" else None
    if isinstance(read, list) and len(read) == trial.n_frames:
        if all(_number(str(t)) is not None for t in read):
            return [str(t) for t in read]
    times = (trial.first_frame - 1 + np.arange(trial.n_frames)) / trial.point_rate
    return [f"{t:.6f}" for t in times]
