/* Compiled kernel of the GCV smoothing spline (numpy twin: gcv.py, gcv_batch.py,
 * _takahashi.py, _brent.py); the bands it reads are _c_bands.c's.
 *
 * Reinsch's banded system (R + p (m!)^2 Q^T W^-1 Q) delta = Q^T y of half-bandwidth m,
 * its Cholesky factor, the fitted values f = y - p (m!)^2 W^-1 Q delta, the weighted
 * residual sum and the trace tr(inv(A) R) by Takahashi's recursion, at one p (fit) or
 * over a whole GCV search (search: the scan over log10 p, then bounded Brent
 * refinement with the arithmetic of _brent.bounded_brent, two channels' refinements
 * interleaved in the factor, solves and trace: each is a latency-bound chain).
 *
 * Layouts (all C-contiguous float64, checked on entry):
 *   q          (rows, m + 1)  q[j, a] multiplies f[j + a] in the j-th divided difference
 *   r, qwq     (rows, m + 1)  upper band by columns, as LAPACK's column-major band
 *                             storage read column after column: [j, m - d] = A[j - d, j]
 *   w, winv    (n,)           weights and their inverses
 *   y, fitted  (n, k)         samples and fitted values, channels side by side
 * with rows = n - m. Every figure is the twin's to the last bit (the factor, solves and
 * trace in the twin's operations, see "The twin's arithmetic" below; the sums of
 * residuals in numpy's order), so a search visits the twin's points and stops at its p.
 * The numeric work runs without the GIL.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include "_buffers.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#if defined(__GNUC__)
#define INLINE static inline __attribute__((always_inline))
#else
#define INLINE static inline
#endif

/* Calls f(args) with the half-bandwidth as a constant for m = 1 .. 4 (unrolled loops). */
#define BY_BANDWIDTH(m, call)                                                                  \
    switch (m) {                                                                               \
    case 1: {                                                                                  \
        const int BW = 1;                                                                      \
        call;                                                                                  \
    } break;                                                                                   \
    case 2: {                                                                                  \
        const int BW = 2;                                                                      \
        call;                                                                                  \
    } break;                                                                                   \
    case 3: {                                                                                  \
        const int BW = 3;                                                                      \
        call;                                                                                  \
    } break;                                                                                   \
    case 4: {                                                                                  \
        const int BW = 4;                                                                      \
        call;                                                                                  \
    } break;                                                                                   \
    default: {                                                                                 \
        const int BW = m;                                                                      \
        call;                                                                                  \
    } break;                                                                                   \
    }

typedef struct {
    Py_ssize_t n;    /* samples */
    Py_ssize_t rows; /* n - m */
    Py_ssize_t k;    /* channels */
    int m;           /* half-bandwidth */
    Py_ssize_t length, blocks; /* the trace's blocks: samples per block, blocks */
    const double *q, *r, *qwq, *w, *winv;
    double fact2; /* (m!)^2 */
} Problem;

typedef struct {
    double *ab;    /* (rows, m + 1) the factor */
    const double *col; /* (n,) one channel's samples: y or buffer */
    double *buffer;    /* (n,) a channel of several, or NULL for one */
    double *rhs;   /* (rows,) Q^T y of that channel */
    double *delta; /* (rows,) the solution */
    double *sums;  /* (blocks,) the trace's sum of each block */
} Work;

/* ---------------------------------------------------------------- algebra */

/* Up to LANES evaluations at different p run side by side in the factor, the solves and
 * the trace: each is a chain of dependent operations (a division per column, a window
 * per step), so two independent chains interleaved take little longer than one. Every
 * lane's arithmetic is the one-lane arithmetic. */
enum { LANES = 2, MAXBW = 9 };

/* Calls f(args) with the number of lanes as a constant (1 or 2). */
#define BY_LANES(lanes, call)                                                                  \
    if ((lanes) == 1) {                                                                        \
        const int LN = 1;                                                                      \
        call;                                                                                  \
    } else {                                                                                   \
        const int LN = 2;                                                                      \
        call;                                                                                  \
    }

/* The twin's arithmetic, operation for operation, so that every figure is bitwise its:
 *
 * - the factor is LAPACK's dpbtrf as the twin's SciPy calls it (reference LAPACK over
 *   OpenBLAS): for half-bandwidths below its block size 32, dpbtf2, column by column a
 *   square root, a scaling by the reciprocal (dscal with 1 / U[j, j]) and a rank-1
 *   update (dsyr with alpha = -1, which OpenBLAS runs as axpy's y += (alpha x_c) x_r);
 * - the solve is dpbtrs: dtbsv transposed (OpenBLAS: a dot product, then a division)
 *   and dtbsv not transposed (a division, then axpy into the rows above);
 * - OpenBLAS's axpy and dot kernels for these short vectors (length <= m) are fused
 *   multiply-adds on processors with FMA (checked on Haswell/Zen kernels, the ones
 *   SciPy's OpenBLAS picks there): FMA below is C99's fma, one rounding, whatever the
 *   processor (its clones use the instruction where there is one, else libm);
 * - the trace is _takahashi's block recursion (the samples in blocks of ceil(sqrt(rows)),
 *   each block's map composed, the maps chained from the last block, then every block
 *   run from its end, its terms summed in order) and the blocks' sums added as numpy's
 *   pairwise sum adds them. */
#define FMA(a, b, c) fma((a), (b), (c))

/* GCC on x86-64 glibc (ifunc): a clone with the FMA instruction and a default one;
 * elsewhere one build (libm's fma, or the instruction where the target has it) */
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__GLIBC__)
#define FMA_CLONES __attribute__((target_clones("fma", "default")))
#else
#define FMA_CLONES
#endif

