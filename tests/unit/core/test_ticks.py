from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from spotlab.core.ticks import CounterUnwrapper, unwrap_counter


def test_unwrap_across_a_u16_wrap() -> None:
    raw = [65533, 65534, 65535, 0, 1, 2]
    assert unwrap_counter(raw, 16).tolist() == [65533, 65534, 65535, 65536, 65537, 65538]


def test_unwrap_continues_from_previous_block() -> None:
    u = CounterUnwrapper(16)
    a = u([65534, 65535])
    b = u([0, 5])
    assert a.tolist() == [65534, 65535]
    assert b.tolist() == [65536, 65541]
    u.reset()
    assert u([3]).tolist() == [3]


def test_unwrap_allows_small_backward_steps() -> None:
    # A duplicate or a reordered frame steps back by a little: it must not look like a wrap.
    assert unwrap_counter([10, 11, 10, 12], 16).tolist() == [10, 11, 10, 12]


def test_unwrap_rejects_values_out_of_range() -> None:
    with pytest.raises(ValueError, match="outside"):
        unwrap_counter([0, 70000], 16)
    with pytest.raises(ValueError, match="1 to 62"):
        unwrap_counter([0], 0)


@given(
    start=st.integers(0, 2**40),
    steps=st.lists(st.integers(0, 2**31 - 1), min_size=1, max_size=50),
)
def test_unwrap_recovers_any_u32_sequence_with_steps_below_half_period(
    start: int, steps: list[int]
) -> None:
    true = start + np.cumsum([0, *steps])
    raw = true % 2**32
    u = CounterUnwrapper(32)
    u.last = int(true[0])
    out = u(raw[1:])
    np.testing.assert_array_equal(out, true[1:])
