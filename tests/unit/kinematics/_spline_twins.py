"""What the spline kernel tests share: the same call with the numpy twin and with the
kernel, and test signals."""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

import numpy as np
import pytest

from spotlab.core import native

T = TypeVar("T")


def twin_and_kernel(make: Callable[[], T], monkeypatch: pytest.MonkeyPatch) -> tuple[T, T]:
    """``make()`` once with the numpy twin, once with the kernel."""
    monkeypatch.setenv(native.NO_NATIVE_ENV, "1")
    twin = make()
    monkeypatch.setenv(native.NO_NATIVE_ENV, "0")
    return twin, make()


def signals(n: int, k: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``k`` noisy sines of random frequency and size at ``n`` jittered times (s)."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.008, 0.012, n))
    freq = rng.uniform(0.2, 2.0, k)
    y = np.sin(2 * np.pi * freq[None, :] * t[:, None]) * rng.uniform(0.5, 50.0, k)
    return t, y + 10.0 ** rng.uniform(-3.0, -1.0, k) * rng.standard_normal((n, k))