/* A = qwq * (p (m!)^2) + r, factored in place as A = U^T U (dpbtf2's operations): U[j, j]
 * on the diagonal slots, U[j, j + t] in A's; fail[q]: 0 or the failing column + 1 of
 * lane q. With `solving`, also the forward solve U^T x = rhs (solve_bw's first half),
 * row j as soon as column j is factored: the two chains overlap. */
INLINE void factor_bw(const Problem *P, const double *p, double *const *ab, Py_ssize_t *fail,
                      const double *const *rhs, double *const *x, const int lanes,
                      const int bw, const int solving)
{
    const int ld = bw + 1;
    const Py_ssize_t n = P->rows;
    double s[LANES];
    /* B[q][r][c] = A[j + r, j + c] (r <= c <= bw) of lane q as updated by the columns
     * before j; the entries of column j + bw are still A's own, assembled here from qwq
     * and r. Columns past the end are zero: they neither couple nor get stored. */
    double B[LANES][MAXBW][MAXBW], l[LANES][MAXBW];
    double z[LANES][MAXBW]; /* the forward solution at j - bw .. j - 1 (zero before 0) */
    for (int q = 0; q < lanes; q++) {
        for (int a = 0; a < bw; a++) {
            z[q][a] = 0.0;
        }
        s[q] = p[q] * P->fact2;
        fail[q] = 0;
        /* the slots above the first columns (rows before 0) are zero: the solves read them */
        for (Py_ssize_t j = 0; j < bw && j < n; j++) {
            for (int t = 0; t < bw - j; t++) {
                ab[q][j * ld + t] = 0.0;
            }
        }
        for (int r = 0; r < bw; r++) {
            for (int c = r; c < bw; c++) {
                const Py_ssize_t at = (Py_ssize_t)c * ld + bw - (c - r);
                B[q][r][c] = c < n ? P->qwq[at] * s[q] + P->r[at] : 0.0;
            }
        }
    }
    for (Py_ssize_t j = 0; j < n; j++) {
        const Py_ssize_t col = j + bw;
        for (int q = 0; q < lanes; q++) {
            for (int r = 0; r <= bw; r++) {
                const Py_ssize_t at = col * ld + r; /* A[j + r, j + bw] */
                B[q][r][bw] = col < n ? P->qwq[at] * s[q] + P->r[at] : 0.0;
            }
            double ajj = B[q][0][0];
            if (!(ajj > 0.0) && fail[q] == 0) {
                fail[q] = j + 1; /* the lane goes on, its figures are not used */
            }
            ajj = sqrt(ajj);
            ab[q][j * ld + bw] = ajj;
            if (solving) {
                double dot = 0.0;
                for (int a = 0; a < bw; a++) { /* rows j - bw .. j - 1 of column j */
                    dot = FMA(z[q][a], ab[q][j * ld + a], dot);
                }
                const double temp = (rhs[q][j] - dot) / ajj;
                for (int a = 0; a + 1 < bw; a++) {
                    z[q][a] = z[q][a + 1];
                }
                z[q][bw - 1] = temp;
                x[q][j] = temp;
            }
            const double rec = 1.0 / ajj;
            for (int t = 1; t <= bw; t++) {
                l[q][t] = B[q][0][t] * rec;
            }
            for (int c = 1; c <= bw; c++) {
                const double neg = -1.0 * l[q][c];
                for (int r = 1; r <= c; r++) {
                    B[q][r][c] = FMA(neg, l[q][r], B[q][r][c]);
                }
                if (j + c < n) {
                    ab[q][(j + c) * ld + bw - c] = l[q][c];
                }
            }
            for (int r = 0; r < bw; r++) {
                for (int c = r; c < bw; c++) {
                    B[q][r][c] = B[q][r + 1][c + 1];
                }
            }
        }
    }
}

/* The factors of the lanes; with rhs (not NULL) the forward solves into x too. */
FMA_CLONES static void factor_lanes(const Problem *P, const double *p, double *const *ab,
                                    Py_ssize_t *fail, const double *const *rhs,
                                    double *const *x, int lanes)
{
    if (rhs != NULL) {
        BY_LANES(lanes, BY_BANDWIDTH(P->m, factor_bw(P, p, ab, fail, rhs, x, LN, BW, 1)));
    } else {
        BY_LANES(lanes, BY_BANDWIDTH(P->m, factor_bw(P, p, ab, fail, rhs, x, LN, BW, 0)));
    }
}

static Py_ssize_t factor(const Problem *P, double p, double *ab)
{
    Py_ssize_t fail = 0;
    factor_lanes(P, &p, &ab, &fail, NULL, NULL, 1);
    return fail;
}

/* x[q] = inv(U^T U) rhs[q] (dpbtrs): U^T z = rhs forward, then U x = z backward. */
INLINE void solve_bw(const Problem *P, const double *const *ab, const double *const *rhs,
                     double *const *x, const int lanes, const int bw)
{
    const int ld = bw + 1;
    const Py_ssize_t n = P->rows;
    /* z[q][a] = lane q's solution at j - bw + a, kept in registers (zero before the start,
     * where the factor's slots are zero too: the dot product's leading terms are then
     * exact zeros, as if it were shorter) */
    double z[LANES][MAXBW];
    for (int q = 0; q < lanes; q++) {
        for (int a = 0; a < bw; a++) {
            z[q][a] = 0.0;
        }
    }
    for (Py_ssize_t j = 0; j < n; j++) {
        for (int q = 0; q < lanes; q++) {
            double dot = 0.0;
            for (int a = 0; a < bw; a++) { /* rows j - bw .. j - 1 */
                dot = FMA(z[q][a], ab[q][j * ld + a], dot);
            }
            const double temp = (rhs[q][j] - dot) / ab[q][j * ld + bw];
            for (int a = 0; a + 1 < bw; a++) {
                z[q][a] = z[q][a + 1];
            }
            z[q][bw - 1] = temp;
            x[q][j] = temp;
        }
    }
    /* backward: z[q][a] = the solution at j + 1 + a (zero past the end); row j takes the
     * axpy of column j + bw first, j + 1 last */
    for (int q = 0; q < lanes; q++) {
        for (int a = 0; a < bw; a++) {
            z[q][a] = 0.0;
        }
    }
    for (Py_ssize_t j = n - 1; j >= 0; j--) {
        for (int q = 0; q < lanes; q++) {
            double temp = x[q][j];
            for (int a = bw - 1; a >= 0; a--) {
                const Py_ssize_t i = j + 1 + a;
                if (i < n) {
                    temp = FMA(-z[q][a], ab[q][i * ld + bw - (a + 1)], temp);
                }
            }
            temp /= ab[q][j * ld + bw];
            for (int a = bw - 1; a > 0; a--) {
                z[q][a] = z[q][a - 1];
            }
            z[q][0] = temp;
            x[q][j] = temp;
        }
    }
}

