"""Brent minimisation (bounded, or from a bracket) as generators: the caller evaluates.

:func:`bounded_brent` is the bounded minimiser of Forsythe, Malcolm & Moler
(1977, ``fmin``: golden section with parabolic steps on an interval), with the
arithmetic, the order of operations and the stopping rule of SciPy's
``minimize_scalar(method="bounded")``, so that it visits the same points and
returns the same minimum to the last bit. As a generator it hands each point
to its caller and waits for the value, so that many searches can be stepped
side by side and their evaluations batched, without threads.
:func:`bracketed_brent` is SciPy's ``minimize_scalar(method="brent")`` from a
bracket, likewise step for step; :func:`minimise` runs either on a function. With
them a GCV search needs no SciPy import (most of a short fit's memory).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator

#: Square root of the machine epsilon used by the stopping rule.
_SQRT_EPS = math.sqrt(2.2e-16)
#: Golden-section fraction ``(3 - sqrt 5) / 2``.
_GOLDEN = 0.5 * (3.0 - math.sqrt(5.0))


def _sign(value: float) -> float:
    """``sign(value)``, with 1 for zero."""
    return 1.0 if value >= 0.0 else -1.0


def bounded_brent(
    lo: float, hi: float, xatol: float, maxfun: int = 500
) -> Generator[float, float, tuple[float, float]]:
    """Minimise a function of one variable on [lo, hi]; yields points, is sent their values.

    Parameters
    ----------
    lo, hi : float
        The interval, ``lo <= hi``.
    xatol : float
        Absolute tolerance in x.
    maxfun : int
        Largest number of evaluations.

    Returns
    -------
    tuple of float
        The minimiser found and its value (the generator's return value).
    """
    a, b = float(lo), float(hi)
    fulc = a + _GOLDEN * (b - a)
    nfc = xf = fulc
    rat = e = 0.0
    fx = yield xf
    num = 1
    ffulc = fnfc = fx
    xm = 0.5 * (a + b)
    tol1 = _SQRT_EPS * abs(xf) + xatol / 3.0
    tol2 = 2.0 * tol1
    while abs(xf - xm) > tol2 - 0.5 * (b - a):
        golden = True
        if abs(e) > tol1:  # try a parabolic step through the three best points
            golden = False
            r = (xf - nfc) * (fx - ffulc)
            q = (xf - fulc) * (fx - fnfc)
            p = (xf - fulc) * q - (xf - nfc) * r
            q = 2.0 * (q - r)
            if q > 0.0:
                p = -p
            q = abs(q)
            r, e = e, rat
            if abs(p) < abs(0.5 * q * r) and q * (a - xf) < p < q * (b - xf):
                rat = (p + 0.0) / q
                x = xf + rat
                if (x - a) < tol2 or (b - x) < tol2:
                    rat = tol1 * _sign(xm - xf)
            else:
                golden = True
        if golden:
            e = (a - xf) if xf >= xm else (b - xf)
            rat = _GOLDEN * e
        x = xf + _sign(rat) * max(abs(rat), tol1)
        fu = yield x
        num += 1
        if fu <= fx:
            if x >= xf:
                a = xf
            else:
                b = xf
            fulc, ffulc = nfc, fnfc
            nfc, fnfc = xf, fx
            xf, fx = x, fu
        else:
            if x < xf:
                a = x
            else:
                b = x
            if fu <= fnfc or nfc == xf:
                fulc, ffulc = nfc, fnfc
                nfc, fnfc = x, fu
            elif fu <= ffulc or fulc == xf or fulc == nfc:
                fulc, ffulc = x, fu
        xm = 0.5 * (a + b)
        tol1 = _SQRT_EPS * abs(xf) + xatol / 3.0
        tol2 = 2.0 * tol1
        if num >= maxfun:
            break
    return xf, fx


#: Golden-section fraction and smallest tolerance of SciPy's unbounded Brent minimiser.
_CG = 0.3819660
_MINTOL = 1.0e-11


def bracketed_brent(
    xa: float, xb: float, xc: float, tol: float, maxiter: int = 500
) -> Generator[float, float, tuple[float, float]]:
    """Brent's minimiser from a bracket; yields points, is sent their values.

    The arithmetic, order of evaluations and stopping rule of SciPy's
    ``minimize_scalar(method="brent", bracket=(xa, xb, xc), tol=tol)``: the three
    bracket points first (``xa < xb < xc`` after ordering the ends, ``f(xb)`` below
    both), then golden-section and parabolic steps (Brent 1973, ``localmin``) to a
    relative tolerance ``tol`` in x.

    Parameters
    ----------
    xa, xb, xc : float
        The bracket, xb between the others.
    tol : float
        Relative tolerance in x (plus 1e-11 absolute).
    maxiter : int
        Largest number of steps after the bracket.

    Returns
    -------
    tuple of float
        The minimiser found and its value (the generator's return value).

    Raises
    ------
    ValueError
        When the points do not bracket a minimum.
    """
    if xa > xc:
        xa, xc = xc, xa
    if not xa < xb < xc:
        raise ValueError("bracket: need xa < xb < xc")
    fa = yield xa
    fb = yield xb
    fc = yield xc
    if not (fb < fa and fb < fc):
        raise ValueError("bracket: need f(xb) below f(xa) and f(xc)")
    x = w = v = xb
    fw = fv = fx = fb
    a, b = xa, xc
    deltax = rat = 0.0
    for _ in range(maxiter):
        tol1 = tol * abs(x) + _MINTOL
        tol2 = 2.0 * tol1
        xmid = 0.5 * (a + b)
        if abs(x - xmid) < (tol2 - 0.5 * (b - a)):
            break
        golden = abs(deltax) <= tol1
        if not golden:  # parabolic step through x, w, v
            tmp1 = (x - w) * (fx - fv)
            tmp2 = (x - v) * (fx - fw)
            p = (x - v) * tmp2 - (x - w) * tmp1
            tmp2 = 2.0 * (tmp2 - tmp1)
            if tmp2 > 0.0:
                p = -p
            tmp2 = abs(tmp2)
            dx_temp, deltax = deltax, rat
            if tmp2 * (a - x) < p < tmp2 * (b - x) and abs(p) < abs(0.5 * tmp2 * dx_temp):
                rat = p * 1.0 / tmp2
                u = x + rat
                if (u - a) < tol2 or (b - u) < tol2:
                    rat = tol1 if xmid - x >= 0 else -tol1
            else:
                golden = True
        if golden:
            deltax = (a - x) if x >= xmid else (b - x)
            rat = _CG * deltax
        if abs(rat) < tol1:
            u = x + tol1 if rat >= 0 else x - tol1
        else:
            u = x + rat
        fu = yield u
        if fu > fx:
            if u < x:
                a = u
            else:
                b = u
            if fu <= fw or w == x:
                v, w, fv, fw = w, u, fw, fu
            elif fu <= fv or v == x or v == w:
                v, fv = u, fu
        else:
            if u >= x:
                a = x
            else:
                b = x
            v, w, x = w, x, u
            fv, fw, fx = fw, fx, fu
    return x, fx


def minimise(
    search: Generator[float, float, tuple[float, float]], f: Callable[[float], float]
) -> tuple[float, float]:
    """Run one of the searches above on f; its minimiser and value."""
    point = next(search)
    while True:
        try:
            point = search.send(f(point))
        except StopIteration as done:
            result: tuple[float, float] = done.value
            return result
