"""The trace ``tr(inv(A) R)`` of a banded A from its Cholesky factor, by Takahashi's recursion."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: Steps of the recursion whose contributions to the trace are summed in one call.
SUM_STEPS = 16

_multiply = np.multiply
_reduce = np.add.reduce
_copyto = np.copyto


class _BlockLayout:
    """Samples ``i = b * length + j`` as (length, ..., blocks) arrays, blocks contiguous."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.length = min(max(int(np.ceil(np.sqrt(n))), 1), n)
        self.blocks = -(-n // self.length)
        self.total = self.blocks * self.length

    def arrange(self, values: FloatArray, out: FloatArray) -> FloatArray:
        """``values`` (..., n) into ``out`` (length, ..., blocks), zero past the end."""
        padded = np.zeros((*values.shape[:-1], self.total))
        padded[..., : values.shape[-1]] = values
        return self.arrange_padded(padded, out)

    def arrange_padded(self, padded: FloatArray, out: FloatArray) -> FloatArray:
        """``padded`` (..., total), zero past n, into ``out`` (length, ..., blocks)."""
        by_block = padded.reshape(*padded.shape[:-1], self.blocks, self.length)
        out[...] = np.moveaxis(by_block, -1, 0)
        return out


class _Window:
    """A stack of bw x bw windows (bw, bw, C, blocks) and the views a step reads or writes."""

    def __init__(self, bw: int, count: int, blocks: int) -> None:
        self.x = np.empty((bw, bw, count, blocks))
        self.corner = self.x[0, 0]
        self.top = self.x[0, 1:]
        self.left = self.x[1:, 0]
        self.inner = self.x[1:, 1:]  # the previous window's leading block goes here
        self.leading = self.x[:-1, :-1]
        self.first_row = self.x[0]
        self.later_rows = self.x[1:]  # the previous window's leading rows go here
        self.leading_rows = self.x[:-1]


class _Plan:
    """Work arrays of :func:`_takahashi_sums` for C factors, with the views of every step.

    ``coupling`` (bw, length, C, blocks) holds ``-U[i, i + d] / U[i, i]`` and
    ``source`` (length, C, blocks) ``1 / U[i, i]^2`` of C upper banded Cholesky
    factors U, laid out by the block layout (:meth:`InverseTrace.load`). The
    views are made once, since a search runs the recursion many times at one size.
    """

    def __init__(self, bw: int, count: int, layout: _BlockLayout, r: FloatArray) -> None:
        length, blocks = layout.length, layout.blocks
        shape = (count, blocks)
        self.bw, self.count, self.blocks = bw, count, blocks
        self.coupling = np.empty((bw, length, *shape))
        self.source = np.empty((length, *shape))
        self.prod = np.empty((bw, bw, *shape))
        self.ny = np.empty((bw, *shape))
        self.ny_head = self.ny[:-1]
        self.terms = np.empty((bw + 1, *shape))
        self.terms_source = self.terms[0]
        self.terms_rest = self.terms[1:]
        self.windows = (_Window(bw, count, blocks), _Window(bw, count, blocks))
        self.phis = (_Window(bw, count, blocks), _Window(bw, count, blocks))
        # the trace's terms of up to SUM_STEPS steps, after the running sum (row 0)
        self.sums = np.empty((1 + SUM_STEPS * (bw + 1), *shape))
        self.sum_slots = [
            (self.sums[1 + s * (bw + 1)], self.sums[2 + s * (bw + 1) : 1 + (s + 1) * (bw + 1)])
            for s in range(SUM_STEPS)
        ]
        self.sum_rows = [self.sums[: 1 + s * (bw + 1)] for s in range(SUM_STEPS + 1)]
        # per step j: -c as it multiplies rows (phi) and columns (windows), c, source, R
        self.steps = [
            (
                self.coupling[:, j][:, None],
                self.coupling[:, j][None],
                self.coupling[:, j],
                self.source[j],
                r[0, j],
                r[1:, j, None],
            )
            for j in range(length - 1, -1, -1)
        ]


def _companion_step(
    window: _Window, new: _Window, negc_cols: FloatArray, negc: FloatArray, source: FloatArray,
    plan: _Plan,
) -> None:  # fmt: skip
    """``new = T X T^T + source e1 e1^T`` for stacks of symmetric windows X (bw, bw, ...).

    ``T = [[-c^T], [I, 0]]`` is the companion matrix of one row of the Cholesky
    factor; ``negc`` is ``-c`` (bw, ...), ``negc_cols`` the same as (1, bw, ...).
    Leaves ``-y = -X c`` (minus the rest of that row of the inverse) in
    ``plan.ny``; ``new.corner`` is a diagonal entry of the inverse.

    Notes
    -----
    Each entry is computed by the same floating-point operations in the same
    order as ``y = sum_b X[:, b] c[b]``, ``corner = source + c_0 y_0 + c_1 y_1 +
    ...``: negating a factor negates a product and a sum exactly.
    """
    _multiply(window.x, negc_cols, out=plan.prod)
    _reduce(plan.prod, axis=1, out=plan.ny)
    _copyto(plan.terms_source, source)
    _multiply(negc, plan.ny, out=plan.terms_rest)
    _reduce(plan.terms, axis=0, out=new.corner)
    _copyto(new.inner, window.leading)
    _copyto(new.top, plan.ny_head)
    _copyto(new.left, plan.ny_head)


def _takahashi_sums(plan: _Plan) -> FloatArray:
    """Takahashi's recursion for all blocks (and factors) at once, summed against R.

    Returns ``sum_j corner_j r[0, j] - sum_k y_j[k] r[k + 1, j]`` per factor and
    block, shape (C, blocks), for the factors loaded into ``plan``: per step j
    of every block (last sample first), ``corner`` is ``inv(A)[i, i]`` and
    ``-y[k - 1]`` is ``inv(A)[i, i + k]`` for ``i = b * length + j``; ``r``
    (R's band laid out alike, off-diagonals doubled) was given to the plan.

    Notes
    -----
    Takahashi's backward recursion (Hutchinson & de Hoog 1985): from
    ``U Sigma = U^-T``, the window ``X_i = Sigma[i:i+bw, i:i+bw]`` follows
    ``X_i = T_i X_{i+1} T_i^T + e_1 e_1^T / U_ii^2`` with ``T_i`` the
    companion matrix of row i of U, O(n bw^2) in all. The maps compose, so
    the n steps run as blocks side by side: compose each block's map, chain
    the block maps, then run all blocks from their known ends together. The
    windows are held entry by entry (arrays over factors and blocks), so each
    step is a few vector operations whatever the number of factors; the work
    arrays and their views are reused, and the coupling is held negated, which
    saves a negation per step and leaves every result unchanged to the last
    bit. The trace's terms are summed in order, SUM_STEPS steps per reduction.
    """
    bw, count, blocks = plan.bw, plan.count, plan.blocks
    # 1. each block's map X -> phi X phi^T + psi, as stacks (bw, bw, C, blocks)
    phi, phi_next = plan.phis
    phi.x[...] = 0.0
    for a in range(bw):
        phi.x[a, a] = 1.0
    psi, psi_next = plan.windows
    psi.x[...] = 0.0
    for negc_rows, negc_cols, negc, source, _, _ in plan.steps:
        _multiply(phi.x, negc_rows, out=plan.prod)
        _reduce(plan.prod, axis=0, out=phi_next.first_row)
        _copyto(phi_next.later_rows, phi.leading_rows)
        phi, phi_next = phi_next, phi
        _companion_step(psi, psi_next, negc_cols, negc, source, plan)
        psi, psi_next = psi_next, psi
    # (C, blocks, bw, bw)
    phi_b: FloatArray = np.moveaxis(phi.x, (2, 3), (0, 1))
    psi_b: FloatArray = np.moveaxis(psi.x, (2, 3), (0, 1))
    # 2. the window at the end of each block
    ends = np.empty((count, blocks, bw, bw))
    ends[:, blocks - 1] = 0.0
    phi_t = np.swapaxes(phi_b, 2, 3)
    left, both = np.empty((count, bw, bw)), np.empty((count, bw, bw))
    for b in range(blocks - 1, 0, -1):
        np.matmul(phi_b[:, b], ends[:, b], out=left)
        np.matmul(left, phi_t[:, b], out=both)
        np.add(both, psi_b[:, b], out=ends[:, b - 1])
    # 3. all blocks from their ends at once, the trace's terms summed as they come
    window, other = plan.windows
    window.x[...] = np.moveaxis(ends, (2, 3), (0, 1))
    acc = np.zeros((count, blocks))
    slot = 0
    last = len(plan.steps) - 1
    for step, (_, negc_cols, negc, source, r_diag, r_off) in enumerate(plan.steps):
        _companion_step(window, other, negc_cols, negc, source, plan)
        window, other = other, window
        corner_term, other_terms = plan.sum_slots[slot]
        _multiply(window.corner, r_diag, out=corner_term)
        _multiply(plan.ny, r_off, out=other_terms)
        slot += 1
        if slot == SUM_STEPS or step == last:
            _copyto(plan.sums[0], acc)
            _reduce(plan.sum_rows[slot], axis=0, out=acc)
            slot = 0
    return acc


class InverseTrace:
    """``tr(inv(A) R)`` for banded A (from its Cholesky factor) and a fixed banded R.

    Parameters
    ----------
    r : ndarray, shape (bw + 1, n)
        R in upper band storage (the band of A may be as wide, not wider).

    Notes
    -----
    Only the band of ``inv(A)`` enters the trace, and its entries are summed as
    Takahashi's recursion (:func:`_takahashi_sums`) produces them, block-major, so no
    band of the inverse is ever stored. Several factors of the same size (one
    matrix at several smoothing parameters) run side by side in one recursion,
    so its per-step cost in Python is paid once for all of them. The work arrays
    are kept between calls: a smoothing-parameter search evaluates the trace
    many times at one size.
    """

    def __init__(self, r: FloatArray) -> None:
        bw = r.shape[0] - 1
        n = r.shape[1]
        self.layout = _BlockLayout(n)
        shape = (self.layout.length, self.layout.blocks)
        # entry (i, i + d) counts twice for d > 0 (both triangles)
        self.r = np.empty((bw + 1, *shape))
        for d in range(bw + 1):
            row = np.zeros(n)
            row[: n - d] = r[bw - d, d:] * (1.0 if d == 0 else 2.0)
            self.layout.arrange(row, self.r[d])
        self._bw = bw
        self._row = np.zeros(self.layout.total)
        self._plan: _Plan | None = None

    def prepare(self, count: int) -> None:
        """Make room for ``count`` factors, to be given by :meth:`load`."""
        if self._plan is None or self._plan.count != count:
            # one size at a time: the work arrays are as large as the data
            self._plan = None
            self._plan = _Plan(self._bw, count, self.layout, self.r)

    def load(self, slot: int, chol: FloatArray) -> None:
        """Take the upper banded Cholesky factor ``chol`` (bw + 1, n) as factor ``slot``.

        Only what the recursion needs is kept (``-U[i, i + d] / U[i, i]`` and
        ``1 / U[i, i]^2``), so ``chol`` may be overwritten afterwards.
        """
        assert self._plan is not None, "prepare() first"
        coupling, source = self._plan.coupling, self._plan.source
        bw, n, row = self._bw, chol.shape[1], self._row
        layout = self.layout
        diag = chol[bw]
        # past the end: no coupling and no source, so the window stays zero
        for d in range(1, bw + 1):
            np.divide(chol[bw - d, d:], diag[: n - d], out=row[: n - d])
            np.negative(row[: n - d], out=row[: n - d])
            row[n - d :] = 0.0
            coupling[d - 1, :, slot] = row.reshape(layout.blocks, layout.length).T
        np.square(diag, out=row[:n])
        np.divide(1.0, row[:n], out=row[:n])
        row[n:] = 0.0
        source[:, slot] = row.reshape(layout.blocks, layout.length).T

    def run(self, count: int) -> FloatArray:
        """The traces, shape (count,), of the factors loaded in slots ``0 .. count - 1``."""
        plan = self._plan
        assert plan is not None, "prepare() and load() first"
        if count < plan.count:  # fewer factors than prepared for
            self.prepare(count)
            assert self._plan is not None
            self._plan.coupling[...] = plan.coupling[:, :, :count]
            self._plan.source[...] = plan.source[:, :count]
            plan = self._plan
        acc = _takahashi_sums(plan)
        return np.asarray(acc.sum(axis=1), dtype=np.float64)

    def __call__(self, chol: FloatArray) -> float:
        """The trace, for the upper banded Cholesky factor ``chol`` (bw + 1, n) of A."""
        return float(self.many(chol[None])[0])

    def many(self, chol: FloatArray) -> FloatArray:
        """The traces, shape (C,), for a stack of upper banded factors ``chol`` (C, bw + 1, n)."""
        self.prepare(chol.shape[0])
        for slot, one in enumerate(chol):
            self.load(slot, one)
        return self.run(chol.shape[0])