FMA_CLONES static void solve_lanes(const Problem *P, const double *const *ab,
                                   const double *const *rhs, double *const *x, int lanes)
{
    BY_LANES(lanes, BY_BANDWIDTH(P->m, solve_bw(P, ab, rhs, x, LN, BW)));
}

static void solve(const Problem *P, const double *ab, const double *rhs, double *x)
{
    solve_lanes(P, &ab, &rhs, &x, 1);
}

/* numpy's pairwise summation (its order of additions for float64). */
static double pairwise(const double *a, Py_ssize_t n)
{
    if (n < 8) {
        double res = 0.0;
        for (Py_ssize_t i = 0; i < n; i++) {
            res += a[i];
        }
        return res;
    }
    if (n <= 128) {
        double r[8];
        for (int j = 0; j < 8; j++) {
            r[j] = a[j];
        }
        Py_ssize_t i;
        for (i = 8; i < n - (n % 8); i += 8) {
            for (int j = 0; j < 8; j++) {
                r[j] += a[i + j];
            }
        }
        double res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for (; i < n; i++) {
            res += a[i];
        }
        return res;
    }
    Py_ssize_t n2 = n / 2;
    n2 -= n2 % 8;
    return pairwise(a, n2) + pairwise(a + n2, n - n2);
}

/* Row i's -U[i, i + 1 + a] / U[i, i] (a < bw) and 1 / U[i, i]^2 as _takahashi's load
 * computes them; zero past the end (i >= n, or i + 1 + a >= n). */
INLINE void coupling_at(const double *ab, Py_ssize_t n, Py_ssize_t i, double *negc,
                        double *source, const int bw)
{
    const int ld = bw + 1;
    if (i >= n) {
        for (int a = 0; a < bw; a++) {
            negc[a] = 0.0;
        }
        *source = 0.0;
        return;
    }
    const double d = ab[i * ld + bw];
    for (int a = 0; a < bw; a++) {
        const Py_ssize_t jj = i + 1 + a;
        negc[a] = jj < n ? -(ab[jj * ld + bw - (a + 1)] / d) : 0.0;
    }
    *source = 1.0 / (d * d);
}

/* _takahashi._companion_step on one window: X <- T X T^T + source e1 e1^T, with
 * ny = X (-c) (row i of the inverse beyond the diagonal) left in ny. */
INLINE void companion(double (*X)[MAXBW], const double *negc, double source, double *ny,
                      const int bw)
{
    for (int a = 0; a < bw; a++) {
        double sum = X[a][0] * negc[0];
        for (int b = 1; b < bw; b++) {
            sum += X[a][b] * negc[b];
        }
        ny[a] = sum;
    }
    double corner = source;
    for (int a = 0; a < bw; a++) {
        corner += negc[a] * ny[a];
    }
    for (int a = bw - 1; a > 0; a--) {
        for (int b = bw - 1; b > 0; b--) {
            X[a][b] = X[a - 1][b - 1];
        }
    }
    X[0][0] = corner;
    for (int a = 1; a < bw; a++) {
        X[0][a] = ny[a - 1];
        X[a][0] = ny[a - 1];
    }
}

/* tr(inv(A) R) of lanes' factors by _takahashi's block recursion (Hutchinson & de Hoog
 * 1985): sums[q] holds lane q's per-block sums (P->blocks). The blocks run last first:
 * block b from its end window (its terms summed in order), then block b's map
 * X -> phi X phi^T + psi composed from its steps gives block b - 1's end window. */
