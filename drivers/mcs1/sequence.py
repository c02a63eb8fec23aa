"""Counters of the MCS-1 header and payload prefix: losses, duplicates, restarts.

Every data frame carries a 16-bit ``seq`` (frames *sent*, from 0 at ``START:``)
in its header and a 32-bit ``frame_no`` (frame periods since ``START:``,
counting frames the device dropped) and a 32-bit µs ``tick`` in its payload
prefix (mcs1.md §4-5). From them :class:`SequenceTracker` derives, per frame:

* link losses: ``seq`` advanced by ``s > 1``: ``s - 1`` frames lost on the link;
* device drops: ``frame_no`` advanced by ``f > s``: ``f - s`` frames the device
  dropped itself (FIFO overflow, status bit 0x40);
* duplicates: ``seq`` did not advance (``s == 0``): the frame is dropped;
* restarts: ``seq`` or ``frame_no`` went backwards, or ``frame_no`` advanced
  by more than the device clock allows (below): the device started a new stream
  the host was not told about, or the payload was damaged in a way its CRC-16
  missed; handled like :meth:`mark_discontinuity`, nothing counted as lost.

The plausibility limit: the device takes one frame per frame period and can
drop only frames it took, so between two frames ``frame_no`` cannot advance by
more than ``1 + (1 + TICK_TOLERANCE) * dt / period`` for a tick advance ``dt``
(ticks going back allow no advance at all). Without a frame period the limit
is :data:`MAX_FRAME_NO_STEP` frames. It keeps a damaged ``frame_no`` that
still passes the CRC (about 1 damaged frame in 65536) from counting as
billions of frames dropped by the device.

Each frame that reveals a loss counts one gap. A new tracker makes no
assumption about where in a stream it joins. After :meth:`mark_discontinuity`
(called when ``START:`` has been acknowledged) or a detected restart, the first
frame is compared with a stream counting from 0, so frames lost right after
``START:`` are counted too — unless its ``seq`` exceeds its ``frame_no``, which
no stream counting from ``START:`` can show, or its ``frame_no + 1`` exceeds
the limit: :data:`MAX_FRAME_NO_STEP` after ``START:``, the ticks since the
previous frame after a detected restart. Such a frame joins the new stream
without counting anything before it.

The unwrapped ``seq`` handed out stays strictly increasing across restarts: a
new stream starts at the next multiple of 65536, so ``seq % 65536`` is always
the device's value. Ticks are unwrapped continuously (nearest value with the
same residue), across discontinuities too; a clock model must start a new
piece at a discontinuity.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from spotlab.core.stats import LinkStats

SEQ_PERIOD = 1 << 16
#: Largest ``frame_no`` advance accepted when the frame period is not known.
MAX_FRAME_NO_STEP = 1 << 16
#: Clock drift and jitter allowed, as a fraction of the tick advance (one frame is added).
TICK_TOLERANCE = 0.05
I64 = npt.NDArray[np.int64]


def _steps(raw: I64, previous: int, bits: int) -> I64:
    """Steps between consecutive counter values, each brought into [-half, half).

    ``raw`` holds K >= 1 raw values, ``previous`` the value before the first
    (any integer congruent to the raw value modulo ``2**bits``).
    """
    half, mask = 1 << (bits - 1), (1 << bits) - 1
    out = np.empty_like(raw)
    out[0] = int(raw[0]) - previous
    np.subtract(raw[1:], raw[:-1], out=out[1:])
    out += half
    out &= mask
    out -= half
    return out


def _advance(ticks: I64, before: int | None) -> I64:
    """Tick advance from the frame before each frame (0 for the very first frame)."""
    return np.diff(ticks, prepend=ticks[:1] if before is None else before)


class SequenceTracker:
    """Turns raw counters into unwrapped ones and counts losses into ``stats``.

    Parameters
    ----------
    stats : LinkStats
        Counters to update: ``frames``, ``lost_frames``, ``device_dropped``,
        ``duplicates``, ``gaps``.
    frame_period : float, optional
        Device ticks per frame period, for the plausibility limit on ``frame_no``
        advances. Without it the limit is :data:`MAX_FRAME_NO_STEP` frames.

    Attributes
    ----------
    restarts : int
        Streams restarted without :meth:`mark_discontinuity` (a counter went
        back, or ``frame_no`` advanced more than the ticks allow).
    """

    def __init__(self, stats: LinkStats, frame_period: float | None = None) -> None:
        if frame_period is not None and not frame_period > 0:
            raise ValueError(f"the frame period must be > 0 ticks, got {frame_period}")
        self.stats = stats
        self.frame_period = frame_period
        # frame_no advance allowed per tick of advance (the limit is 1 + this * dt)
        self._per_tick = None if frame_period is None else (1 + TICK_TOLERANCE) / frame_period
        self.restarts = 0
        self._tick: int | None = None  # last unwrapped tick
        self._epoch = 0  # added to the unwrapped seq of the current stream
        self._seq: int | None = None  # last unwrapped seq within the epoch
        self._frame_no: int | None = None  # last unwrapped frame_no
        self._last_out = -1  # last seq handed out
        self._from_start = False  # the next fresh frame belongs to a stream begun at START:
        self._unannounced = False  # ... and that stream was detected, not announced

    def mark_discontinuity(self) -> None:
        """A new stream starts (``START:`` acknowledged, reconnect): do not join counters across.

        The next frame is compared with a stream counting from 0.
        """
        self._new_stream(unannounced=False)

    def _new_stream(self, unannounced: bool) -> None:
        if self._last_out >= self._epoch:
            self._epoch = (self._last_out // SEQ_PERIOD + 1) * SEQ_PERIOD
        self._seq = None
        self._frame_no = None
        self._from_start = True
        self._unannounced = unannounced

    def update(
        self,
        seq: npt.ArrayLike,
        frame_no: npt.ArrayLike,
        ticks: npt.ArrayLike,
    ) -> tuple[npt.NDArray[np.bool_], I64, I64]:
        """Process the counters of the next frames.

        Parameters
        ----------
        seq : array_like of int, shape (K,)
            Raw 16-bit header sequence numbers.
        frame_no : array_like of int, shape (K,)
            Raw 32-bit frame numbers of the payload prefix.
        ticks : array_like of int, shape (K,)
            Raw 32-bit device ticks (µs) of the payload prefix.

        Returns
        -------
        keep : ndarray of bool, shape (K,)
            False for duplicates, which must be dropped.
        seq : ndarray of int64, shape (K,)
            Unwrapped sequence numbers (meaningful where ``keep``).
        ticks : ndarray of int64, shape (K,)
            Unwrapped ticks in µs.
        """
        seq_raw = np.asarray(seq).astype(np.int64).reshape(-1)
        fn_raw = np.asarray(frame_no).astype(np.int64).reshape(-1)
        tick_before = self._tick
        ticks_out = self._unwrap_ticks(np.asarray(ticks).astype(np.int64).reshape(-1))
        k = seq_raw.shape[0]
        if k and self._seq is not None and self._frame_no is not None:
            # The common case, every counter +1, costs a few array operations at most.
            if (
                (int(seq_raw[0]) - self._seq) & 0xFFFF == 1
                and (int(fn_raw[0]) - self._frame_no) & 0xFFFFFFFF == 1
                and (
                    k == 1
                    or (
                        bool(((np.diff(seq_raw) & 0xFFFF) == 1).all())
                        and bool(((np.diff(fn_raw) & 0xFFFFFFFF) == 1).all())
                    )
                )
                # frame_no +1 is within the limit unless the ticks went back
                and (self._per_tick is None or bool((_advance(ticks_out, tick_before) >= 0).all()))
            ):
                seq_u = np.arange(self._seq + 1, self._seq + 1 + k, dtype=np.int64)
                self._seq += k
                self._frame_no += k
                self.stats.frames += k
                seq_u += self._epoch
                self._last_out = int(seq_u[-1])
                return np.ones(k, dtype=bool), seq_u, ticks_out
        keep = np.ones(k, dtype=bool)
        seq_out = np.zeros(k, dtype=np.int64)
        t_step = _advance(ticks_out, tick_before)
        start = 0
        while start < k:
            start = self._segment(
                seq_raw[start:], fn_raw[start:], t_step[start:], start, keep, seq_out
            )
        return keep, seq_out, ticks_out

    def _limit(self, t_step: I64) -> npt.NDArray[np.float64] | float:
        """Largest ``frame_no`` advance the device clock allows over each tick advance."""
        if self._per_tick is None:
            return float(MAX_FRAME_NO_STEP)
        return np.asarray(t_step * self._per_tick + 1.0, dtype=np.float64)

    def _unwrap_ticks(self, raw: I64) -> I64:
        if not raw.shape[0]:
            return raw
        if self._tick is None:
            self._tick = int(raw[0])
        if raw.shape[0] == 1:
            step = ((int(raw[0]) - self._tick + 0x80000000) & 0xFFFFFFFF) - 0x80000000
            self._tick += step
            return np.array([self._tick], dtype=np.int64)
        out = np.cumsum(_steps(raw, self._tick, 32))
        out += self._tick
        self._tick = int(out[-1])
        return out

    def _segment(
        self,
        s_raw: I64,
        f_raw: I64,
        t_step: I64,
        start: int,
        keep: npt.NDArray[np.bool_],
        seq_out: I64,
    ) -> int:
        """Process frames up to the next restart; return the index where it stopped."""
        if self._seq is None or self._frame_no is None:
            fresh, s_prev, f_prev = True, -1, -1
        else:
            fresh, s_prev, f_prev = False, self._seq, self._frame_no
        s_step = _steps(s_raw, s_prev, 16)
        f_step = _steps(f_raw, f_prev, 32)
        # A restart: a counter went back, or frame_no advanced more than the ticks allow.
        back = (s_step < 0) | (f_step < 0) | (f_step > self._limit(t_step))
        if fresh:
            # Since START: at most MAX_FRAME_NO_STEP frames; since a detected restart, at
            # most what the ticks since the previous frame allow.
            first_limit = float(MAX_FRAME_NO_STEP)
            if self._unannounced and self._per_tick is not None:
                first_limit = int(t_step[0]) * self._per_tick + 1.0
            if self._from_start and s_raw[0] <= f_raw[0] and f_raw[0] + 1 <= first_limit:
                # A new stream counts both from 0: frames before the first one were lost.
                s_step[0], f_step[0] = s_raw[0] + 1, f_raw[0] + 1
            else:
                # Joined a running stream: nothing to compare the first frame with.
                s_step[0], f_step[0] = 1, 1
            s_prev, f_prev = int(s_raw[0] - s_step[0]), int(f_raw[0] - f_step[0])
            back[0] = False
        if back[0]:
            # The device started a new stream unannounced, or the payload was damaged.
            self.restarts += 1
            self.stats.gaps += 1
            self._new_stream(unannounced=True)
            return start
        stop = int(np.argmax(back)) if back.any() else s_raw.shape[0]
        s_step, f_step = s_step[:stop], f_step[:stop]
        seq_u = s_prev + np.cumsum(s_step)
        dup = s_step == 0
        link_lost = np.where(dup, 0, s_step - 1)
        dev_lost = np.where(dup, 0, np.maximum(f_step - s_step, 0))
        lost = link_lost + dev_lost
        keep[start : start + stop] = ~dup
        seq_out[start : start + stop] = self._epoch + seq_u
        n_dup = int(dup.sum())
        self.stats.duplicates += n_dup
        self.stats.frames += stop - n_dup
        self.stats.lost_frames += int(lost.sum())
        self.stats.device_dropped += int(dev_lost.sum())
        self.stats.gaps += int(np.count_nonzero(lost))
        self._seq = int(seq_u[-1])
        self._frame_no = f_prev + int(f_step.sum())
        self._last_out = int(seq_out[start + stop - 1])
        return start + stop
