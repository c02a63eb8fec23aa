/*
 * Triangulation in compiled code: one live frame (the twin of the numpy path of
 * spotlab.reconstruction.frame_triangulator.FrameTriangulator) and the batch ODLE of
 * spotlab.reconstruction.triangulate (the twin of _rays.normalize_seen and
 * _solvers.odle), on the numeric core of _frame_core.h.
 *
 * Per observation: the lens's fitted start and one Newton step (up to six more for the
 * few that the first leaves short; those still short are returned to Python, which
 * asks the geometry layer), in the order of operations of _rays.py, so undistorted
 * coordinates equal the twin's to the last bit. Per point: the depth-weighted ODLE of
 * _solvers.odle (its sums formed directly from each ray's direction rather than
 * through the twin's matrix product, a third of the operations, so the points agree
 * to rounding); for a live frame one re-weighting pass, the conditioning test, the ray
 * residuals in undistorted pixels and their RMS; for the batch any number of passes,
 * per-ray weights, and the unmasked points and conditioning (Python masks them).
 *
 * The rig buffer's layout is in _frame_core.h. Arrays are C-contiguous; Python checks
 * shapes and dtypes, this file checks sizes. Only the C API and the buffer protocol are
 * used (no numpy headers). The numeric work runs without the GIL.
 */

#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include "_frame_core.h"

/* Distance (undistorted px) between each ray of camera L and its point P; NaN where
 * use is 0. sum2 gets the squares of the used ones. */
static void residuals(const Lens *L, double (*restrict P)[CHUNK], const double *restrict x,
                      const double *restrict y, const double *restrict use,
                      double *restrict ray, double *restrict sum2, Py_ssize_t m) {
    double R[9], t[3];
    memcpy(R, L->R, sizeof R);
    memcpy(t, L->t, sizeof t);
    const double f2 = L->f2;
    for (Py_ssize_t k = 0; k < m; ++k) {
        const double X0 = P[0][k], X1 = P[1][k], X2 = P[2][k];
        double xc = R[0] * X0 + R[1] * X1 + R[2] * X2 + t[0];
        double yc = R[3] * X0 + R[4] * X1 + R[5] * X2 + t[1];
        double zc = R[6] * X0 + R[7] * X1 + R[8] * X2 + t[2];
        double ex = xc / zc - x[k];
        double ey = yc / zc - y[k];
        ray[k] = (ex * ex + ey * ey) * f2;
    }
    /* A loop of its own: sqrt may set errno, a call the vectorised loop cannot hold. */
    for (Py_ssize_t k = 0; k < m; ++k) {
        const double r = sqrt(ray[k]);
        const double r2 = r * r;
        ray[k] = use[k] != 0.0 ? r : NAN;
        sum2[k] += use[k] != 0.0 ? r2 : 0.0;
    }
}

/* Points of undistorted observations: _solvers.odle (one depth-weighted pass) and the
 * masking and residuals of FrameTriangulator._solve, CHUNK points at a time. X (N, 3)
 * world points (NaN where bad), n_views (N,); ray_px (C, N) if not NULL (NaN where
 * unseen or bad); rms (N,) if not NULL. x, y must be 0 where unseen. */
