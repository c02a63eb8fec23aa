"""Ground truth of a simulated MCS-1 device as one ``.npz`` file, written on close.

The rows of :class:`~spotlab.simulators.truth.TruthWriter`, as arrays (F frames
taken, L LED/marker ids 0 .. L-1), named as the other families' npz truths
(``time_s``, ``markers_mm``) and as the truth CSV's columns otherwise:

* ``stream``, ``seq`` (-1: never sent), ``frame_no``, ``device_tick``, ``device_us``
  (int64, F); ``sent`` (bool, F);
* ``time_s`` (F,): world monotonic seconds of the frame's start (the CSV's
  ``true_time_s``);
* ``markers_mm`` (F, L, 3): each id's true position then, NaN where it has none;
  ``marker_ids`` (L,): 0 .. L-1.

Nothing is written until the device closes (a killed simulator leaves no file).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from spotlab.simulators.truth import TruthRow, TruthWriter


class NpzTruthWriter(TruthWriter):
    """A :class:`TruthWriter` that keeps its rows and writes them as ``.npz`` on close.

    Parameters
    ----------
    path : str or Path
        Output file (``.npz``).
    n_leds : int
        Ids 0 .. n_leds-1 get positions.
    """

    def __init__(self, path: str | Path, n_leds: int) -> None:
        super().__init__(path, n_leds)
        self.path.unlink(missing_ok=True)  # the CSV header the base class wrote
        self._heads: list[tuple[int, int, int, bool, float, int]] = []
        self._xyz: list[np.ndarray] = []

    def _write(self, row: TruthRow) -> None:
        if self._closed:
            return
        sent = bool(row.sent)
        self._heads.append(
            (row.stream, row.seq if sent else -1, row.frame_no, sent, row.world_ns, row.device_us)
        )
        self._xyz.append(self._positions(row))

    def flush(self) -> None:
        """Nothing: the file is written once, on close."""

    def close(self) -> None:
        """Resolve what is left (as not sent) and write the npz, atomically."""
        if self._closed:
            return
        super().close()
        heads = list(zip(*self._heads, strict=True)) if self._heads else [()] * 6
        stream, seq, frame_no, sent, world_ns, device_us = heads
        us = np.asarray(device_us, dtype=np.int64)
        tmp = self.path.with_name(self.path.name + ".tmp.npz")
        np.savez(
            tmp,
            stream=np.asarray(stream, dtype=np.int64),
            seq=np.asarray(seq, dtype=np.int64),
            frame_no=np.asarray(frame_no, dtype=np.int64),
            sent=np.asarray(sent, dtype=bool),
            time_s=np.asarray(world_ns, dtype=np.float64) / 1e9,
            device_tick=us & 0xFFFFFFFF,
            device_us=us,
            markers_mm=np.stack(self._xyz) if self._xyz else np.zeros((0, self.n_leds, 3)),
            marker_ids=np.arange(self.n_leds),
        )
        os.replace(tmp, self.path)


def truth_writer(path: str | Path, n_leds: int) -> TruthWriter:
    """The truth writer for ``path``: ``.npz`` arrays for that suffix, else the CSV."""
    if Path(path).suffix.lower() == ".npz":
        return NpzTruthWriter(path, n_leds)
    return TruthWriter(path, n_leds)
