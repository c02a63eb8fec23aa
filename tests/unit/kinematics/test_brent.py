"""The Brent generators of _brent equal SciPy's minimize_scalar step for step."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from scipy import optimize

from spotlab.kinematics._brent import bounded_brent, bracketed_brent, minimise
from spotlab.kinematics.gcv import median

FUNCTIONS: list[Callable[[float], float]] = [
    lambda x: (x - 0.3) ** 2,
    lambda x: float(np.cosh(x - 1.7) + 0.01 * np.sin(40.0 * x)),
    lambda x: abs(x + 0.25) ** 1.5 + 1e-12 * x,
    lambda x: float(np.log1p((x - 2.0) ** 4)),
]


def _recorded(f: Callable[[float], float]) -> tuple[Callable[[float], float], list[float]]:
    seen: list[float] = []

    def g(x: float) -> float:
        seen.append(float(x))
        return f(float(x))

    return g, seen


@pytest.mark.parametrize("f", FUNCTIONS)
@pytest.mark.parametrize("xatol", [1e-6, 1e-3])
def test_bounded_brent_is_scipys_bounded(f: Callable[[float], float], xatol: float) -> None:
    ours, our_points = _recorded(f)
    theirs, their_points = _recorded(f)
    x, fun = minimise(bounded_brent(-1.0, 3.0, xatol), ours)
    res = optimize.minimize_scalar(
        theirs, bounds=(-1.0, 3.0), method="bounded", options={"xatol": xatol}
    )
    assert our_points == their_points
    assert x == res.x and fun == res.fun


@pytest.mark.parametrize("f", FUNCTIONS)
@pytest.mark.parametrize("tol", [1e-5, 1.48e-8])
def test_bracketed_brent_is_scipys_brent(f: Callable[[float], float], tol: float) -> None:
    grid = np.linspace(-1.0, 3.0, 9)
    best = int(np.argmin([f(g) for g in grid]))
    bracket = (float(grid[best + 1]), float(grid[best]), float(grid[best - 1]))  # reversed ends
    ours, our_points = _recorded(f)
    theirs, their_points = _recorded(f)
    x, fun = minimise(bracketed_brent(*bracket, tol=tol), ours)
    res = optimize.minimize_scalar(theirs, bracket=bracket, method="brent", tol=tol)
    assert our_points == their_points
    assert x == res.x and fun == res.fun


def test_bracketed_brent_refuses_a_bad_bracket() -> None:
    with pytest.raises(ValueError, match="xa < xb < xc"):
        minimise(bracketed_brent(0.0, 2.0, 1.0, tol=1e-5), lambda x: x * x)
    with pytest.raises(ValueError, match="below"):
        minimise(bracketed_brent(0.0, 1.0, 2.0, tol=1e-5), lambda x: x * x)


def test_median_is_numpys() -> None:
    rng = np.random.default_rng(0)
    for n in range(1, 200):
        values = rng.standard_normal(n)
        assert median(values) == np.median(values)