INLINE void trace_bw(const Problem *P, const double *const *ab, double *const *sums,
                     double *out, double *const *x, const int lanes, const int bw,
                     const int solving)
{
    const int ld = bw + 1;
    const Py_ssize_t n = P->rows, length = P->length;
    double win[LANES][MAXBW][MAXBW], phi[LANES][MAXBW][MAXBW], psi[LANES][MAXBW][MAXBW];
    double end[LANES][MAXBW][MAXBW], left[MAXBW][MAXBW];
    double negc[MAXBW], ny[MAXBW], ro[MAXBW];
    /* with `solving`, solve_bw's backward half in the same sweep (i descending): zb[q][a]
     * is the solution at i + 1 + a (zero past the end) */
    double zb[LANES][MAXBW];
    for (int q = 0; q < lanes; q++) {
        for (int a = 0; a < bw; a++) {
            zb[q][a] = 0.0;
        }
        for (int a = 0; a < bw; a++) {
            for (int b = 0; b < bw; b++) {
                end[q][a][b] = 0.0;
            }
        }
    }
    for (Py_ssize_t blk = P->blocks - 1; blk >= 0; blk--) {
        for (int q = 0; q < lanes; q++) {
            for (int a = 0; a < bw; a++) {
                for (int b = 0; b < bw; b++) {
                    win[q][a][b] = end[q][a][b];
                    phi[q][a][b] = a == b ? 1.0 : 0.0;
                    psi[q][a][b] = 0.0;
                }
            }
        }
        double acc[LANES];
        for (int q = 0; q < lanes; q++) {
            acc[q] = 0.0;
        }
        for (Py_ssize_t j = length - 1; j >= 0; j--) {
            const Py_ssize_t i = blk * length + j;
            /* R's band at i, the off-diagonals doubled (both triangles) */
            const double rd = i < n ? P->r[i * ld + bw] * 1.0 : 0.0;
            for (int a = 0; a < bw; a++) {
                const Py_ssize_t jj = i + 1 + a;
                ro[a] = jj < n ? P->r[jj * ld + bw - (a + 1)] * 2.0 : 0.0;
            }
            for (int q = 0; q < lanes; q++) {
                if (solving && i < n) {
                    double temp = x[q][i];
                    for (int a = bw - 1; a >= 0; a--) {
                        if (i + 1 + a < n) {
                            temp = FMA(-zb[q][a], ab[q][(i + 1 + a) * ld + bw - (a + 1)], temp);
                        }
                    }
                    temp /= ab[q][i * ld + bw];
                    for (int a = bw - 1; a > 0; a--) {
                        zb[q][a] = zb[q][a - 1];
                    }
                    zb[q][0] = temp;
                    x[q][i] = temp;
                }
                double source;
                coupling_at(ab[q], n, i, negc, &source, bw);
                /* the trace's terms at i, in the twin's order */
                companion(win[q], negc, source, ny, bw);
                acc[q] += win[q][0][0] * rd;
                for (int a = 0; a < bw; a++) {
                    acc[q] += ny[a] * ro[a];
                }
                if (blk == 0) {
                    continue; /* no block before the first: its map is not needed */
                }
                /* the block's map: phi <- T phi, psi <- T psi T^T + source e1 e1^T */
                for (int b = 0; b < bw; b++) {
                    double sum = phi[q][0][b] * negc[0];
                    for (int a = 1; a < bw; a++) {
                        sum += phi[q][a][b] * negc[a];
                    }
                    ny[b] = sum;
                }
                for (int a = bw - 1; a > 0; a--) {
                    for (int b = 0; b < bw; b++) {
                        phi[q][a][b] = phi[q][a - 1][b];
                    }
                }
                for (int b = 0; b < bw; b++) {
                    phi[q][0][b] = ny[b];
                }
                companion(psi[q], negc, source, ny, bw);
            }
        }
        for (int q = 0; q < lanes; q++) {
            sums[q][blk] = acc[q];
            if (blk == 0) {
                continue;
            }
            /* block blk - 1's end: phi end phi^T + psi (numpy's matmul of these strided
             * bw x bw stacks: each entry fused multiply-adds in order from zero, checked) */
            for (int a = 0; a < bw; a++) {
                for (int c = 0; c < bw; c++) {
                    double sum = 0.0;
                    for (int t = 0; t < bw; t++) {
                        sum = FMA(phi[q][a][t], end[q][t][c], sum);
                    }
                    left[a][c] = sum;
                }
            }
            for (int a = 0; a < bw; a++) {
                for (int c = 0; c < bw; c++) {
                    double sum = 0.0;
                    for (int t = 0; t < bw; t++) {
                        sum = FMA(left[a][t], phi[q][c][t], sum);
                    }
                    end[q][a][c] = sum + psi[q][a][c];
                }
            }
        }
    }
    for (int q = 0; q < lanes; q++) {
        out[q] = pairwise(sums[q], P->blocks);
    }
}

/* The traces of the lanes; with x (not NULL, forward solutions) the backward solves too. */
FMA_CLONES static void trace_lanes(const Problem *P, const double *const *ab,
                                   double *const *sums, double *out, double *const *x,
                                   int lanes)
{
    if (x != NULL) {
        BY_LANES(lanes, BY_BANDWIDTH(P->m, trace_bw(P, ab, sums, out, x, LN, BW, 1)));
    } else {
        BY_LANES(lanes, BY_BANDWIDTH(P->m, trace_bw(P, ab, sums, out, x, LN, BW, 0)));
    }
}

static double trace(const Problem *P, const double *ab, double *sums)
{
    double out = 0.0;
    trace_lanes(P, &ab, &sums, &out, NULL, 1);
    return out;
}

/* Q^T y for one channel. */
static void qt_times(const Problem *P, const double *y, double *out)
{
    const int ld = P->m + 1;
    for (Py_ssize_t j = 0; j < P->rows; j++) {
        double acc = 0.0;
        for (int a = 0; a < ld; a++) {
            acc += P->q[j * ld + a] * y[j + a];
        }
        out[j] = acc;
    }
}

/* One fit's residuals: f = y - s W^-1 Q delta (s = p (m!)^2), written to fitted (stride)
 * if given, and the terms w (y - f)^2. */
typedef struct {
    const Problem *P;
    double s;
    const double *y, *delta;
    double *fitted;
    Py_ssize_t stride;
} Residuals;

/* terms[i - i0] = w_i (y_i - f_i)^2 for i in i0 .. i0 + count - 1. */
INLINE void residual_terms_bw(const Residuals *R, Py_ssize_t i0, Py_ssize_t count,
                              double *terms, const int bw)
{
    const Problem *P = R->P;
    const int ld = bw + 1;
    const Py_ssize_t rows = P->rows;
    for (Py_ssize_t i = i0; i < i0 + count; i++) {
        /* (Q delta)_i = sum over a of q[i - a, a] delta[i - a], a increasing */
        double qd = 0.0;
        if (i >= bw && i < rows) {
            for (int a = 0; a < ld; a++) {
                qd += P->q[(i - a) * ld + a] * R->delta[i - a];
            }
        } else {
            for (int a = 0; a < ld; a++) {
                Py_ssize_t j = i - a;
                if (j >= 0 && j < rows) {
                    qd += P->q[j * ld + a] * R->delta[j];
                }
            }
        }
        const double f = R->y[i] - (R->s * P->winv[i]) * qd;
        const double res = R->y[i] - f;
        terms[i - i0] = P->w[i] * (res * res);
        if (R->fitted != NULL) {
            R->fitted[i * R->stride] = f;
        }
    }
}