static void solve(const Rig *rig, Py_ssize_t N, const double *x, const double *y,
                  const unsigned char *seen, double *X, double *ray_px, double *rms,
                  int64_t *n_views) {
    const Py_ssize_t C = rig->C;
    double e[9][CHUNK], P[3][CHUNK], w[CHUNK], wz[CHUNK], cond[CHUNK], views[CHUNK];
    double use[CHUNK], ray[CHUNK], sum2[CHUNK];
    for (Py_ssize_t n0 = 0; n0 < N; n0 += CHUNK) {
        const Py_ssize_t m = N - n0 < CHUNK ? N - n0 : CHUNK;
        memset(e, 0, sizeof e);
        for (Py_ssize_t k = 0; k < m; ++k) views[k] = 0.0;
        for (Py_ssize_t c = 0; c < C; ++c) {
            const Lens L = rig_lens(rig, c);
            const unsigned char *s = seen + c * N + n0;
            for (Py_ssize_t k = 0; k < m; ++k) w[k] = s[k];
            for (Py_ssize_t k = 0; k < m; ++k) views[k] += w[k];
            add_rays(&L, x + c * N + n0, y + c * N + n0, w, e, m);
        }
        solve3(e, P, cond, m);
        memset(e, 0, sizeof e);
        for (Py_ssize_t c = 0; c < C; ++c) {
            const Lens L = rig_lens(rig, c);
            const unsigned char *s = seen + c * N + n0;
            for (Py_ssize_t k = 0; k < m; ++k) w[k] = s[k];
            depth_weights(&L, P, w, wz, m);
            add_rays(&L, x + c * N + n0, y + c * N + n0, wz, e, m);
        }
        solve3(e, P, cond, m);
        const double min_conditioning = rig->min_conditioning;
        for (Py_ssize_t k = 0; k < m; ++k) {
            const int bad = views[k] < 2.0 || !(cond[k] >= min_conditioning);
            cond[k] = bad; /* from here: whether the point is masked */
            sum2[k] = 0.0;
            n_views[n0 + k] = (int64_t)views[k];
        }
        for (Py_ssize_t c = 0; c < C; ++c) {
            const Lens L = rig_lens(rig, c);
            const unsigned char *s = seen + c * N + n0;
            for (Py_ssize_t k = 0; k < m; ++k) use[k] = s[k] && cond[k] == 0.0;
            double *out = ray_px ? ray_px + c * N + n0 : ray;
            residuals(&L, P, x + c * N + n0, y + c * N + n0, use, out, sum2, m);
        }
        for (Py_ssize_t k = 0; k < m; ++k) {
            double *out = X + 3 * (n0 + k);
            const int bad = cond[k] != 0.0;
            out[0] = bad ? NAN : P[0][k] + rig->origin[0];
            out[1] = bad ? NAN : P[1][k] + rig->origin[1];
            out[2] = bad ? NAN : P[2][k] + rig->origin[2];
            if (rms) rms[n0 + k] = isnan(out[0]) ? NAN : sqrt(sum2[k] / views[k]);
        }
    }
}

/* The weight of each ray of one camera before depth weighting: the caller's weight
 * wc (1 if NULL) where seen, 0 where not (_solvers.Views.weights). */
static void base_weights(const unsigned char *restrict s, const double *restrict wc,
                         double *restrict w, Py_ssize_t m) {
    if (wc) {
        for (Py_ssize_t k = 0; k < m; ++k) w[k] = s[k] ? wc[k] : 0.0;
    } else {
        for (Py_ssize_t k = 0; k < m; ++k) w[k] = s[k];
    }
}

/* _solvers.odle with depth weights, CHUNK points at a time: the first solution with
 * the base weights, then `passes` solutions each weighing the rays by (f / z)^2 at the
 * previous one. weights (C, N) or NULL (1); x, y must be 0 where unseen. X (N, 3) gets
 * the centred points and conditioning (N,) that of the last solution, both unmasked
 * (NaN or inf for points seen by fewer than two cameras, as in the twin). */
static void odle_points(const Rig *rig, Py_ssize_t N, const double *x, const double *y,
                        const unsigned char *seen, const double *weights, int passes,
                        double *X, double *conditioning) {
    const Py_ssize_t C = rig->C;
    double e[9][CHUNK], P[3][CHUNK], w[CHUNK], wz[CHUNK], cond[CHUNK];
    for (Py_ssize_t n0 = 0; n0 < N; n0 += CHUNK) {
        const Py_ssize_t m = N - n0 < CHUNK ? N - n0 : CHUNK;
        for (int pass = 0; pass <= passes; ++pass) {
            memset(e, 0, sizeof e);
            for (Py_ssize_t c = 0; c < C; ++c) {
                const Lens L = rig_lens(rig, c);
                const Py_ssize_t at = c * N + n0;
                base_weights(seen + at, weights ? weights + at : NULL, w, m);
                if (pass) depth_weights(&L, P, w, wz, m);
                add_rays(&L, x + at, y + at, pass ? wz : w, e, m);
            }
            solve3(e, P, cond, m);
        }
        for (Py_ssize_t k = 0; k < m; ++k) {
            double *out = X + 3 * (n0 + k);
            out[0] = P[0][k];
            out[1] = P[1][k];
            out[2] = P[2][k];
            conditioning[n0 + k] = cond[k];
        }
    }
}

