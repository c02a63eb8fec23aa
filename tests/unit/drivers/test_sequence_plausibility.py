"""The plausibility limit on frame_no advances (mcs1.md §4 "Losses", docs/drivers.md).

The device takes one frame per frame period and can drop only frames it took,
so frame_no cannot advance faster than the ticks allow. A frame that claims
more (a damaged frame_no behind a CRC that still passes) is an unannounced
restart: one gap, a new stretch, nothing counted as lost.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pytest
from _spx_wire import SpxStream

from spotlab.core.frames import FrameBlock
from spotlab.core.stats import LinkStats
from spotlab.drivers.mcs1.sequence import MAX_FRAME_NO_STEP, SequenceTracker
from spotlab.drivers.selspot import SelspotConfig, SelspotDecoder, decoder_from_metadata

PERIOD = 5000  # µs: 200 Hz
N_FRAMES = 20
J = 10  # the frame that carries the fault


def config(rate_hz: float = 200.0) -> SelspotConfig:
    return SelspotConfig.create(cameras=2, leds=4, rate_hz=rate_hz, slot_us=100)


def stream(
    frame_no: Sequence[int],
    at: Sequence[int] | None = None,
    *,
    period_us: int = PERIOD,
    tick0: int = 0,
    status: int = 0,
) -> bytes:
    """Frames with seq 0, 1, ... and the given frame_no, CRCs valid.

    Frame ``k`` is taken at period ``at[k]`` (``frame_no[k]`` by default): its tick
    is ``tick0 + at[k] * period_us``. ``status`` goes to frames after a jump.
    """
    at = frame_no if at is None else at
    s = SpxStream(n_leds=4, n_cams=2, tick0=tick0, period_us=period_us)
    for k, (fn, i) in enumerate(zip(frame_no, at, strict=True)):
        jumped = k and fn - frame_no[k - 1] > 1
        s.append(i, seq=k, frame_no=fn, status=status if jumped else 0)
    return b"".join(s.frames)


def feed(dec: SelspotDecoder, data: bytes, whole: bool) -> FrameBlock:
    """At once (the vectorised path) or frame by frame (the one-frame path)."""
    if whole:
        return dec.feed(data, 0)
    n = dec.frame_bytes
    return FrameBlock.concat([dec.feed(data[i : i + n], i) for i in range(0, len(data), n)])


def counts(dec: SelspotDecoder) -> tuple[int, int, int, int]:
    st = dec.stats
    return st.lost_frames, st.device_dropped, st.gaps, dec.restarts


@pytest.fixture(params=[True, False], ids=["whole", "per-frame"])
def whole(request: pytest.FixtureRequest) -> bool:
    return bool(request.param)


def test_from_config_gives_the_decoder_its_frame_period() -> None:
    assert SelspotDecoder.from_config(config(70.0)).frame_period_us == pytest.approx(1e6 / 70)
    dec = decoder_from_metadata({"family": "selspot", "config": config().to_dict()})
    assert dec.frame_period_us == PERIOD
    assert SelspotDecoder(2, 4).frame_period_us is None


@pytest.mark.parametrize("jump", [2**31, 1000, 2**20, 2**31 + 12345])
def test_a_crc_valid_frame_no_jump_is_one_restart_not_dropped_frames(
    jump: int, whole: bool
) -> None:
    fns = list(range(N_FRAMES))
    fns[J] += jump  # the payload CRC is made for the damaged value: it passes
    data = stream(fns, at=range(N_FRAMES))  # ticks intact: one period per frame
    frame_len = len(data) // N_FRAMES
    dec = SelspotDecoder.from_config(config())
    upto = feed(dec, data[: (J + 1) * frame_len], whole)
    assert len(upto) == J + 1  # the frame is returned (its records may well be right)
    assert counts(dec) == (0, 0, 1, 1)  # one gap, a new stretch, nothing lost
    rest = feed(dec, data[(J + 1) * frame_len :], whole)
    # The next frame goes back relative to the damaged one: the spec's restart. Still
    # nothing lost; each restart opens a new seq epoch, so seq keeps increasing.
    assert counts(dec) == (0, 0, 2, 2)
    seq = FrameBlock.concat([upto, rest]).seq
    assert len(seq) == N_FRAMES and np.all(np.diff(seq) > 0)
    assert (seq % 65536).tolist() == list(range(N_FRAMES))


def test_a_fifo_overflow_of_3_frames_is_still_3_device_drops(whole: bool) -> None:
    fns = [k if k < J else k + 3 for k in range(N_FRAMES)]  # frame_no +4, ticks +4 periods
    dec = SelspotDecoder.from_config(config())
    block = feed(dec, stream(fns, status=0x40), whole)
    assert block.status[J] == 0x40
    assert block.seq.tolist() == list(range(N_FRAMES))
    assert counts(dec) == (3, 3, 1, 0)


def test_tick_wrap_at_2_32_does_not_trip_the_limit(whole: bool) -> None:
    # Ticks wrap between frames 2 and 3; a 3-frame overflow straddles the wrap too.
    fns = [k if k < 2 else k + 3 for k in range(N_FRAMES)]
    dec = SelspotDecoder.from_config(config())
    block = feed(dec, stream(fns, tick0=2**32 - 4 * PERIOD, status=0x40), whole)
    assert len(block) == N_FRAMES
    assert np.all(np.diff(block.ticks) > 0) and block.ticks[-1] > 2**32
    assert counts(dec) == (3, 3, 1, 0)


@pytest.mark.parametrize(
    ("rate_hz", "ticks_per_frame"),
    [(70.0, 14286), (70.0, 14285), (200.0, 4950), (200.0, 5049)],  # rounding, ±1 % drift
)
def test_clock_rounding_and_drift_stay_within_the_limit(
    rate_hz: float, ticks_per_frame: int, whole: bool
) -> None:
    fns = [k if k < J else k + 3 for k in range(N_FRAMES)]
    dec = SelspotDecoder.from_config(config(rate_hz))
    feed(dec, stream(fns, period_us=ticks_per_frame, status=0x40), whole)
    assert counts(dec) == (3, 3, 1, 0)


def test_more_drops_than_the_ticks_allow_is_a_restart(whole: bool) -> None:
    # frame_no +4 but the ticks moved one period: the device cannot have taken 4 frames.
    fns = [k if k < J else k + 3 for k in range(N_FRAMES)]
    dec = SelspotDecoder.from_config(config())
    feed(dec, stream(fns, at=range(N_FRAMES), status=0x40), whole)
    assert counts(dec) == (0, 0, 1, 1)


def test_ticks_going_back_is_a_restart(whole: bool) -> None:
    at = [k if k < J else k - 5 for k in range(N_FRAMES)]  # 4 periods back at J
    dec = SelspotDecoder.from_config(config())
    block = feed(dec, stream(range(N_FRAMES), at, tick0=10**6), whole)
    assert len(block) == N_FRAMES
    assert counts(dec) == (0, 0, 1, 1)


def test_a_real_unannounced_restart_still_counts_its_leading_losses() -> None:
    # The device restarts its stream (seq and frame_no from 0, ticks run on) 4 periods
    # after its last frame; frames 0 and 1 of the new stream are lost. The ticks allow
    # them, so they are counted, as before the limit.
    s = SpxStream(n_leds=4, n_cams=2, period_us=PERIOD)
    for k in range(5):
        s.append(k)
    for k in range(2, 6):
        s.append(8 + k, seq=k, frame_no=k)
    dec = SelspotDecoder.from_config(config())
    block = dec.feed(b"".join(s.frames), 0)
    assert len(block) == 9
    assert counts(dec) == (2, 0, 2, 1)


# -- the tracker alone, without a frame period: a fixed cap -----------------------------
BASE = 10**6  # a stream well under way: a return to it cannot pass for a new stream


def track(fns: Sequence[int]) -> tuple[int, int, int, int]:
    """(lost, device dropped, gaps, restarts) of frames with seq 0, 1, ... and ``fns``."""
    stats = LinkStats()
    tracker = SequenceTracker(stats)
    n = len(fns)
    tracker.update(np.arange(n), np.asarray(fns) % 2**32, np.zeros(n, dtype=np.int64))
    return stats.lost_frames, stats.device_dropped, stats.gaps, tracker.restarts


@pytest.mark.parametrize("jump", [4, MAX_FRAME_NO_STEP])
def test_without_a_frame_period_drops_up_to_the_cap_are_counted(jump: int) -> None:
    fns = [BASE + k if k < J else BASE + k + jump - 1 for k in range(N_FRAMES)]
    assert track(fns) == (jump - 1, jump - 1, 1, 0)


@pytest.mark.parametrize("jump", [MAX_FRAME_NO_STEP + 1, 2**31])
def test_without_a_frame_period_a_jump_past_the_cap_is_a_restart(jump: int) -> None:
    fns = [BASE + k for k in range(N_FRAMES)]
    fns[J] += jump - 1  # frame J alone damaged: a restart there and one back
    assert track(fns) == (0, 0, 2, 2)


def test_after_start_a_first_frame_past_the_cap_counts_nothing() -> None:
    stats = LinkStats()
    tracker = SequenceTracker(stats, frame_period=PERIOD)
    tracker.mark_discontinuity()  # START: acknowledged
    tracker.update([0], [2**31], [0])  # a damaged first frame
    assert (stats.lost_frames, stats.gaps, tracker.restarts) == (0, 0, 0)
    tracker.mark_discontinuity()
    tracker.update([2], [2], [10**6])  # two frames lost right after START: counted
    assert (stats.lost_frames, stats.gaps) == (2, 1)


def test_the_frame_period_must_be_positive() -> None:
    with pytest.raises(ValueError, match="frame period"):
        SequenceTracker(LinkStats(), frame_period=0)