/* sum of the terms of i0 .. i0 + n - 1, split as numpy's pairwise sum splits an array of n. */
static double residual_sum(const Residuals *R, Py_ssize_t i0, Py_ssize_t n)
{
    if (n <= 128) {
        double terms[128];
        BY_BANDWIDTH(R->P->m, residual_terms_bw(R, i0, n, terms, BW));
        return pairwise(terms, n);
    }
    Py_ssize_t n2 = n / 2;
    n2 -= n2 % 8;
    return residual_sum(R, i0, n2) + residual_sum(R, i0 + n2, n - n2);
}

/* sum(w (y - f)^2) with f = y - p (m!)^2 W^-1 Q delta; f written to fitted (stride) if given. */
/* the same terms added one after the other (numpy's sum over the rows of an (n, k > 1)
 * array, as the twin's statistics sums several channels at once) */
static double residual_sum_in_order(const Residuals *R)
{
    double terms[128], sum = 0.0;
    for (Py_ssize_t i0 = 0; i0 < R->P->n; i0 += 128) {
        const Py_ssize_t count = R->P->n - i0 < 128 ? R->P->n - i0 : 128;
        BY_BANDWIDTH(R->P->m, residual_terms_bw(R, i0, count, terms, BW));
        for (Py_ssize_t i = 0; i < count; i++) {
            sum += terms[i];
        }
    }
    return sum;
}

static double residuals(const Problem *P, double p, const double *y, const double *delta,
                        double *fitted, Py_ssize_t stride, int in_order)
{
    const Residuals R = {P, p * P->fact2, y, delta, fitted, stride};
    return in_order ? residual_sum_in_order(&R) : residual_sum(&R, 0, P->n);
}

/* Channel ch's samples into work->col (y itself for one channel) and Q^T of them into
 * work->rhs. */
static void load_channel(const Problem *P, const double *y, Py_ssize_t ch, Work *wk)
{
    if (P->k == 1) {
        wk->col = y;
    } else {
        for (Py_ssize_t i = 0; i < P->n; i++) {
            wk->buffer[i] = y[i * P->k + ch];
        }
        wk->col = wk->buffer;
    }
    qt_times(P, wk->col, wk->rhs);
}

/* GCV of the loaded channel from sum(w r^2) and n - dof, as gcv._Criterion computes it. */
static double criterion(const Problem *P, double rss, double rdof)
{
    const double n = (double)P->n;
    rss = (rss / n) * n;
    rdof = n - (n - rdof);
    if (rdof < n * 1e-9) {
        return INFINITY;
    }
    const double v = rdof / n;
    return (rss / n) / (v * v);
}

/* n - dof, floored at the smallest normal number, from the factor. */
static double residual_dof(const Problem *P, const Work *wk)
{
    double rdof = (double)P->rows - trace(P, wk->ab, wk->sums);
    return rdof > DBL_MIN ? rdof : DBL_MIN;
}

/* The criteria of the channels loaded in wk[0 .. lanes - 1], each at its own log10 p
 * (infinite where the factor fails), the lanes side by side. */
static void evaluate_lanes(const Problem *P, Work *const *wk, const double *log_p, double *f,
                           int lanes)
{
    double p[LANES], rdof[LANES];
    double *ab[LANES], *delta[LANES], *sums[LANES];
    const double *abc[LANES], *rhs[LANES];
    Py_ssize_t fail[LANES];
    for (int q = 0; q < lanes; q++) {
        p[q] = pow(10.0, log_p[q]);
        ab[q] = wk[q]->ab;
        abc[q] = wk[q]->ab;
        rhs[q] = wk[q]->rhs;
        delta[q] = wk[q]->delta;
        sums[q] = wk[q]->sums;
    }
    /* the factor with the forward solve, the trace with the backward one: the solves'
     * chains overlap the others' (each lane's arithmetic that of factor, solve, trace) */
    factor_lanes(P, p, ab, fail, rhs, delta, lanes);
    trace_lanes(P, abc, sums, rdof, delta, lanes);
    for (int q = 0; q < lanes; q++) {
        if (fail[q] != 0) {
            f[q] = INFINITY;
            continue;
        }
        const double rss = residuals(P, p[q], wk[q]->col, wk[q]->delta, NULL, 0, 0);
        double rd = (double)P->rows - rdof[q];
        f[q] = criterion(P, rss, rd > DBL_MIN ? rd : DBL_MIN);
    }
}

/* ------------------------------------------------------------ Brent search */

/* _brent.bounded_brent (SciPy's minimize_scalar(method="bounded")) as a state machine:
 * brent_begin gives the first point, brent_step takes the value at the last point and
 * gives the next (1) or ends the search (0: the minimiser in xf, its value in fx). */
typedef struct {
    double a, b, fulc, nfc, xf, rat, e, fx, ffulc, fnfc, xm, tol1, tol2, xatol, x;
    int num;
} Brent;

static const int BRENT_MAXFUN = 500;

static double brent_begin(Brent *s, double lo, double hi, double xatol)
{
    const double golden_c = 0.5 * (3.0 - sqrt(5.0));
    s->a = lo;
    s->b = hi;
    s->xatol = xatol;
    s->fulc = s->a + golden_c * (s->b - s->a);
    s->nfc = s->xf = s->fulc;
    s->rat = s->e = 0.0;
    s->num = 0;
    s->x = s->xf;
    return s->x;
}

