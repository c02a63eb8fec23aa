/* Compiled kernel of the GCV smoothing spline (numpy twin: gcv.py, gcv_batch.py,
 * _takahashi.py, _brent.py).
 *
 * Reinsch's banded system (R + p (m!)^2 Q^T W^-1 Q) delta = Q^T y of half-bandwidth m,
 * its Cholesky factor, the fitted values f = y - p (m!)^2 W^-1 Q delta, the weighted
 * residual sum and the trace tr(inv(A) R) by Takahashi's recursion, at one p (fit) or
 * over a whole GCV search (search: the scan over log10 p, then bounded Brent
 * refinement with the arithmetic of _brent.bounded_brent, channel by channel).
 *
 * Layouts (all C-contiguous float64, checked on entry):
 *   q          (rows, m + 1)  q[j, a] multiplies f[j + a] in the j-th divided difference
 *   r, qwq     (rows, m + 1)  upper band by columns, as LAPACK's column-major band
 *                             storage read column after column: [j, m - d] = A[j - d, j]
 *   w, winv    (n,)           weights and their inverses
 *   y, fitted  (n, k)         samples and fitted values, channels side by side
 * with rows = n - m. The factor is A = U^T D U (U unit upper triangular; the twin uses
 * LAPACK's A = U^T U, equal to rounding); the sums of residuals are numpy's pairwise
 * sums. The numeric
 * work runs without the GIL.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

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
    const double *q, *r, *qwq, *w, *winv;
    double fact2; /* (m!)^2 */
} Problem;

typedef struct {
    double *ab;    /* (rows, m + 1) the factor */
    const double *col; /* (n,) one channel's samples: y or buffer */
    double *buffer;    /* (n,) a channel of several, or NULL for one */
    double *rhs;   /* (rows,) Q^T y of that channel */
    double *delta; /* (rows,) the solution */
} Work;

/* ---------------------------------------------------------------- algebra */

/* A = qwq * (p (m!)^2) + r, factored in place as A = U^T D U, U unit upper triangular
 * (U[j, j + t] in A's slots, 1 / D[j] on the diagonal); 0 or the failing column + 1.
 * LDL^T rather than LAPACK's LL^T: no square root on the chain from column to column. */
INLINE Py_ssize_t factor_bw(const Problem *P, double p, double *ab, const int bw)
{
    enum { MAXBW = 9 };
    const int ld = bw + 1;
    const Py_ssize_t n = P->rows;
    const double s = p * P->fact2;
    /* B[r][c] = A[j + r, j + c] (r <= c <= bw) as updated by the columns before j; the
     * entries of column j + bw are still A's own, assembled here from qwq and r. Columns
     * past the end are zero: they neither couple nor get stored. */
    double B[MAXBW][MAXBW], v[MAXBW], l[MAXBW];
    /* the slots above the first columns (rows before 0) are zero: the solves read them */
    for (Py_ssize_t j = 0; j < bw && j < n; j++) {
        for (int t = 0; t < bw - j; t++) {
            ab[j * ld + t] = 0.0;
        }
    }
    for (int r = 0; r < bw; r++) {
        for (int c = r; c < bw; c++) {
            const Py_ssize_t col = c;
            B[r][c] = col < n ? P->qwq[col * ld + bw - (c - r)] * s + P->r[col * ld + bw - (c - r)]
                              : 0.0;
        }
    }
    for (Py_ssize_t j = 0; j < n; j++) {
        const Py_ssize_t col = j + bw;
        for (int r = 0; r <= bw; r++) {
            const Py_ssize_t at = col * ld + r; /* A[j + r, j + bw] */
            B[r][bw] = col < n ? P->qwq[at] * s + P->r[at] : 0.0;
        }
        const double d = B[0][0];
        if (!(d > 0.0)) {
            return j + 1;
        }
        const double rd = 1.0 / d;
        ab[j * ld + bw] = rd;
        for (int t = 1; t <= bw; t++) {
            v[t] = B[0][t];
            l[t] = v[t] * rd;
        }
        for (int c = 1; c <= bw; c++) {
            for (int r = 1; r <= c; r++) {
                B[r][c] -= l[r] * v[c];
            }
            if (j + c < n) {
                ab[(j + c) * ld + bw - c] = l[c];
            }
        }
        for (int r = 0; r < bw; r++) {
            for (int c = r; c < bw; c++) {
                B[r][c] = B[r + 1][c + 1];
            }
        }
    }
    return 0;
}