/* Buffer of exactly `count` items of `itemsize` bytes; 0 or -1 with an exception. */
static int check(const Py_buffer *b, Py_ssize_t count, Py_ssize_t itemsize, const char *name) {
    if (b->len != count * itemsize) {
        PyErr_Format(PyExc_ValueError, "%s: %zd bytes, expected %zd", name, b->len,
                     count * itemsize);
        return -1;
    }
    return 0;
}

#define RELEASE(...)                                                                   \
    do {                                                                               \
        Py_buffer *all_[] = {__VA_ARGS__};                                             \
        for (size_t i_ = 0; i_ < sizeof(all_) / sizeof(all_[0]); ++i_)                \
            PyBuffer_Release(all_[i_]);                                                \
    } while (0)

static PyObject *py_normalize(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer rb, uvb, xb, yb, sb, slb;
    Py_ssize_t N;
    int by_marker;
    if (!PyArg_ParseTuple(args, "y*ny*pw*w*w*w*", &rb, &N, &uvb, &by_marker, &xb, &yb, &sb, &slb))
        return NULL;
    Rig rig;
    Py_ssize_t n_slow = 0;
    if (rig_parse(&rb, &rig) < 0 || check(&uvb, rig.C * N * 2, 8, "uv") < 0 ||
        check(&xb, rig.C * N, 8, "x") < 0 || check(&yb, rig.C * N, 8, "y") < 0 ||
        check(&sb, rig.C * N, 1, "seen") < 0 || check(&slb, rig.C * N, 8, "slow") < 0) {
        RELEASE(&rb, &uvb, &xb, &yb, &sb, &slb);
        return NULL;
    }
    Py_BEGIN_ALLOW_THREADS
    n_slow = undistort(&rig, N, uvb.buf, by_marker ? 2 : 2 * N, by_marker ? 2 * rig.C : 2, xb.buf,
                       yb.buf, sb.buf, slb.buf);
    Py_END_ALLOW_THREADS
    RELEASE(&rb, &uvb, &xb, &yb, &sb, &slb);
    return PyLong_FromSsize_t(n_slow);
}

static PyObject *py_solve(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer rb, xb, yb, sb, Xb, rayb, nvb;
    Py_ssize_t N;
    if (!PyArg_ParseTuple(args, "y*ny*y*y*w*w*w*", &rb, &N, &xb, &yb, &sb, &Xb, &rayb, &nvb))
        return NULL;
    Rig rig;
    if (rig_parse(&rb, &rig) < 0 || check(&xb, rig.C * N, 8, "x") < 0 ||
        check(&yb, rig.C * N, 8, "y") < 0 || check(&sb, rig.C * N, 1, "seen") < 0 ||
        check(&Xb, N * 3, 8, "X") < 0 || check(&rayb, rig.C * N, 8, "ray_px") < 0 ||
        check(&nvb, N, 8, "n_views") < 0) {
        RELEASE(&rb, &xb, &yb, &sb, &Xb, &rayb, &nvb);
        return NULL;
    }
    Py_BEGIN_ALLOW_THREADS
    solve(&rig, N, xb.buf, yb.buf, sb.buf, Xb.buf, rayb.buf, NULL, nvb.buf);
    Py_END_ALLOW_THREADS
    RELEASE(&rb, &xb, &yb, &sb, &Xb, &rayb, &nvb);
    Py_RETURN_NONE;
}

static PyObject *py_frame(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer rb, uvb, Xb, rmsb, nvb;
    Py_ssize_t N;
    int by_marker;
    if (!PyArg_ParseTuple(args, "y*ny*pw*w*w*", &rb, &N, &uvb, &by_marker, &Xb, &rmsb, &nvb))
        return NULL;
    Rig rig;
    Py_ssize_t n_slow = 0;
    if (rig_parse(&rb, &rig) < 0 || check(&uvb, rig.C * N * 2, 8, "uv") < 0 ||
        check(&Xb, N * 3, 8, "X") < 0 || check(&rmsb, N, 8, "rms") < 0 ||
        check(&nvb, N, 8, "n_views") < 0) {
        RELEASE(&rb, &uvb, &Xb, &rmsb, &nvb);
        return NULL;
    }
    /* x, y, slow (C N numbers each) and seen (C N bytes) in one block of scratch. */
    const Py_ssize_t CN = rig.C * N;
    double *work = PyMem_Malloc((size_t)(3 * CN + CN / 8 + 1) * sizeof(double));
    if (!work) {
        RELEASE(&rb, &uvb, &Xb, &rmsb, &nvb);
        return PyErr_NoMemory();
    }
    double *x = work, *y = x + CN;
    int64_t *slow = (int64_t *)(y + CN);
    unsigned char *seen = (unsigned char *)(slow + CN);
    Py_BEGIN_ALLOW_THREADS
    n_slow = undistort(&rig, N, uvb.buf, by_marker ? 2 : 2 * N, by_marker ? 2 * rig.C : 2, x, y, seen,
                       slow);
    if (n_slow == 0) solve(&rig, N, x, y, seen, Xb.buf, NULL, rmsb.buf, nvb.buf);
    Py_END_ALLOW_THREADS
    PyMem_Free(work);
    RELEASE(&rb, &uvb, &Xb, &rmsb, &nvb);
    return PyLong_FromSsize_t(n_slow);
}

