"""Ground truth of a simulated run, written as CSV while the device runs.

One row per data frame the device *took* (including frames it then dropped
because its FIFO overflowed), in the order taken. A row is written once the
frame's fate is known — sent, dropped, or thrown away by a reset — and rows
are appended to the file every ``flush_every`` rows and on close (the file is
opened only for each append), so a reader, or a run that is killed, sees all
but the last few frames.

Columns:

``stream``
    0 for the first ``START:``, +1 at every later one.
``seq``
    The frame's seq on the wire (u16), -1 when it was never sent.
``frame_no``
    Frame number on the wire (u32).
``sent``
    1 when the frame went onto the line (maybe damaged or lost later by a
    link fault: see the fault log), 0 when it was dropped in the device or
    thrown away by a reset before its first byte.
``true_time_s``
    World monotonic seconds (``time.monotonic_ns() / 1e9``) at which the device
    clock read ``device_tick``: the start of the frame's first sample,
    including trigger jitter.
``device_tick``
    The tick the frame carries (device µs modulo 2**32).
``device_us``
    The same tick unwrapped (int64).
``led{id}_x_mm, led{id}_y_mm, led{id}_z_mm``
    For every LED of the scene: its true position at its own slot time
    ``true_time_s + (k + 1/2) * slot`` (k its place in the LED table);
    ``nan`` when the LED is not in the table or the scene has no position.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]


@dataclass
class TruthRow:
    """One frame taken by the device; ``sent`` is None until its fate is known."""

    stream: int
    frame_no: int
    world_ns: float
    device_us: int
    led_ids: I64
    positions: F64
    seq: int = -1
    sent: bool | None = None


class TruthWriter:
    """Writes :class:`TruthRow` objects to CSV in the order they were taken.

    Parameters
    ----------
    path : str or Path
        Output file (created or truncated).
    n_leds : int
        LEDs of the scene: ids 0 .. n_leds-1 get position columns.
    flush_every : int
        Flush after this many rows.
    """

    def __init__(self, path: str | Path, n_leds: int, flush_every: int = 50) -> None:
        self.path = Path(path)
        self.n_leds = n_leds
        self.flush_every = flush_every
        self._pending: deque[TruthRow] = deque()
        self._lines: list[str] = []
        self._closed = False
        cols = ["stream", "seq", "frame_no", "sent", "true_time_s", "device_tick", "device_us"]
        for i in range(n_leds):
            cols += [f"led{i}_x_mm", f"led{i}_y_mm", f"led{i}_z_mm"]
        self.path.write_text(",".join(cols) + "\n", encoding="ascii")

    def add(self, row: TruthRow) -> None:
        """Queue a row (written once it and every earlier row are resolved)."""
        self._pending.append(row)
        self.drain()

    def drain(self, force: bool = False) -> None:
        """Write every resolved row at the head of the queue; ``force``: all of them."""
        while self._pending and (force or self._pending[0].sent is not None):
            self._write(self._pending.popleft())
        if len(self._lines) >= self.flush_every or force:
            self.flush()

    def _positions(self, row: TruthRow) -> F64:
        """The row's positions (n_leds, 3) by LED id, NaN where it has none."""
        xyz = np.full((self.n_leds, 3), np.nan)
        keep = row.led_ids < self.n_leds
        xyz[row.led_ids[keep]] = row.positions[keep]
        return xyz

    def _write(self, row: TruthRow) -> None:
        if self._closed:
            return
        xyz = self._positions(row)
        head = (
            f"{row.stream},{row.seq if row.sent else -1},{row.frame_no},{int(bool(row.sent))},"
            f"{row.world_ns / 1e9:.9f},{row.device_us & 0xFFFFFFFF},{row.device_us}"
        )
        body = ",".join(f"{v:.4f}" for v in xyz.ravel()) if self.n_leds else ""
        self._lines.append(head + ("," + body if body else "") + "\n")

    def flush(self) -> None:
        """Append the rows written so far to the file."""
        if self._lines:
            with open(self.path, "a", encoding="ascii") as fh:
                fh.write("".join(self._lines))
            self._lines.clear()

    def close(self) -> None:
        """Write what is left (unresolved rows as not sent) and close the file."""
        for row in self._pending:
            if row.sent is None:
                row.sent = False
        self.drain(force=True)
        self._closed = True


@dataclass
class TruthPositions:
    """The marker positions of a truth CSV (see the module docstring).

    Attributes
    ----------
    device_tick : ndarray of int64, shape (N,)
        Device tick (µs modulo 2**32) of each frame taken.
    sent : ndarray of bool, shape (N,)
        Whether the frame went onto the line.
    positions : ndarray, shape (N, L, 3)
        True position of every LED id 0 .. L-1 (mm), NaN where it has none.
    """

    device_tick: I64
    sent: npt.NDArray[np.bool_]
    positions: F64

    def at_ticks(self, ticks: npt.ArrayLike) -> F64:
        """Positions (F, L, 3) of the frames sent at device ticks ``ticks`` (F,), unwrapped or
        not; NaN for a tick the device never sent."""
        keys = np.asarray(ticks, dtype=np.int64) % (1 << 32)
        sent = np.flatnonzero(self.sent)
        order = sent[np.argsort(self.device_tick[sent], kind="stable")]
        table = self.device_tick[order]
        pos = np.minimum(np.searchsorted(table, keys), max(table.size - 1, 0))
        out = np.full((keys.size, *self.positions.shape[1:]), np.nan)
        if table.size:
            found = table[pos] == keys
            out[found] = self.positions[order[pos[found]]]
        return out


def read_truth_positions(path: str | Path) -> TruthPositions:
    """Read the device ticks and LED positions of a truth CSV written by :class:`TruthWriter`.

    Rows cut short (a simulator killed while writing) are skipped.

    Raises
    ------
    ValueError
        If the file is not a truth CSV (its header does not start as :class:`TruthWriter`
        writes it).
    """
    with open(path, encoding="ascii") as fh:
        header = fh.readline().strip().split(",")
        if header[:7] != [
            "stream",
            "seq",
            "frame_no",
            "sent",
            "true_time_s",
            "device_tick",
            "device_us",
        ]:
            raise ValueError(f"{path}: not a spotlab truth CSV (header {header[:7]})")
        rows = [
            line.split(",")
            for line in fh
            if line.endswith("\n") and line.count(",") == len(header) - 1
        ]
    values = np.array(rows, dtype=np.float64).reshape(len(rows), len(header))
    n_leds = (len(header) - 7) // 3
    return TruthPositions(
        device_tick=values[:, 5].astype(np.int64),
        sent=values[:, 3] != 0,
        positions=values[:, 7:].reshape(len(rows), n_leds, 3),
    )
