"""Bounded Brent minimisation as a generator: the caller evaluates the points.

:func:`bounded_brent` is the bounded minimiser of Forsythe, Malcolm & Moler
(1977, ``fmin``: golden section with parabolic steps on an interval), with the
arithmetic, the order of operations and the stopping rule of SciPy's
``minimize_scalar(method="bounded")``, so that it visits the same points and
returns the same minimum to the last bit. As a generator it hands each point
to its caller and waits for the value, so that many searches can be stepped
side by side and their evaluations batched, without threads.
"""

from __future__ import annotations

import math
from collections.abc import Generator

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