/* Optional weights: None (buffer with NULL buf) or exactly `count` float64; 0 or -1. */
static int get_weights(PyObject *obj, Py_buffer *wb, Py_ssize_t count) {
    memset(wb, 0, sizeof *wb);
    if (obj == Py_None) return 0;
    if (PyObject_GetBuffer(obj, wb, PyBUF_C_CONTIGUOUS) < 0) return -1;
    return check(wb, count, 8, "weights");
}

/* The points start .. start + count - 1 of uv (C, N, 2): 0, or -1 with an exception. */
static int check_range(const Py_buffer *uvb, Py_ssize_t C, Py_ssize_t N, Py_ssize_t start,
                       Py_ssize_t count) {
    if (N < 0 || start < 0 || count < 0 || start > N - count) {
        PyErr_SetString(PyExc_ValueError, "point range outside uv");
        return -1;
    }
    return check(uvb, C * N * 2, 8, "uv");
}

static PyObject *py_normalize_range(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer rb, uvb, xb, yb, sb, slb;
    Py_ssize_t N, start, n;
    if (!PyArg_ParseTuple(args, "y*ny*nnw*w*w*w*", &rb, &N, &uvb, &start, &n, &xb, &yb, &sb,
                          &slb))
        return NULL;
    Rig rig;
    Py_ssize_t n_slow = 0;
    if (rig_parse(&rb, &rig) < 0 || check_range(&uvb, rig.C, N, start, n) < 0 ||
        check(&xb, rig.C * n, 8, "x") < 0 || check(&yb, rig.C * n, 8, "y") < 0 ||
        check(&sb, rig.C * n, 1, "seen") < 0 || check(&slb, rig.C * n, 8, "slow") < 0) {
        RELEASE(&rb, &uvb, &xb, &yb, &sb, &slb);
        return NULL;
    }
    const double *uv = (const double *)uvb.buf + 2 * start;
    Py_BEGIN_ALLOW_THREADS
    n_slow = undistort(&rig, n, uv, 2 * N, 2, xb.buf, yb.buf, sb.buf, slb.buf);
    Py_END_ALLOW_THREADS
    RELEASE(&rb, &uvb, &xb, &yb, &sb, &slb);
    return PyLong_FromSsize_t(n_slow);
}

static PyObject *py_odle(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer rb, uvb, wb, Xb, cb, xb, yb, sb, slb;
    Py_ssize_t N, start, n;
    PyObject *weights;
    int passes;
    if (!PyArg_ParseTuple(args, "y*ny*nnOiw*w*w*w*w*w*", &rb, &N, &uvb, &start, &n, &weights,
                          &passes, &Xb, &cb, &xb, &yb, &sb, &slb))
        return NULL;
    Rig rig;
    Py_ssize_t n_slow = 0;
    memset(&wb, 0, sizeof wb);
    if (rig_parse(&rb, &rig) < 0 || check_range(&uvb, rig.C, N, start, n) < 0 ||
        get_weights(weights, &wb, rig.C * n) < 0 || check(&Xb, n * 3, 8, "X") < 0 ||
        check(&cb, n, 8, "conditioning") < 0 || check(&xb, rig.C * n, 8, "x") < 0 ||
        check(&yb, rig.C * n, 8, "y") < 0 || check(&sb, rig.C * n, 1, "seen") < 0 ||
        check(&slb, rig.C * n, 8, "slow") < 0 || passes < 0) {
        if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "passes must be >= 0");
        RELEASE(&rb, &uvb, &wb, &Xb, &cb, &xb, &yb, &sb, &slb);
        return NULL;
    }
    const double *uv = (const double *)uvb.buf + 2 * start;
    Py_BEGIN_ALLOW_THREADS
    n_slow = undistort(&rig, n, uv, 2 * N, 2, xb.buf, yb.buf, sb.buf, slb.buf);
    if (n_slow == 0)
        odle_points(&rig, n, xb.buf, yb.buf, sb.buf, wb.buf, passes, Xb.buf, cb.buf);
    Py_END_ALLOW_THREADS
    RELEASE(&rb, &uvb, &wb, &Xb, &cb, &xb, &yb, &sb, &slb);
    return PyLong_FromSsize_t(n_slow);
}

