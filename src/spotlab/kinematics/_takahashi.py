"""The trace ``tr(inv(A) R)`` of a banded A from its Cholesky factor, by Takahashi's recursion."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


class _Steps:
    """Work arrays of :func:`_takahashi_sums` for C factors and a block layout, reused."""

    def __init__(self, bw: int, count: int, blocks: int) -> None:
        shape = (count, blocks)
        self.prod = np.empty((bw, bw, *shape))
        self.ny = np.empty((bw, *shape))
        self.terms = np.empty((bw + 1, *shape))
        self.windows = (np.empty((bw, bw, *shape)), np.empty((bw, bw, *shape)))
        self.phis = (np.empty((bw, bw, *shape)), np.empty((bw, bw, *shape)))
        #: Contributions to the trace of up to SUM_STEPS steps, after the running sum (row 0).
        self.sums = np.empty((1 + SUM_STEPS * (bw + 1), *shape))


#: Steps of the recursion whose contributions to the trace are summed in one call.
SUM_STEPS = 16


def _companion_step(
    window: FloatArray, new: FloatArray, negc: FloatArray, source: FloatArray, work: _Steps
) -> None:
    """``new = T X T^T + source e1 e1^T`` for stacks of symmetric windows X (bw, bw, ...).

    ``T = [[-c^T], [I, 0]]`` is the companion matrix of one row of the Cholesky
    factor; ``negc`` is ``-c`` (bw, ...). Leaves ``-y = -X c`` (minus the rest of
    that row of the inverse) in ``work.ny``; ``new[0, 0]`` is the corner (a
    diagonal entry of the inverse).

    Notes
    -----
    Each entry is computed by the same floating-point operations in the same
    order as ``y = sum_b X[:, b] c[b]``, ``corner = source + c_0 y_0 + c_1 y_1 +
    ...``: negating a factor negates a product and a sum exactly.
    """
    np.multiply(window, negc[None], out=work.prod)
    np.add.reduce(work.prod, axis=1, out=work.ny)
    work.terms[0] = source
    np.multiply(negc, work.ny, out=work.terms[1:])
    np.add.reduce(work.terms, axis=0, out=new[0, 0])
    new[1:, 1:] = window[:-1, :-1]
    new[0, 1:] = work.ny[:-1]
    new[1:, 0] = work.ny[:-1]


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


def _takahashi_sums(
    layout: _BlockLayout,
    coupling: FloatArray,
    source: FloatArray,
    r: FloatArray,
    work: _Steps,
) -> FloatArray:
    """Takahashi's recursion for all blocks (and factors) at once, summed against R.

    ``coupling`` (bw, length, C, blocks) holds ``-U[i, i + d] / U[i, i]`` and
    ``source`` (length, C, blocks) ``1 / U[i, i]^2`` of C upper banded Cholesky
    factors U, laid out by ``layout`` (:meth:`InverseTrace.load`); ``r``
    (bw + 1, length, blocks) is R's band, laid out alike, off-diagonals doubled.
    Returns ``sum_j corner_j r[0, j] - sum_k y_j[k] r[k + 1, j]`` per factor and
    block, shape (C, blocks): per step j of every block (last sample first),
    ``corner`` is ``inv(A)[i, i]`` and ``-y[k - 1]`` is ``inv(A)[i, i + k]`` for
    ``i = b * length + j``.

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
    arrays are reused, and the coupling is held negated, which saves a
    negation per step and leaves every result unchanged to the last bit. The
    trace's terms are summed in order, SUM_STEPS steps per reduction.
    """
    bw, length, count, blocks = coupling.shape
    # 1. each block's map X -> phi X phi^T + psi, as stacks (bw, bw, C, blocks)
    phi, phi_next = work.phis
    phi[...] = 0.0
    for a in range(bw):
        phi[a, a] = 1.0
    psi, psi_next = work.windows
    psi[...] = 0.0
    for j in range(length - 1, -1, -1):
        negc = coupling[:, j]
        np.multiply(phi, negc[:, None], out=work.prod)
        np.add.reduce(work.prod, axis=0, out=phi_next[0])
        phi_next[1:] = phi[:-1]
        phi, phi_next = phi_next, phi
        _companion_step(psi, psi_next, negc, source[j], work)
        psi, psi_next = psi_next, psi
    # (C, blocks, bw, bw)
    phi_b: FloatArray = np.moveaxis(phi, (2, 3), (0, 1))
    psi_b: FloatArray = np.moveaxis(psi, (2, 3), (0, 1))
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
    window, other = work.windows
    window[...] = np.moveaxis(ends, (2, 3), (0, 1))
    sums = work.sums
    acc = np.zeros((count, blocks))
    used = 1
    for j in range(length - 1, -1, -1):
        _companion_step(window, other, coupling[:, j], source[j], work)
        window, other = other, window
        np.multiply(window[0, 0], r[0, j], out=sums[used])
        np.multiply(work.ny, r[1:, j, None], out=sums[used + 1 : used + 1 + bw])
        used += bw + 1
        if used == sums.shape[0] or j == 0:
            sums[0] = acc
            np.add.reduce(sums[:used], axis=0, out=acc)
            used = 1
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
        self._work: dict[int, tuple[FloatArray, FloatArray, _Steps]] = {}
        self._count = 0

    def prepare(self, count: int) -> None:
        """Make room for ``count`` factors, to be given by :meth:`load`."""
        if count not in self._work:
            shape = (self.layout.length, count, self.layout.blocks)
            # one size at a time: the work arrays are as large as the data
            self._work = {}
            self._work[count] = (
                np.empty((self._bw, *shape)),
                np.empty(shape),
                _Steps(self._bw, count, self.layout.blocks),
            )
        self._count = count

    def load(self, slot: int, chol: FloatArray) -> None:
        """Take the upper banded Cholesky factor ``chol`` (bw + 1, n) as factor ``slot``.

        Only what the recursion needs is kept (``-U[i, i + d] / U[i, i]`` and
        ``1 / U[i, i]^2``), so ``chol`` may be overwritten afterwards.
        """
        coupling, source, _ = self._work[self._count]
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
        coupling, source, work = self._work[self._count]
        if count < self._count:  # fewer factors than prepared for
            self.prepare(count)
            self._work[count][0][...] = coupling[:, :, :count]
            self._work[count][1][...] = source[:, :count]
            coupling, source, work = self._work[count]
        acc = _takahashi_sums(self.layout, coupling, source, self.r, work)
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