static int brent_step(Brent *s, double f)
{
    const double sqrt_eps = sqrt(2.2e-16);
    const double golden_c = 0.5 * (3.0 - sqrt(5.0));
    if (s->num == 0) {
        s->fx = f;
        s->num = 1;
        s->ffulc = s->fnfc = f;
    } else {
        const double x = s->x, fu = f;
        s->num += 1;
        if (fu <= s->fx) {
            if (x >= s->xf) {
                s->a = s->xf;
            } else {
                s->b = s->xf;
            }
            s->fulc = s->nfc;
            s->ffulc = s->fnfc;
            s->nfc = s->xf;
            s->fnfc = s->fx;
            s->xf = x;
            s->fx = fu;
        } else {
            if (x < s->xf) {
                s->a = x;
            } else {
                s->b = x;
            }
            if (fu <= s->fnfc || s->nfc == s->xf) {
                s->fulc = s->nfc;
                s->ffulc = s->fnfc;
                s->nfc = x;
                s->fnfc = fu;
            } else if (fu <= s->ffulc || s->fulc == s->xf || s->fulc == s->nfc) {
                s->fulc = x;
                s->ffulc = fu;
            }
        }
    }
    s->xm = 0.5 * (s->a + s->b);
    s->tol1 = sqrt_eps * fabs(s->xf) + s->xatol / 3.0;
    s->tol2 = 2.0 * s->tol1;
    if (s->num > 1 && s->num >= BRENT_MAXFUN) {
        return 0;
    }
    if (!(fabs(s->xf - s->xm) > s->tol2 - 0.5 * (s->b - s->a))) {
        return 0;
    }
    const double xf = s->xf, fx = s->fx, tol1 = s->tol1, tol2 = s->tol2;
    int golden = 1;
    if (fabs(s->e) > tol1) {
        golden = 0;
        double r = (xf - s->nfc) * (fx - s->ffulc);
        double q = (xf - s->fulc) * (fx - s->fnfc);
        double p = (xf - s->fulc) * q - (xf - s->nfc) * r;
        q = 2.0 * (q - r);
        if (q > 0.0) {
            p = -p;
        }
        q = fabs(q);
        r = s->e;
        s->e = s->rat;
        if (fabs(p) < fabs(0.5 * q * r) && q * (s->a - xf) < p && p < q * (s->b - xf)) {
            s->rat = (p + 0.0) / q;
            const double x = xf + s->rat;
            if ((x - s->a) < tol2 || (s->b - x) < tol2) {
                s->rat = (s->xm - xf >= 0.0) ? tol1 : -tol1;
            }
        } else {
            golden = 1;
        }
    }
    if (golden) {
        s->e = (xf >= s->xm) ? (s->a - xf) : (s->b - xf);
        s->rat = golden_c * s->e;
    }
    double step = fabs(s->rat);
    if (tol1 > step) {
        step = tol1;
    }
    s->x = xf + ((s->rat >= 0.0) ? step : -step);
    return 1;
}

/* The channels' refinements after the scan (values (g_count, k)), two at a time in the
 * lanes, and each channel's fit at its chosen log10 p. */
typedef struct {
    const Problem *P;
    const double *y, *grid, *values;
    Py_ssize_t g_count, next;
    double xatol;
    double *fitted, *log_p, *rss, *rdof;
    Py_ssize_t failures;
} Refine;

typedef struct {
    Work *wk;
    Py_ssize_t ch, best;
    Brent s;
} Lane;

/* Channel ch (loaded in wk) fitted at log10 p = chosen. */
static void finish(Refine *R, Work *wk, Py_ssize_t ch, double chosen)
{
    const Problem *P = R->P;
    R->log_p[ch] = chosen;
    const double p = pow(10.0, chosen);
    if (factor(P, p, wk->ab) != 0) {
        R->rss[ch] = NAN;
        R->rdof[ch] = NAN;
        R->failures++;
        return;
    }
    solve(P, wk->ab, wk->rhs, wk->delta);
    R->rss[ch] = residuals(P, p, wk->col, wk->delta, R->fitted + ch, P->k, 0);
    R->rdof[ch] = residual_dof(P, wk);
}

/* The next channel with a search into the lane (0 when none is left); channels without
 * a finite value on the grid are fitted at its end, as the twin does. */
static int next_channel(Refine *R, Lane *lane)
{
    const Problem *P = R->P;
    const Py_ssize_t k = P->k, g_count = R->g_count;
    while (R->next < k) {
        const Py_ssize_t ch = R->next++;
        Py_ssize_t best = -1;
        for (Py_ssize_t g = 0; g < g_count; g++) {
            const double v = R->values[g * k + ch];
            if (isfinite(v) && (best < 0 || v < R->values[best * k + ch])) {
                best = g;
            }
        }
        load_channel(P, R->y, ch, lane->wk);
        if (best < 0) {
            finish(R, lane->wk, ch, R->grid[g_count - 1]);
            continue;
        }
        lane->ch = ch;
        lane->best = best;
        const double lo = R->grid[best > 0 ? best - 1 : 0];
        const double hi = R->grid[best + 1 < g_count ? best + 1 : g_count - 1];
        brent_begin(&lane->s, lo, hi, R->xatol);
        return 1;
    }
    return 0;
}

static void refine(Refine *R, Work *wks, int lanes)
{
    const Py_ssize_t k = R->P->k;
    Lane lane[LANES];
    int active[LANES];
    for (int q = 0; q < lanes; q++) {
        lane[q].wk = &wks[q];
        active[q] = next_channel(R, &lane[q]);
    }
    for (;;) {
        Work *wk[LANES];
        double x[LANES], f[LANES];
        int which[LANES], count = 0;
        for (int q = 0; q < lanes; q++) {
            if (active[q]) {
                which[count] = q;
                wk[count] = lane[q].wk;
                x[count] = lane[q].s.x;
                count++;
            }
        }
        if (count == 0) {
            break;
        }
        evaluate_lanes(R->P, wk, x, f, count);
        for (int i = 0; i < count; i++) {
            Lane *ln = &lane[which[i]];
            if (brent_step(&ln->s, f[i])) {
                continue;
            }
            const double bound = R->values[ln->best * k + ln->ch];
            finish(R, ln->wk, ln->ch, ln->s.fx <= bound ? ln->s.xf : R->grid[ln->best]);
            active[which[i]] = next_channel(R, ln);
        }
    }
}

