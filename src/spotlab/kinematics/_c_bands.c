/* Compiled kernel of the smoothing spline's set-up (numpy twin: _banded.py).
 *
 * The divided differences q and the bands of Q^T W^-1 Q and of R (the Gram matrix of the
 * order-m B-splines of unit integral) for samples x and weights w, in the twin's
 * operations and order, so that every entry is bitwise the twin's; the GCV kernel
 * (_c_gcv.c) then factors R + p (m!)^2 Q^T W^-1 Q at each p. Its own module so that the
 * GCV kernel is the factor, solves, trace and search alone.
 *
 * Layouts (all C-contiguous float64, checked on entry): x, winv (n,); nodes, weights (m,);
 * q (rows, m + 1), q[j, a] multiplies f[j + a]; qwq, r (rows, m + 1), upper band by
 * columns, [j, m - d] = A[j - d, j] (LAPACK's column-major band storage read column after
 * column); rows = n - m. The numeric work runs without the GIL.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include "_buffers.h"

#include <string.h>

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

PyDoc_STRVAR(bands_doc, "bands(x, winv, nodes, weights, q, qwq, r, m, n)\n"
                        "--\n\n"
                        "The divided differences q (n - m, m + 1) and the bands of Q^T W^-1 Q\n"
                        "and R (n - m, m + 1, band columns) of samples x (n,), weights 1/winv,\n"
                        "written into q, qwq and r; nodes and weights: m-point Gauss-Legendre.");

static PyObject *py_bands(PyObject *self, PyObject *args)
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
    {"bands", py_bands, METH_VARARGS, bands_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_c_bands",
    "Compiled kernel of the smoothing spline's bands (twin: _banded.py).", -1,
    methods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__c_bands(void)
{
    return PyModule_Create(&module);
}
