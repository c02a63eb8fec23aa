/* Compiled kernel of the natural spline interpolant and its evaluation (numpy twin:
 * scipy.interpolate.make_interp_spline and BSpline, as spotlab.kinematics._natural
 * calls them).
 *
 * natural: the B-spline coefficients (n + k - 1, K) of the spline of odd degree
 * k = 2m - 1 on the knots t = (x_0 x k, x, x_{n-1} x k) through f (n, K) with
 * derivatives m .. 2m - 2 zero at both ends: the collocation rows (left derivatives,
 * values, right derivatives, in SciPy's order) solved by banded Gaussian elimination
 * with partial pivoting (LAPACK's gbsv does the same).
 * evaluate: the nu-th derivative at points inside [t_k, t_{n + k - 1}] (de Boor).
 * All arrays C-contiguous float64; the numeric work runs without the GIL.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include "_buffers.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

enum { MAXK = 15 };

/* The knot interval l (k <= l < nc) holding x: t[l] <= x < t[l + 1], the last one at its
 * right end (nc coefficients, t of nc + k + 1 knots). */
static Py_ssize_t interval(const double *t, int k, Py_ssize_t nc, double x)
{
    Py_ssize_t lo = k, hi = nc - 1;
    if (x >= t[hi]) {
        return hi;
    }
    while (hi - lo > 1) { /* t[lo] <= x < t[hi] */
        const Py_ssize_t mid = lo + (hi - lo) / 2;
        if (x >= t[mid]) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return lo;
}

/* h[a], a = 0 .. k: the nu-th derivatives at x of the B-splines l - k + a that are
 * non-zero on interval l (Cox-de Boor to degree k - nu, then differentiation steps). */
static void basis(const double *t, int k, Py_ssize_t l, double x, int nu, double *h)
{
    double hh[MAXK + 1];
    h[0] = 1.0;
    for (int j = 1; j <= k; j++) {
        memcpy(hh, h, sizeof(double) * (size_t)j);
        h[0] = 0.0;
        for (int n = 1; n <= j; n++) {
            const double xb = t[l + n], xa = t[l + n - j];
            if (xb == xa) {
                h[n] = 0.0;
                continue;
            }
            if (j <= k - nu) {
                const double w = hh[n - 1] / (xb - xa);
                h[n - 1] += w * (xb - x);
                h[n] = w * (x - xa);
            } else {
                const double w = j * hh[n - 1] / (xb - xa);
                h[n - 1] -= w;
                h[n] = w;
            }
        }
    }
}

/* Row-band matrix of size nr with kl sub- and ku super-diagonals, room for the fill-in of
 * row interchanges: A(r, c) at band[r * width + c - r + kl], c - r in -kl .. ku + kl. */
typedef struct {
    double *band;
    Py_ssize_t nr;
    int kl, ku, width;
} Band;

#define AT(B, r, c) ((B)->band[(r) * (B)->width + (c) - (r) + (B)->kl])

/* Solve A X = rhs (nr, nch) in place by Gaussian elimination with partial pivoting;
 * 0, or -1 for a singular matrix. */
static int band_solve(Band *B, double *rhs, Py_ssize_t nch)
{
    const Py_ssize_t nr = B->nr;
    const int reach = B->ku + B->kl;
    for (Py_ssize_t j = 0; j < nr; j++) {
        const Py_ssize_t last = j + B->kl < nr - 1 ? j + B->kl : nr - 1;
        Py_ssize_t piv = j;
        for (Py_ssize_t r = j + 1; r <= last; r++) {
            if (fabs(AT(B, r, j)) > fabs(AT(B, piv, j))) {
                piv = r;
            }
        }
        if (AT(B, piv, j) == 0.0) {
            return -1;
        }
        const Py_ssize_t cend = j + reach < nr - 1 ? j + reach : nr - 1;
        if (piv != j) {
            for (Py_ssize_t c = j; c <= cend; c++) {
                const double tmp = AT(B, j, c);
                AT(B, j, c) = AT(B, piv, c);
                AT(B, piv, c) = tmp;
            }
            for (Py_ssize_t q = 0; q < nch; q++) {
                const double tmp = rhs[j * nch + q];
                rhs[j * nch + q] = rhs[piv * nch + q];
                rhs[piv * nch + q] = tmp;
            }
        }
        const double pivot = AT(B, j, j);
        for (Py_ssize_t r = j + 1; r <= last; r++) {
            const double factor = AT(B, r, j) / pivot;
            if (factor == 0.0) {
                continue;
            }
            for (Py_ssize_t c = j + 1; c <= cend; c++) {
                AT(B, r, c) -= factor * AT(B, j, c);
            }
            for (Py_ssize_t q = 0; q < nch; q++) {
                rhs[r * nch + q] -= factor * rhs[j * nch + q];
            }
        }
    }
    for (Py_ssize_t j = nr - 1; j >= 0; j--) {
        const Py_ssize_t cend = j + reach < nr - 1 ? j + reach : nr - 1;
        for (Py_ssize_t q = 0; q < nch; q++) {
            double s = rhs[j * nch + q];
            for (Py_ssize_t c = j + 1; c <= cend; c++) {
                s -= AT(B, j, c) * rhs[c * nch + q];
            }
            rhs[j * nch + q] = s / AT(B, j, j);
        }
    }
    return 0;
}

/* Coefficients c (n + k - 1, nch) of the natural interpolant of f (n, nch) on knots t. */
static int natural(const double *t, const double *x, const double *f, Py_ssize_t n, int k,
                   Py_ssize_t nch, double *c, double *band)
{
    const int m = (k + 1) / 2, nl = m - 1;
    const Py_ssize_t nc = n + k - 1;
    Band B = {band, nc, k, k, 3 * k + 1};
    memset(band, 0, sizeof(double) * (size_t)(nc * B.width));
    double h[MAXK + 1];
    /* left: derivatives m .. 2m - 2 at x_0, on interval k (B-splines 0 .. k) */
    for (int s = 0; s < nl; s++) {
        basis(t, k, k, x[0], m + s, h);
        for (int a = 0; a <= k; a++) {
            AT(&B, s, a) = h[a];
        }
        for (Py_ssize_t q = 0; q < nch; q++) {
            c[s * nch + q] = 0.0;
        }
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        const Py_ssize_t l = i < n - 1 ? k + i : nc - 1;
        const Py_ssize_t r = nl + i;
        basis(t, k, l, x[i], 0, h);
        for (int a = 0; a <= k; a++) {
            AT(&B, r, l - k + a) = h[a];
        }
        for (Py_ssize_t q = 0; q < nch; q++) {
            c[r * nch + q] = f[i * nch + q];
        }
    }
    for (int s = 0; s < nl; s++) {
        const Py_ssize_t r = nl + n + s;
        basis(t, k, nc - 1, x[n - 1], m + s, h);
        for (int a = 0; a <= k; a++) {
            AT(&B, r, nc - 1 - k + a) = h[a];
        }
        for (Py_ssize_t q = 0; q < nch; q++) {
            c[r * nch + q] = 0.0;
        }
    }
    return band_solve(&B, c, nch);
}

/* out (npts, nch): the nu-th derivative at x (npts,) of the spline (t, c, k). */
static void evaluate(const double *t, const double *c, Py_ssize_t nc, int k, Py_ssize_t nch,
                     const double *x, Py_ssize_t npts, int nu, double *out)
{
    double h[MAXK + 1];
    for (Py_ssize_t i = 0; i < npts; i++) {
        const Py_ssize_t l = interval(t, k, nc, x[i]);
        basis(t, k, l, x[i], nu, h);
        double *row = out + i * nch;
        for (Py_ssize_t q = 0; q < nch; q++) {
            row[q] = 0.0;
        }
        for (int a = 0; a <= k; a++) {
            const double *cr = c + (l - k + a) * nch;
            for (Py_ssize_t q = 0; q < nch; q++) {
                row[q] += cr[q] * h[a];
            }
        }
    }
}

/* ------------------------------------------------------------ Python glue */

PyDoc_STRVAR(natural_doc, "natural(t, x, f, c, n, k, nch)\n"
                          "--\n\n"
                          "B-spline coefficients c (n + k - 1, nch) of the natural spline of odd\n"
                          "degree k on knots t (n + 2k) through f (n, nch) at x (n,). Raises\n"
                          "ValueError when the collocation matrix is singular.");

static PyObject *py_natural(PyObject *self, PyObject *args)
{
    PyObject *objs[4];
    Py_ssize_t n, nch;
    int k;
    (void)self;
    if (!PyArg_ParseTuple(args, "OOOOnin:natural", &objs[0], &objs[1], &objs[2], &objs[3], &n,
                          &k, &nch)) {
        return NULL;
    }
    if (k < 1 || k > MAXK || k % 2 == 0 || n < k + 1 || nch < 1) {
        PyErr_SetString(PyExc_ValueError, "need odd 1 <= k <= 15, n > k and nch >= 1");
        return NULL;
    }
    static const char *const names[4] = {"t", "x", "f", "c"};
    const Py_ssize_t nc = n + k - 1;
    const Py_ssize_t counts[4] = {n + 2 * k, n, n * nch, nc * nch};
    Py_buffer views[4];
    if (get_buffers(objs, views, counts, names, 4, 3) != 0) {
        return NULL;
    }
    double *band = malloc(sizeof(double) * (size_t)(nc * (3 * k + 1)));
    int status = -2;
    if (band != NULL) {
        Py_BEGIN_ALLOW_THREADS;
        status = natural(views[0].buf, views[1].buf, views[2].buf, n, k, nch, views[3].buf, band);
        Py_END_ALLOW_THREADS;
    }
    free(band);
    release(views, 4);
    if (status == -2) {
        return PyErr_NoMemory();
    }
    if (status != 0) {
        PyErr_SetString(PyExc_ValueError, "singular collocation matrix");
        return NULL;
    }
    Py_RETURN_NONE;
}

PyDoc_STRVAR(evaluate_doc, "evaluate(t, c, x, out, nc, k, nch, npts, nu)\n"
                           "--\n\n"
                           "out (npts, nch): the nu-th derivative at x (npts,) of the spline with\n"
                           "knots t (nc + k + 1) and coefficients c (nc, nch); x inside the base\n"
                           "interval [t_k, t_nc].");

static PyObject *py_evaluate(PyObject *self, PyObject *args)
{
    PyObject *objs[4];
    Py_ssize_t nc, nch, npts;
    int k, nu;
    (void)self;
    if (!PyArg_ParseTuple(args, "OOOOninni:evaluate", &objs[0], &objs[1], &objs[2], &objs[3],
                          &nc, &k, &nch, &npts, &nu)) {
        return NULL;
    }
    if (k < 0 || k > MAXK || nu < 0 || nu > k || nc < k + 1 || nch < 1 || npts < 0) {
        PyErr_SetString(PyExc_ValueError, "need 0 <= nu <= k <= 15, nc > k, nch >= 1");
        return NULL;
    }
    static const char *const names[4] = {"t", "c", "x", "out"};
    const Py_ssize_t counts[4] = {nc + k + 1, nc * nch, npts, npts * nch};
    Py_buffer views[4];
    if (get_buffers(objs, views, counts, names, 4, 3) != 0) {
        return NULL;
    }
    Py_BEGIN_ALLOW_THREADS;
    evaluate(views[0].buf, views[1].buf, nc, k, nch, views[2].buf, npts, nu, views[3].buf);
    Py_END_ALLOW_THREADS;
    release(views, 4);
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"natural", py_natural, METH_VARARGS, natural_doc},
    {"evaluate", py_evaluate, METH_VARARGS, evaluate_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT,
    "_c_bspline",
    "Compiled natural spline interpolant and B-spline evaluation (twin: scipy.interpolate).",
    -1,
    methods,
    NULL,
    NULL,
    NULL,
    NULL,
};

PyMODINIT_FUNC PyInit__c_bspline(void)
{
    return PyModule_Create(&module);
}