/* ------------------------------------------------------------ Python glue */

static int work_alloc(const Problem *P, Work *wk)
{
    wk->ab = malloc(sizeof(double) * (size_t)(P->rows * (P->m + 1)));
    wk->buffer = P->k > 1 ? malloc(sizeof(double) * (size_t)P->n) : NULL;
    wk->rhs = malloc(sizeof(double) * (size_t)P->rows);
    wk->delta = malloc(sizeof(double) * (size_t)P->rows);
    wk->sums = malloc(sizeof(double) * (size_t)P->blocks);
    return wk->ab && (wk->buffer || P->k == 1) && wk->rhs && wk->delta && wk->sums;
}

static void work_free(Work *wk)
{
    free(wk->ab);
    free(wk->buffer);
    free(wk->rhs);
    free(wk->delta);
    free(wk->sums);
}

enum { B_Q, B_R, B_QWQ, B_W, B_WINV, B_Y, B_OUT, B_COUNT };

/* Parse the problem's arrays (q, r, qwq, w, winv, y, fitted) into P and views. */
static int get_problem(PyObject *const *objs, int m, Py_ssize_t n, Py_ssize_t k, double fact2,
                       Problem *P, Py_buffer *views)
{
    static const char *names[B_COUNT] = {"q", "r", "qwq", "w", "winv", "y", "fitted"};
    if (m < 1 || m > 8 || n <= m || k < 1) {
        PyErr_SetString(PyExc_ValueError, "need 1 <= m <= 8, n > m and k >= 1");
        return -1;
    }
    P->n = n;
    P->rows = n - m;
    P->k = k;
    P->m = m;
    P->fact2 = fact2;
    /* _takahashi._BlockLayout: ceil(sqrt(rows)) samples per block */
    Py_ssize_t length = (Py_ssize_t)ceil(sqrt((double)P->rows));
    P->length = length < 1 ? 1 : (length > P->rows ? P->rows : length);
    P->blocks = (P->rows + P->length - 1) / P->length;
    Py_ssize_t counts[B_COUNT] = {P->rows * (m + 1), P->rows * (m + 1), P->rows * (m + 1),
                                  n,                 n,                 n * k,
                                  n * k};
    for (int i = 0; i < B_COUNT; i++) {
        if (get_buffer(objs[i], &views[i], counts[i], i == B_OUT, names[i]) != 0) {
            for (int j = 0; j < i; j++) {
                PyBuffer_Release(&views[j]);
            }
            return -1;
        }
    }
    P->q = views[B_Q].buf;
    P->r = views[B_R].buf;
    P->qwq = views[B_QWQ].buf;
    P->w = views[B_W].buf;
    P->winv = views[B_WINV].buf;
    return 0;
}

PyDoc_STRVAR(fit_doc,
             "fit(q, r, qwq, w, winv, y, fitted, rss, m, n, k, p, fact2, want_trace)\n"
             "--\n\n"
             "Fit the k channels of y (n, k) at smoothing parameter p: fitted values into\n"
             "fitted (n, k), sum(w r^2) of each channel into rss (k,) (numpy's order: pairwise\n"
             "for one channel, in order for several). Returns n - m - trace\n"
             "(n - dof, floored at the smallest normal float) when want_trace, else 0.0;\n"
             "None when the banded matrix is not positive definite.");

static PyObject *gcv_fit(PyObject *self, PyObject *args)
{
    PyObject *objs[B_COUNT], *rss_obj;
    int m, want_trace;
    Py_ssize_t n, k;
    double p, fact2;
    (void)self;
    if (!PyArg_ParseTuple(args, "OOOOOOOOinnddp:fit", &objs[0], &objs[1], &objs[2], &objs[3],
                          &objs[4], &objs[5], &objs[6], &rss_obj, &m, &n, &k, &p, &fact2,
                          &want_trace)) {
        return NULL;
    }
    Problem P;
    Py_buffer views[B_COUNT], rss_view;
    if (get_problem(objs, m, n, k, fact2, &P, views) != 0) {
        return NULL;
    }
    if (get_buffer(rss_obj, &rss_view, k, 1, "rss") != 0) {
        release(views, B_COUNT);
        return NULL;
    }
    Work wk;
    int ok = work_alloc(&P, &wk);
    Py_ssize_t failed = 0;
    double rdof = 0.0;
    if (ok) {
        const double *y = views[B_Y].buf;
        double *fitted = views[B_OUT].buf, *rss = rss_view.buf;
        Py_BEGIN_ALLOW_THREADS;
        if (k == 1 && want_trace) {
            /* one channel: the solves fused into the factor and the trace */
            double *ab = wk.ab, *delta = wk.delta, *sums = wk.sums, tr = 0.0;
            const double *abc = wk.ab, *rhs = wk.rhs;
            load_channel(&P, y, 0, &wk);
            factor_lanes(&P, &p, &ab, &failed, &rhs, &delta, 1);
            if (failed == 0) {
                trace_lanes(&P, &abc, &sums, &tr, &delta, 1);
                rss[0] = residuals(&P, p, wk.col, wk.delta, fitted, 1, 0);
                rdof = (double)P.rows - tr;
                rdof = rdof > DBL_MIN ? rdof : DBL_MIN;
            }
        } else if ((failed = factor(&P, p, wk.ab)) == 0) {
            for (Py_ssize_t ch = 0; ch < k; ch++) {
                load_channel(&P, y, ch, &wk);
                solve(&P, wk.ab, wk.rhs, wk.delta);
                rss[ch] = residuals(&P, p, wk.col, wk.delta, fitted + ch, k, k > 1);
            }
            if (want_trace) {
                rdof = residual_dof(&P, &wk);
            }
        }
        Py_END_ALLOW_THREADS;
    }
    work_free(&wk);
    release(views, B_COUNT);
    PyBuffer_Release(&rss_view);
    if (!ok) {
        return PyErr_NoMemory();
    }
    if (failed != 0) {
        Py_RETURN_NONE;
    }
    return PyFloat_FromDouble(rdof);
}