static Py_ssize_t factor(const Problem *P, double p, double *ab)
{
    Py_ssize_t out = 0;
    BY_BANDWIDTH(P->m, out = factor_bw(P, p, ab, BW));
    return out;
}

/* delta = inv(U^T D U) rhs: U^T z = rhs forward, then U delta = D^-1 z backward. */
INLINE void solve_bw(const Problem *P, const double *ab, const double *rhs, double *x,
                     const int bw)
{
    enum { MAXBW = 9 };
    const int ld = bw + 1;
    const Py_ssize_t n = P->rows;
    /* z[a] = the solution at j - bw + a, kept in registers (zero before the start) */
    double z[MAXBW];
    for (int a = 0; a < bw; a++) {
        z[a] = 0.0;
    }
    for (Py_ssize_t j = 0; j < n; j++) {
        double temp = rhs[j];
        for (int a = 0; a < bw; a++) { /* x[j - 1] last: the shortest chain */
            temp -= ab[j * ld + a] * z[a];
        }
        for (int a = 0; a + 1 < bw; a++) {
            z[a] = z[a + 1];
        }
        z[bw - 1] = temp;
        x[j] = temp;
    }
    /* backward: z[a] = delta at j + 1 + a (zero past the end) */
    for (int a = 0; a < bw; a++) {
        z[a] = 0.0;
    }
    for (Py_ssize_t j = n - 1; j >= 0; j--) {
        double temp = x[j] * ab[j * ld + bw];
        for (int a = bw - 1; a >= 0; a--) { /* delta[j + 1] last */
            const Py_ssize_t i = j + 1 + a;
            if (i < n) {
                temp -= ab[i * ld + bw - (a + 1)] * z[a];
            }
        }
        for (int a = bw - 1; a > 0; a--) {
            z[a] = z[a - 1];
        }
        z[0] = temp;
        x[j] = temp;
    }
}

static void solve(const Problem *P, const double *ab, const double *rhs, double *x)
{
    BY_BANDWIDTH(P->m, solve_bw(P, ab, rhs, x, BW));
}

/* tr(inv(A) R) from A = U^T D U, by Takahashi's backward recursion over a bw x bw window
 * X of inv(A): row i of the inverse is -X c beyond the diagonal (c = U[i, i + 1 ..]) and
 * 1 / D[i] + c . X c on it (Hutchinson & de Hoog 1985). */
INLINE double trace_bw(const Problem *P, const double *ab, const int bw)
{
    enum { MAXBW = 9 };
    const int ld = bw + 1;
    const Py_ssize_t n = P->rows;
    double win[MAXBW][MAXBW], next[MAXBW][MAXBW], c[MAXBW], y[MAXBW];
    for (int a = 0; a < bw; a++) {
        for (int b = 0; b < bw; b++) {
            win[a][b] = 0.0;
        }
    }
    /* the terms of the trace summed with Neumaier's compensation (n - trace cancels) */
    double acc = 0.0, comp = 0.0;
    for (Py_ssize_t i = n - 1; i >= 0; i--) {
        for (int a = 0; a < bw; a++) {
            Py_ssize_t jj = i + 1 + a;
            c[a] = jj < n ? ab[jj * ld + bw - (a + 1)] : 0.0;
        }
        /* y = X c: minus row i of the inverse beyond the diagonal */
        for (int a = 0; a < bw; a++) {
            double s = 0.0;
            for (int b = 0; b < bw; b++) {
                s += win[a][b] * c[b];
            }
            y[a] = s;
        }
        double corner = ab[i * ld + bw];
        for (int a = 0; a < bw; a++) {
            corner += c[a] * y[a];
        }
        double term = corner * P->r[i * ld + bw];
        for (int a = 0; a < bw; a++) {
            Py_ssize_t jj = i + 1 + a;
            if (jj < n) {
                /* R[i, i + 1 + a] counts twice (both triangles) */
                term -= 2.0 * y[a] * P->r[jj * ld + bw - (a + 1)];
            }
        }
        const double sum = acc + term;
        comp += fabs(acc) >= fabs(term) ? (acc - sum) + term : (term - sum) + acc;
        acc = sum;
        next[0][0] = corner;
        for (int a = 1; a < bw; a++) {
            next[0][a] = -y[a - 1];
            next[a][0] = -y[a - 1];
            for (int b = 1; b < bw; b++) {
                next[a][b] = win[a - 1][b - 1];
            }
        }
        for (int a = 0; a < bw; a++) {
            for (int b = 0; b < bw; b++) {
                win[a][b] = next[a][b];
            }
        }
    }
    return acc + comp;
}

