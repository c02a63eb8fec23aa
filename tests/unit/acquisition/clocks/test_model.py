"""ClockModel: mapping, precision, epochs, inverse, JSON round trip, bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from spotlab.acquisition.clocks import ClockEvent, ClockModel, ClockSegment
from spotlab.core.errors import ClockError


def two_segments() -> ClockModel:
    a = ClockSegment(epoch=0, tick_start=0, tick_end=999_999, origin=0, offset_s=1.0, rate=1e-6)
    b = ClockSegment(
        epoch=0, tick_start=1_001_000, tick_end=2_000_000, origin=1_001_000, offset_s=2.0, rate=1e-6
    )
    c = ClockSegment(epoch=1, tick_start=0, tick_end=500_000, origin=0, offset_s=3.5, rate=2e-6)
    return ClockModel(1e6, [a, b, c], [ClockEvent("step", 1_001_000, -1e-3, 10)])


def test_segments_and_epochs_map_ticks():
    m = two_segments()
    ticks = np.array([0, 500_000, 1_001_000, 1_500_000, 100, 200_000])
    got = m(ticks)  # the drop 1_500_000 -> 100 starts epoch 1
    np.testing.assert_allclose(got, [1.0, 1.5, 2.0, 2.499, 3.5002, 3.9], rtol=0, atol=1e-12)
    assert m.epochs == 2
    np.testing.assert_array_equal(m.epochs_of(ticks), [0, 0, 0, 0, 1, 1])
    # explicit epoch overrides the inference
    assert m(np.array([100]), epoch=1)[0] == pytest.approx(3.5002)
    assert m(np.array([100]), epoch=0)[0] == pytest.approx(1.0001)


def test_drift_and_jitter_figures():
    seg = ClockSegment(0, 0, 10, 0, 0.0, 1.0 / (1e6 * (1 + 250e-6)), n=5, jitter_s=2e-7)
    m = ClockModel(1e6, [seg])
    assert m.drift_ppm == pytest.approx(250.0, abs=1e-6)
    assert m.jitter_s == pytest.approx(2e-7)


def test_precision_holds_for_hours_at_mhz_rates():
    # 10 h of a 10 MHz counter that started at 2**40: one tick apart must stay 1e-7 s apart
    tick_hz = 1e7
    origin = 1 << 40
    seg = ClockSegment(0, origin, origin + 10**12, origin, 5.0, 1.0 / tick_hz)
    m = ClockModel(tick_hz, [seg])
    t0 = origin + 36_000 * 10**7
    got = m(np.array([t0, t0 + 1]))
    assert got[1] - got[0] == pytest.approx(1e-7, abs=1e-12)
    assert got[0] == pytest.approx(5.0 + 36_000.0, abs=1e-9)


def test_inverse_round_trips():
    m = two_segments()
    ticks = np.array([10, 400_000, 1_200_000, 1_900_000])
    back = m.inverse(m(ticks), epoch=0)
    np.testing.assert_allclose(back, ticks, atol=1e-6)


def test_json_round_trip_is_exact():
    m = two_segments()
    text = json.dumps(m.to_dict(include_residuals=True))
    m2 = ClockModel.from_dict(json.loads(text))
    ticks = np.array([0, 999, 1_500_000, 5, 400_000])
    np.testing.assert_array_equal(m2(ticks), m(ticks))
    assert m2.events == m.events
    assert m2.segments == m.segments


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda d: d.update(format="other"), "not a spotlab.clock_model"),
        (lambda d: d.pop("segments"), "incomplete"),
        (lambda d: d["segments"][0].update(rate=-1.0), "positive rate"),
        (lambda d: d["events"].append({"kind": "melt", "at_tick": 0, "size_s": 0}), "kind"),
    ],
)
def test_from_dict_names_what_is_wrong(mutate, match):
    d = two_segments().to_dict()
    mutate(d)
    with pytest.raises(ClockError, match=match):
        ClockModel.from_dict(d)


def test_bad_models_and_ticks_raise():
    with pytest.raises(ClockError, match="at least one segment"):
        ClockModel(1e6, [])
    with pytest.raises(ClockError, match="tick rate"):
        ClockModel(0.0, two_segments().segments)
    m = two_segments()
    with pytest.raises(ClockError, match="finite"):
        m(np.array([1.0, np.nan]))
    with pytest.raises(ClockError, match="no segment in epoch 5"):
        m(np.array([1]), epoch=5)