PyDoc_STRVAR(search_doc,
             "search(q, r, qwq, w, winv, y, fitted, grid, log_p, rss, rdof, m, n, k, fact2, "
             "xatol)\n"
             "--\n\n"
             "GCV search of each channel of y (n, k): the criterion at every point of grid\n"
             "(log10 p, one factor per point for all channels), then bounded Brent on the\n"
             "two grid steps around each channel's smallest value, kept when not worse.\n"
             "Writes each channel's log10 p (k,), its fit at that p into fitted (n, k),\n"
             "sum(w r^2) into rss (k,) and n - dof into rdof (k,). Returns the number of\n"
             "channels whose final banded matrix was not positive definite (their rss and\n"
             "rdof are NaN).");

static PyObject *gcv_search(PyObject *self, PyObject *args)
{
    PyObject *objs[B_COUNT], *grid_obj, *logp_obj, *rss_obj, *rdof_obj;
    int m;
    Py_ssize_t n, k, g_count;
    double fact2, xatol;
    (void)self;
    if (!PyArg_ParseTuple(args, "OOOOOOOOOOOinndd:search", &objs[0], &objs[1], &objs[2],
                          &objs[3], &objs[4], &objs[5], &objs[6], &grid_obj, &logp_obj, &rss_obj,
                          &rdof_obj, &m, &n, &k, &fact2, &xatol)) {
        return NULL;
    }
    g_count = PyObject_Length(grid_obj);
    if (g_count < 1) {
        if (!PyErr_Occurred()) {
            PyErr_SetString(PyExc_ValueError, "grid: empty");
        }
        return NULL;
    }
    Problem P;
    Py_buffer views[B_COUNT], extra[4];
    if (get_problem(objs, m, n, k, fact2, &P, views) != 0) {
        return NULL;
    }
    PyObject *more[4] = {grid_obj, logp_obj, rss_obj, rdof_obj};
    static const char *names[4] = {"grid", "log_p", "rss", "rdof"};
    for (int i = 0; i < 4; i++) {
        if (get_buffer(more[i], &extra[i], i == 0 ? g_count : k, i > 0, names[i]) != 0) {
            release(extra, i);
            release(views, B_COUNT);
            return NULL;
        }
    }
    Work wk[LANES];
    memset(wk, 0, sizeof wk);
    const int lanes = k > 1 ? LANES : 1;
    double *values = malloc(sizeof(double) * (size_t)(g_count * k));
    int ok = values != NULL;
    for (int q = 0; q < lanes; q++) {
        ok = work_alloc(&P, &wk[q]) && ok;
    }
    Py_ssize_t failures = 0;
    if (ok) {
        const double *y = views[B_Y].buf, *grid = extra[0].buf;
        double *fitted = views[B_OUT].buf, *log_p = extra[1].buf, *rss = extra[2].buf;
        double *rdof = extra[3].buf;
        Py_BEGIN_ALLOW_THREADS;
        /* 1. the scan: one factor and one trace per grid point for all channels */
        for (Py_ssize_t g = 0; g < g_count && k == 1; g++) {
            /* one channel: the solves fused into the factor and the trace */
            Work *one = &wk[0];
            load_channel(&P, y, 0, one);
            evaluate_lanes(&P, &one, &grid[g], &values[g], 1);
        }
        for (Py_ssize_t g = 0; g < g_count && k > 1; g++) {
            const double p = pow(10.0, grid[g]);
            if (factor(&P, p, wk[0].ab) != 0) {
                for (Py_ssize_t ch = 0; ch < k; ch++) {
                    values[g * k + ch] = INFINITY;
                }
                continue;
            }
            const double rd = residual_dof(&P, &wk[0]);
            /* the channels' solves two at a time through the one factor */
            for (Py_ssize_t ch = 0; ch < k; ch += LANES) {
                const int count = k - ch < LANES ? (int)(k - ch) : LANES;
                const double *abs[LANES], *rhs[LANES];
                double *delta[LANES];
                for (int q = 0; q < count; q++) {
                    load_channel(&P, y, ch + q, &wk[q]);
                    abs[q] = wk[0].ab;
                    rhs[q] = wk[q].rhs;
                    delta[q] = wk[q].delta;
                }
                solve_lanes(&P, abs, rhs, delta, count);
                for (int q = 0; q < count; q++) {
                    double s = residuals(&P, p, wk[q].col, wk[q].delta, NULL, 0, 0);
                    values[g * k + ch + q] = criterion(&P, s, rd);
                }
            }
        }
        /* 2. each channel's refinement, two channels side by side, then its fit */
        Refine R = {&P, y, grid, values, g_count, 0, xatol, fitted, log_p, rss, rdof, 0};
        refine(&R, wk, lanes);
        failures = R.failures;
        Py_END_ALLOW_THREADS;
    }
    free(values);
    for (int q = 0; q < LANES; q++) {
        work_free(&wk[q]);
    }
    release(extra, 4);
    release(views, B_COUNT);
    if (!ok) {
        return PyErr_NoMemory();
    }
    return PyLong_FromSsize_t(failures);
}

static PyMethodDef methods[] = {
    {"fit", gcv_fit, METH_VARARGS, fit_doc},
    {"search", gcv_search, METH_VARARGS, search_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_c_gcv",
    "Compiled kernel of the GCV smoothing spline (twin: gcv.py and gcv_batch.py).", -1,
    methods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__c_gcv(void)
{
    return PyModule_Create(&module);
}
