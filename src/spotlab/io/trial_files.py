"""A labelled trial from a C3D or TRC file: the markers and frames a model is learnt from.

:func:`read_trial` picks the reader by the file's suffix; :func:`labelled_markers`
takes the labelled markers of chosen frames out of a :class:`~spotlab.io.trial.Trial`
for learning or checking a marker model (:mod:`spotlab.reconstruction.identification`).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from spotlab.io.c3d_files import read_c3d
from spotlab.io.trc_files import read_trc
from spotlab.io.trial import FileFormatError, Trial

__all__ = ["TRIAL_READERS", "labelled_markers", "read_trial"]

FloatArray = NDArray[np.float64]

TRIAL_READERS = {".c3d": read_c3d, ".trc": read_trc}

#: Labels an acquisition program gives trajectories it could not name (Vicon ``*12``,
#: empty labels, Cortex/EVaRT ``M012``-style is a real name and is kept).
_UNNAMED = re.compile(r"^(\*\d*|)$")

#: By default a marker is kept when seen in at least this share of the chosen frames
#: in which any marker is seen.
MIN_SHARE = 0.5


def read_trial(path: str | Path) -> Trial:
    """Read a C3D or TRC file (by its suffix).

    Raises
    ------
    FileFormatError
        For another suffix, or a file its reader refuses.
    """
    reader = TRIAL_READERS.get(Path(path).suffix.lower())
    if reader is None:
        raise FileFormatError(path, "not a trial file: the name must end in .c3d or .trc")
    return reader(path)


def labelled_markers(
    trial: Trial,
    path: str | Path,
    *,
    markers: Sequence[str] | None = None,
    frames: tuple[int | None, int | None] | None = None,
) -> tuple[tuple[str, ...], FloatArray]:
    """The labelled markers of a trial over chosen frames.

    Parameters
    ----------
    trial : Trial
    path : str or Path
        The trial's file, named in errors.
    markers : sequence of str, optional
        Labels to take, in this order. Default: every named marker (not ``*12`` or
        empty, not a model output the C3D file lists as an angle, force, moment, power,
        scalar or modelled marker) seen in at least half of the chosen frames that show
        any marker.
        A label repeated in the file is told apart as ``NAME#2``, ``NAME#3``...
    frames : (start, stop), optional
        Frames ``start`` to ``stop - 1``, counted from 0 at the file's first frame;
        None for either end: the file's. Default: all.

    Returns
    -------
    labels : tuple of str, length M
    positions : ndarray, shape (F, M, 3)
        Trajectories (mm), NaN where a marker is missing.

    Raises
    ------
    FileFormatError
        For frames outside the file or an empty range, a label the trial lacks, or a
        trial with no named marker seen.
    """
    names = _unique(trial.labels)
    if not names:
        raise FileFormatError(path, "the file holds no marker trajectories")
    F = trial.n_frames
    start, stop = (None, None) if frames is None else frames
    first = 0 if start is None else start
    last = F if stop is None else stop
    if not 0 <= first < last <= F:
        raise FileFormatError(
            path, f"frames {first}:{last} are not a range of its {F} frames (0:{F})"
        )
    X = np.asarray(trial.points[first:last], dtype=np.float64)
    seen: NDArray[np.bool_] = np.asarray(np.isfinite(X).all(axis=2))
    if markers is not None:
        index = {name: m for m, name in enumerate(names)}
        unknown = [name for name in markers if name not in index]
        if unknown:
            raise FileFormatError(
                path,
                f"the trial lacks {len(unknown)} of the {len(markers)} markers asked for: "
                f"{_some(unknown)} (it has {_some(names)})",
            )
        if len(set(markers)) != len(markers):
            raise FileFormatError(path, f"a marker is named twice: {', '.join(markers)}")
        take = [index[name] for name in markers]
        absent = [names[m] for m in take if not seen[:, m].any()]
        if absent:
            raise FileFormatError(path, f"markers never seen in these frames: {', '.join(absent)}")
    else:
        active = seen.any(axis=1)
        share = seen[active].mean(axis=0) if active.any() else np.zeros(len(names))
        not_markers = trial.metadata.get("point_kinds", {})
        take = [
            m
            for m, name in enumerate(names)
            if not _UNNAMED.match(name) and name not in not_markers and share[m] >= MIN_SHARE
        ]
        if not take:
            raise FileFormatError(
                path, f"no labelled marker is seen in frames {first}:{last} of the trial"
            )
    return tuple(names[m] for m in take), np.ascontiguousarray(X[:, take])


def _unique(labels: Sequence[str]) -> list[str]:
    """Labels with repeats told apart: the second ``RKNE`` becomes ``RKNE#2``."""
    count: dict[str, int] = {}
    out = []
    for name in labels:
        name = str(name).strip()
        count[name] = count.get(name, 0) + 1
        out.append(name if count[name] == 1 else f"{name}#{count[name]}")
    return out


def _some(names: Sequence[str], n: int = 10) -> str:
    """The first ``n`` names, comma-separated, with ``...`` for the rest."""
    return ", ".join(names[:n]) + (f", ... ({len(names)} in all)" if len(names) > n else "")