static PyObject *py_odle_solve(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer rb, xb, yb, sb, wb, Xb, cb;
    Py_ssize_t N;
    PyObject *weights;
    int passes;
    if (!PyArg_ParseTuple(args, "y*ny*y*y*Oiw*w*", &rb, &N, &xb, &yb, &sb, &weights, &passes,
                          &Xb, &cb))
        return NULL;
    Rig rig;
    memset(&wb, 0, sizeof wb);
    if (rig_parse(&rb, &rig) < 0 || check(&xb, rig.C * N, 8, "x") < 0 ||
        check(&yb, rig.C * N, 8, "y") < 0 || check(&sb, rig.C * N, 1, "seen") < 0 ||
        get_weights(weights, &wb, rig.C * N) < 0 || check(&Xb, N * 3, 8, "X") < 0 ||
        check(&cb, N, 8, "conditioning") < 0 || passes < 0) {
        if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "passes must be >= 0");
        RELEASE(&rb, &xb, &yb, &sb, &wb, &Xb, &cb);
        return NULL;
    }
    Py_BEGIN_ALLOW_THREADS
    odle_points(&rig, N, xb.buf, yb.buf, sb.buf, wb.buf, passes, Xb.buf, cb.buf);
    Py_END_ALLOW_THREADS
    RELEASE(&rb, &xb, &yb, &sb, &wb, &Xb, &cb);
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"normalize", py_normalize, METH_VARARGS,
     "normalize(rig, N, uv, by_marker, x, y, seen, slow) -> n_slow (-1: infinite values)\n\n"
     "Undistort uv (C, N, 2), or (N, C, 2) if by_marker, into x, y (C, N) and seen\n"
     "(C, N, bool); the flat indices of observations that did not converge go to slow\n"
     "(C N int64)."},
    {"solve", py_solve, METH_VARARGS,
     "solve(rig, N, x, y, seen, X, ray_px, n_views) -> None\n\n"
     "Depth-weighted ODLE of undistorted observations: X (N, 3), ray_px (C, N),\n"
     "n_views (N, int64)."},
    {"frame", py_frame, METH_VARARGS,
     "frame(rig, N, uv, by_marker, X, rms, n_views) -> n_slow\n\n"
     "normalize then, if every observation converged (n_slow 0), solve with the RMS of\n"
     "the ray residuals in rms (N,) instead of ray_px; otherwise nothing is written\n"
     "(the caller takes normalize's way)."},
    {"normalize_range", py_normalize_range, METH_VARARGS,
     "normalize_range(rig, N, uv, start, n, x, y, seen, slow) -> n_slow\n\n"
     "normalize of the points start .. start + n - 1 of uv (C, N, 2): x, y, seen and\n"
     "slow of n points."},
    {"odle", py_odle, METH_VARARGS,
     "odle(rig, N, uv, start, n, weights, passes, X, conditioning, x, y, seen, slow)\n"
     "-> n_slow\n\n"
     "normalize_range then, if every observation converged (n_slow 0), odle_solve;\n"
     "otherwise X and conditioning are not written (the caller finishes x, y and calls\n"
     "odle_solve)."},
    {"odle_solve", py_odle_solve, METH_VARARGS,
     "odle_solve(rig, N, x, y, seen, weights, passes, X, conditioning) -> None\n\n"
     "_solvers.odle (depth-weighted, `passes` re-weighting passes) of undistorted\n"
     "observations with weights (C, N) or None: centred, unmasked X (N, 3) and the\n"
     "conditioning (N,)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_c_frame",
    "Compiled twins of FrameTriangulator's numpy path and triangulate's ODLE.", -1,
    methods,
    NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__c_frame(void) { return PyModule_Create(&module); }