static double trace(const Problem *P, const double *ab)
{
    double out = 0.0;
    BY_BANDWIDTH(P->m, out = trace_bw(P, ab, BW));
    return out;
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
static double residuals(const Problem *P, double p, const double *y, const double *delta,
                        double *fitted, Py_ssize_t stride)
{
    const Residuals R = {P, p * P->fact2, y, delta, fitted, stride};
    return residual_sum(&R, 0, P->n);
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
static double residual_dof(const Problem *P, const double *ab)
{
    double rdof = (double)P->rows - trace(P, ab);
    return rdof > DBL_MIN ? rdof : DBL_MIN;
}

/* The criterion of the loaded channel at log10 p (infinite where the factor fails). */
static double evaluate(const Problem *P, Work *wk, double log_p)
{
    const double p = pow(10.0, log_p);
    if (factor(P, p, wk->ab) != 0) {
        return INFINITY;
    }
    solve(P, wk->ab, wk->rhs, wk->delta);
    double rss = residuals(P, p, wk->col, wk->delta, NULL, 0);
    return criterion(P, rss, residual_dof(P, wk->ab));
}

/* ------------------------------------------------------------ Brent search */

/* _brent.bounded_brent (SciPy's minimize_scalar(method="bounded")), step for step. */
static double bounded_brent(const Problem *P, Work *wk, double lo, double hi, double xatol,
                            double *fmin)
{
    const double sqrt_eps = sqrt(2.2e-16);
    const double golden_c = 0.5 * (3.0 - sqrt(5.0));
    const int maxfun = 500;
    double a = lo, b = hi;
    double fulc = a + golden_c * (b - a);
    double nfc = fulc, xf = fulc;
    double rat = 0.0, e = 0.0;
    double fx = evaluate(P, wk, xf);
    int num = 1;
    double ffulc = fx, fnfc = fx;
    double xm = 0.5 * (a + b);
    double tol1 = sqrt_eps * fabs(xf) + xatol / 3.0;
    double tol2 = 2.0 * tol1;
    while (fabs(xf - xm) > tol2 - 0.5 * (b - a)) {
        int golden = 1;
        if (fabs(e) > tol1) {
            golden = 0;
            double r = (xf - nfc) * (fx - ffulc);
            double q = (xf - fulc) * (fx - fnfc);
            double p = (xf - fulc) * q - (xf - nfc) * r;
            q = 2.0 * (q - r);
            if (q > 0.0) {
                p = -p;
            }
            q = fabs(q);
            r = e;
            e = rat;
            if (fabs(p) < fabs(0.5 * q * r) && q * (a - xf) < p && p < q * (b - xf)) {
                rat = (p + 0.0) / q;
                double x = xf + rat;
                if ((x - a) < tol2 || (b - x) < tol2) {
                    rat = (xm - xf >= 0.0) ? tol1 : -tol1;
                }
            } else {
                golden = 1;
            }
        }
        if (golden) {
            e = (xf >= xm) ? (a - xf) : (b - xf);
            rat = golden_c * e;
        }
        double step = fabs(rat);
        if (tol1 > step) {
            step = tol1;
        }
        double x = xf + ((rat >= 0.0) ? step : -step);
        double fu = evaluate(P, wk, x);
        num += 1;
        if (fu <= fx) {
            if (x >= xf) {
                a = xf;
            } else {
                b = xf;
            }
            fulc = nfc;
            ffulc = fnfc;
            nfc = xf;
            fnfc = fx;
            xf = x;
            fx = fu;
        } else {
            if (x < xf) {
                a = x;
            } else {
                b = x;
            }
            if (fu <= fnfc || nfc == xf) {
                fulc = nfc;
                ffulc = fnfc;
                nfc = x;
                fnfc = fu;
            } else if (fu <= ffulc || fulc == xf || fulc == nfc) {
                fulc = x;
                ffulc = fu;
            }
        }
        xm = 0.5 * (a + b);
        tol1 = sqrt_eps * fabs(xf) + xatol / 3.0;
        tol2 = 2.0 * tol1;
        if (num >= maxfun) {
            break;
        }
    }
    *fmin = fx;
    return xf;
}

/* ------------------------------------------------------------ the bands */

/* Divided differences q (rows, m + 1), Q^T W^-1 Q and R in band columns (rows, m + 1),
 * with the operations of _banded.divided_differences, qwq_band and bspline_gram_band:
 * R's Gauss sums per sample interval (nodes, weights: Gauss-Legendre, m points), the
 * B-spline values by Cox-de Boor on knots x padded by m - 1 steps each side. */
static void bands(const double *x, const double *winv, Py_ssize_t n, int m, const double *nodes,
                  const double *weights, double *q, double *qwq, double *r)
{
    enum { MAXM = 9 };
    const int ld = m + 1, degree = m - 1;
    const Py_ssize_t rows = n - m;
    for (Py_ssize_t j = 0; j < rows; j++) {
        for (int a = 0; a <= m; a++) {
            double v = 1.0;
            for (int b = 0; b <= m; b++) {
                if (a != b) {
                    v /= x[j + a] - x[j + b];
                }
            }
            q[j * ld + a] = v;
        }
    }
    for (Py_ssize_t i = 0; i < rows * ld; i++) {
        qwq[i] = 0.0;
        r[i] = 0.0;
    }
    /* entry (j, j + d) of Q^T W^-1 Q, at [j + d, m - d] */
    for (int d = 0; d <= m; d++) {
        for (Py_ssize_t j = 0; j + d < rows; j++) {
            double acc = 0.0;
            for (int a = d; a <= m; a++) {
                acc += q[j * ld + a] * q[(j + d) * ld + a - d] * winv[j + a];
            }
            qwq[(j + d) * ld + m - d] = acc;
        }
    }
    /* knots[k] for k in 0 .. n + 2m - 3: x padded by m - 1 steps of the end intervals */
#define KNOT(k)                                                                                \
    ((k) < degree ? x[0] - (double)(degree - (k)) * (x[1] - x[0])                              \
                  : ((k) - degree < n ? x[(k) - degree]                                        \
                                      : x[n - 1] + (double)((k) - degree - n + 1) *            \
                                                       (x[n - 1] - x[n - 2])))
    /* intervals last first: each band entry then adds its pairs in the twin's order */
    for (Py_ssize_t i = n - 2; i >= 0; i--) {
        const double h = x[i + 1] - x[i];
        const double mid = 0.5 * (x[i + 1] + x[i]), half = 0.5 * h;
        double vals[MAXM][MAXM]; /* vals[s][g]: B-spline i - m + 1 + s at point g */
        double pts[MAXM], qw[MAXM];
        for (int g = 0; g < m; g++) {
            pts[g] = mid + half * nodes[g];
            qw[g] = half * weights[g];
            vals[0][g] = 1.0;
        }
        for (int rr = 1; rr <= degree; rr++) {
            for (int g = 0; g < m; g++) {
                double saved = 0.0, nxt[MAXM];
                for (int s2 = 0; s2 < rr; s2++) {
                    const double right = KNOT(degree + s2 + 1 + i) - pts[g];
                    const double left = pts[g] - KNOT(degree + s2 + 1 - rr + i);
                    const double term = vals[s2][g] / (right + left);
                    nxt[s2] = saved + right * term;
                    saved = left * term;
                }
                nxt[rr] = saved;
                for (int s2 = 0; s2 <= rr; s2++) {
                    vals[s2][g] = nxt[s2];
                }
            }
        }
        for (int a = 0; a < m; a++) {
            const Py_ssize_t j = i - (m - 1) + a; /* the row of B-spline a */
            for (int b = a; b < m; b++) {
                const int d = b - a;
                if (j < 0 || j + d >= rows) {
                    continue;
                }
                double sum = 0.0;
                for (int g = 0; g < m; g++) {
                    sum += qw[g] * vals[a][g] * vals[b][g];
                }
                r[(j + d) * ld + m - d] += sum;
            }
        }
    }
#undef KNOT
    for (Py_ssize_t j = 0; j < rows; j++) {
        const double sj = (double)m / (x[j + m] - x[j]);
        for (int d = 0; d <= m && j + d < rows; d++) {
            const double sd = (double)m / (x[j + d + m] - x[j + d]);
            r[(j + d) * ld + m - d] *= sj * sd;
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
    return wk->ab && (wk->buffer || P->k == 1) && wk->rhs && wk->delta;
}

static void work_free(Work *wk)
{
    free(wk->ab);
    free(wk->buffer);
    free(wk->rhs);
    free(wk->delta);
}

/* A contiguous float64 buffer of exactly `count` items; writable if asked. */
static int get_buffer(PyObject *obj, Py_buffer *view, Py_ssize_t count, int writable,
                      const char *name)
{
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, view, flags) != 0) {
        return -1;
    }
    if (view->itemsize != (Py_ssize_t)sizeof(double) || view->format == NULL ||
        strcmp(view->format, "d") != 0 || view->len != count * (Py_ssize_t)sizeof(double)) {
        PyErr_Format(PyExc_ValueError, "%s: expected %zd contiguous float64 values", name,
                     count);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
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

static void release(Py_buffer *views, int count)
{
    for (int i = 0; i < count; i++) {
        PyBuffer_Release(&views[i]);
    }
}

PyDoc_STRVAR(fit_doc,
             "fit(q, r, qwq, w, winv, y, fitted, rss, m, n, k, p, fact2, want_trace)\n"
             "--\n\n"
             "Fit the k channels of y (n, k) at smoothing parameter p: fitted values into\n"
             "fitted (n, k), sum(w r^2) of each channel into rss (k,). Returns n - m - trace\n"
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
        failed = factor(&P, p, wk.ab);
        if (failed == 0) {
            for (Py_ssize_t ch = 0; ch < k; ch++) {
                load_channel(&P, y, ch, &wk);
                solve(&P, wk.ab, wk.rhs, wk.delta);
                rss[ch] = residuals(&P, p, wk.col, wk.delta, fitted + ch, k);
            }
            if (want_trace) {
                rdof = residual_dof(&P, wk.ab);
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
    Work wk;
    double *values = malloc(sizeof(double) * (size_t)(g_count * k));
    int ok = work_alloc(&P, &wk) && values != NULL;
    Py_ssize_t failures = 0;
    if (ok) {
        const double *y = views[B_Y].buf, *grid = extra[0].buf;
        double *fitted = views[B_OUT].buf, *log_p = extra[1].buf, *rss = extra[2].buf;
        double *rdof = extra[3].buf;
        Py_BEGIN_ALLOW_THREADS;
        /* 1. the scan: one factor and one trace per grid point for all channels */
        for (Py_ssize_t g = 0; g < g_count; g++) {
            const double p = pow(10.0, grid[g]);
            if (factor(&P, p, wk.ab) != 0) {
                for (Py_ssize_t ch = 0; ch < k; ch++) {
                    values[g * k + ch] = INFINITY;
                }
                continue;
            }
            const double rd = residual_dof(&P, wk.ab);
            for (Py_ssize_t ch = 0; ch < k; ch++) {
                load_channel(&P, y, ch, &wk);
                solve(&P, wk.ab, wk.rhs, wk.delta);
                double s = residuals(&P, p, wk.col, wk.delta, NULL, 0);
                values[g * k + ch] = criterion(&P, s, rd);
            }
        }
        /* 2. each channel's refinement, then its fit at the chosen p */
        for (Py_ssize_t ch = 0; ch < k; ch++) {
            Py_ssize_t best = -1;
            for (Py_ssize_t g = 0; g < g_count; g++) {
                const double v = values[g * k + ch];
                if (isfinite(v) && (best < 0 || v < values[best * k + ch])) {
                    best = g;
                }
            }
            load_channel(&P, y, ch, &wk);
            double chosen = grid[g_count - 1];
            if (best >= 0) {
                const double lo = grid[best > 0 ? best - 1 : 0];
                const double hi = grid[best + 1 < g_count ? best + 1 : g_count - 1];
                double fmin;
                const double x = bounded_brent(&P, &wk, lo, hi, xatol, &fmin);
                chosen = (fmin <= values[best * k + ch]) ? x : grid[best];
            }
            log_p[ch] = chosen;
            const double p = pow(10.0, chosen);
            if (factor(&P, p, wk.ab) != 0) {
                rss[ch] = NAN;
                rdof[ch] = NAN;
                failures++;
                continue;
            }
            solve(&P, wk.ab, wk.rhs, wk.delta);
            rss[ch] = residuals(&P, p, wk.col, wk.delta, fitted + ch, k);
            rdof[ch] = residual_dof(&P, wk.ab);
        }
        Py_END_ALLOW_THREADS;
    }
    free(values);
    work_free(&wk);
    release(extra, 4);
    release(views, B_COUNT);
    if (!ok) {
        return PyErr_NoMemory();
    }
    return PyLong_FromSsize_t(failures);
}

PyDoc_STRVAR(bands_doc, "bands(x, winv, nodes, weights, q, qwq, r, m, n)\n"
                        "--\n\n"
                        "The divided differences q (n - m, m + 1) and the bands of Q^T W^-1 Q\n"
                        "and R (n - m, m + 1, band columns) of samples x (n,), weights 1/winv,\n"
                        "written into q, qwq and r; nodes and weights: m-point Gauss-Legendre.");

static PyObject *gcv_bands(PyObject *self, PyObject *args)
{
    PyObject *objs[7];
    int m;
    Py_ssize_t n;
    (void)self;
    if (!PyArg_ParseTuple(args, "OOOOOOOin:bands", &objs[0], &objs[1], &objs[2], &objs[3],
                          &objs[4], &objs[5], &objs[6], &m, &n)) {
        return NULL;
    }
    if (m < 1 || m > 8 || n < m + 2) {
        PyErr_SetString(PyExc_ValueError, "need 1 <= m <= 8 and n >= m + 2");
        return NULL;
    }
    static const char *names[7] = {"x", "winv", "nodes", "weights", "q", "qwq", "r"};
    const Py_ssize_t band = (n - m) * (m + 1);
    const Py_ssize_t counts[7] = {n, n, m, m, band, band, band};
    Py_buffer views[7];
    for (int i = 0; i < 7; i++) {
        if (get_buffer(objs[i], &views[i], counts[i], i >= 4, names[i]) != 0) {
            release(views, i);
            return NULL;
        }
    }
    Py_BEGIN_ALLOW_THREADS;
    bands(views[0].buf, views[1].buf, n, m, views[2].buf, views[3].buf, views[4].buf,
          views[5].buf, views[6].buf);
    Py_END_ALLOW_THREADS;
    release(views, 7);
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"fit", gcv_fit, METH_VARARGS, fit_doc},
    {"search", gcv_search, METH_VARARGS, search_doc},
    {"bands", gcv_bands, METH_VARARGS, bands_doc},
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
