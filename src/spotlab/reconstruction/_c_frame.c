/*
 * One live frame's triangulation in compiled code: the twin of the numpy path of
 * spotlab.reconstruction.frame_triangulator.FrameTriangulator.
 *
 * Per observation: the lens's fitted start and one Newton step (up to six more for the
 * few that the first leaves short; those still short are returned to Python, which
 * asks the geometry layer), in the order of operations of _rays.py, so undistorted
 * coordinates equal the twin's to the last bit. Per point: the depth-weighted ODLE of
 * _solvers.odle (one re-weighting pass; its sums formed directly from each ray's
 * direction rather than through the twin's matrix product, a third of the operations,
 * so the points agree to rounding), the conditioning test, the ray residuals in
 * undistorted pixels and their RMS.
 *
 * The rig is one float64 buffer built by Python once per rig (see _native_rig in
 * frame_triangulator.py):
 *   header  C, min_conditioning, origin[3], n_g, n_a, n_h
 *   C camera blocks of 27 + n_g + n_a + n_h numbers:
 *           cx, cy, skew, fx_inv, fy_inv, k1, k2, p1, p2, k3, distorted,
 *           g[n_g], a[n_a], h[n_h], R[9] (row-major), t[3] (centred frame), f2,
 *           centre[3] (the perspective centre -R't, centred frame)
 * Arrays are C-contiguous; Python checks shapes and dtypes, this file checks sizes.
 * Only the C API and the buffer protocol are used (no numpy headers). The numeric work
 * runs without the GIL.
 */

#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <math.h>
#include <stdint.h>
#include <string.h>

#define HEADER 8
#define STEP_TOL 1e-6 /* _rays._STEP_TOL */
#define EXTRA_STEPS 6 /* _rays._EXTRA_STEPS */
/* Coefficients of the start polynomials g, a, h (_rays._DEGREES plus one). */
#define NG 7
#define NA 4
#define NH 4

typedef struct {
    const double *p; /* the camera's block */
    const double *g, *a, *h, *R, *t, *centre;
    double f2;
    int ng, na, nh;
} Lens;

typedef struct {
    Py_ssize_t C;
    double min_conditioning;
    const double *origin;
    int ng, na, nh;
    Py_ssize_t block;
    const double *blocks;
} Rig;

/* Read the rig header; 0 on success, -1 with an exception set. */
static int rig_parse(const Py_buffer *buf, Rig *rig) {
    const double *d = (const double *)buf->buf;
    Py_ssize_t n = buf->len / (Py_ssize_t)sizeof(double);
    if (n < HEADER) {
        PyErr_SetString(PyExc_ValueError, "rig buffer too short");
        return -1;
    }
    rig->C = (Py_ssize_t)d[0];
    rig->min_conditioning = d[1];
    rig->origin = d + 2;
    rig->ng = (int)d[5];
    rig->na = (int)d[6];
    rig->nh = (int)d[7];
    if (rig->C < 1 || rig->ng != NG || rig->na != NA || rig->nh != NH) {
        PyErr_SetString(PyExc_ValueError, "rig buffer header invalid");
        return -1;
    }
    rig->block = 27 + rig->ng + rig->na + rig->nh;
    rig->blocks = d + HEADER;
    if (n != HEADER + rig->C * rig->block) {
        PyErr_SetString(PyExc_ValueError, "rig buffer size does not match its header");
        return -1;
    }
    return 0;
}

static Lens rig_lens(const Rig *rig, Py_ssize_t c) {
    Lens L;
    L.p = rig->blocks + c * rig->block;
    L.ng = rig->ng;
    L.na = rig->na;
    L.nh = rig->nh;
    L.g = L.p + 11;
    L.a = L.g + L.ng;
    L.h = L.a + L.na;
    L.R = L.h + L.nh;
    L.t = L.R + 9;
    L.f2 = L.t[3];
    L.centre = L.t + 4;
    return L;
}

/* sum_i coef[i] rho^i, lowest power first (degree >= 1): _rays._horner. */
static double horner(double rho, const double *coef, int n) {
    double out = coef[n - 1] * rho;
    for (int i = n - 2; i >= 1; --i) {
        out += coef[i];
        out *= rho;
    }
    out += coef[0];
    return out;
}

/* One Newton step towards brown(x, y) = (xd, yd), in place: _rays._newton_step.
 * Returns whether the step is accepted as converged (size <= STEP_TOL on a positive
 * definite Jacobian; NaN fails). */
static int newton_step(double *px, double *py, double xd, double yd, const double *k) {
    const double k1 = k[0], k2 = k[1], p1 = k[2], p2 = k[3], k3 = k[4];
    double x = *px, y = *py;
    double xx = x * x, yy = y * y, xy = x * y;
    double r2 = xx + yy;
    double radial = r2 * k3;
    radial += k2;
    radial *= r2;
    radial += k1;
    radial *= r2;
    radial += 1.0;
    double slope = r2 * (6.0 * k3);
    slope += 4.0 * k2;
    slope *= r2;
    slope += 2.0 * k1;
    double ex = x * radial;
    ex -= xd;
    ex += (2.0 * p1) * xy;
    ex += (3.0 * p2) * xx;
    ex += p2 * yy;
    double ey = y * radial;
    ey -= yd;
    ey += (2.0 * p2) * xy;
    ey += (3.0 * p1) * yy;
    ey += p1 * xx;
    double j00 = xx * slope;
    j00 += radial;
    j00 += (2.0 * p1) * y;
    j00 += (6.0 * p2) * x;
    double j11 = yy * slope;
    j11 += radial;
    j11 += (6.0 * p1) * y;
    j11 += (2.0 * p2) * x;
    double j01 = xy * slope;
    j01 += (2.0 * p1) * x;
    j01 += (2.0 * p2) * y;
    double det = j00 * j11;
    det -= j01 * j01;
    int ok = det > 0.0;
    double inv_det = 1.0 / det;
    double dx = j11 * ex;
    dx -= j01 * ey;
    dx *= inv_det;
    double dy = j00 * ey;
    dy -= j01 * ex;
    dy *= inv_det;
    *px = x - dx;
    *py = y - dy;
    j00 += j11; /* the folded branch: Jacobian not positive definite */
    ok &= j00 > 0.0;
    return ok & (fabs(dx) <= STEP_TOL) & (fabs(dy) <= STEP_TOL); /* no branch: vectorises */
}

/* The fitted approximate inverse: _rays.Lens._start. */
static void start(const Lens *L, double xd, double yd, double *px, double *py) {
    const double p1 = L->p[7], p2 = L->p[8];
    double xx = xd * xd, yy = yd * yd, xy = xd * yd;
    double rho = xx + yy;
    double g = horner(rho, L->g, NG);
    double a = horner(rho, L->a, NA);
    double h = horner(rho, L->h, NH);
    h *= rho;
    double x = xd * g, y = yd * g;
    xy *= a;
    xx *= a;
    yy *= a;
    x += p1 * xy;
    x += p2 * xx;
    x += p2 * h;
    y += p2 * xy;
    y += p1 * yy;
    y += p1 * h;
    *px = x;
    *py = y;
}

/* Undistort the N observations of every camera. uv (C, N, 2); x, y (C, N) get the
 * ideal normalised coordinates (0 where unseen), seen (C, N) 0/1. Flat indices of the
 * observations still short after the extra Newton steps go to slow; returns their
 * count, or -1 if uv holds an infinite value (nothing else is then meaningful).
 *
 * The twin takes unseen observations at the principal point and replaces their result
 * by 0; here the arithmetic runs on the NaN (quietly) and the result is replaced by 0,
 * with no branch, so that the loop vectorises. Selects take values computed
 * unconditionally: the compiler does not speculate arithmetic that could trap. */
static Py_ssize_t undistort(const Rig *rig, Py_ssize_t N, const double *uv, double *x, double *y,
                            unsigned char *seen, int64_t *slow) {
    const Py_ssize_t C = rig->C;
    int any_inf = 0;
    for (Py_ssize_t i = 0; i < 2 * C * N; ++i) any_inf |= fabs(uv[i]) == INFINITY;
    if (any_inf) return -1;
    Py_ssize_t n_slow = 0;
    for (Py_ssize_t c = 0; c < C; ++c) {
        const Lens L = rig_lens(rig, c);
        const double cx = L.p[0], cy = L.p[1], skew = L.p[2], fx_inv = L.p[3], fy_inv = L.p[4];
        const double *puv = uv + 2 * c * N;
        double *px = x + c * N, *py = y + c * N;
        unsigned char *ps = seen + c * N;
        if (L.p[10] == 0.0) { /* no distortion: the normalised pixel is the ray */
            for (Py_ssize_t n = 0; n < N; ++n) {
                double u = puv[2 * n], v = puv[2 * n + 1];
                int s = (u == u) & (v == v); /* finite: infinities were refused above */
                double yd = v - cy;
                yd *= fy_inv;
                double xd = u - cx;
                xd -= skew * yd; /* skew 0: xd unchanged */
                xd *= fx_inv;
                px[n] = s ? xd : 0.0;
                py[n] = s ? yd : 0.0;
                ps[n] = (unsigned char)s;
            }
            continue;
        }
        for (Py_ssize_t n = 0; n < N; ++n) {
            double u = puv[2 * n], v = puv[2 * n + 1];
            int s = (u == u) & (v == v);
            double yd = v - cy;
            yd *= fy_inv;
            double xd = u - cx;
            xd -= skew * yd;
            xd *= fx_inv;
            double xu, yu;
            start(&L, xd, yd, &xu, &yu);
            int done = newton_step(&xu, &yu, xd, yd, L.p + 5);
            px[n] = s ? xu : 0.0;
            py[n] = s ? yu : 0.0;
            ps[n] = (unsigned char)(s * (2 - done)); /* 2: more steps to take */
        }
        for (Py_ssize_t n = 0; n < N; ++n) {
            if (ps[n] != 2) continue;
            ps[n] = 1;
            double yd = puv[2 * n + 1] - cy;
            yd *= fy_inv;
            double xd = puv[2 * n] - cx;
            xd -= skew * yd;
            xd *= fx_inv;
            int done = 0;
            for (int s = 0; !done && s < EXTRA_STEPS; ++s) {
                done = newton_step(px + n, py + n, xd, yd, L.p + 5);
            }
            if (!done) slow[n_slow++] = (int64_t)(c * N + n);
        }
    }
    return n_slow;
}

/* Add one ray to the normal equations e (A00 A01 A02 A11 A12 A22 b0 b1 b2) of
 * _solvers.odle: ``A += w (I - d d' / d'd)``, ``b += A c`` for the ray of the
 * ideal normalised point (x, y) of camera L, with weight ``w`` (0 for unseen rays,
 * whose x, y are then 0). ``d = R' m`` with ``m = (x, y, 1)`` is the ray's direction,
 * ``d'd = m'm``, and ``A c = w c + (w / m'm) (m't) d`` since ``R c = -t``: the same
 * sums as the twin's matrix product of 7 numbers per ray, in fewer operations. */
static void add_ray(const Lens *L, double xv, double yv, double w, double e[9]) {
    const double *R = L->R, *t = L->t, *c = L->centre;
    double mm = xv * xv;
    mm += yv * yv;
    mm += 1.0;
    const double wn = w / mm;
    const double d0 = R[0] * xv + R[3] * yv + R[6];
    const double d1 = R[1] * xv + R[4] * yv + R[7];
    const double d2 = R[2] * xv + R[5] * yv + R[8];
    const double u0 = wn * d0, u1 = wn * d1, u2 = wn * d2;
    e[0] += w - u0 * d0;
    e[1] -= u0 * d1;
    e[2] -= u0 * d2;
    e[3] += w - u1 * d1;
    e[4] -= u1 * d2;
    e[5] += w - u2 * d2;
    const double mt = xv * t[0] + yv * t[1] + t[2];
    e[6] += w * c[0] + mt * u0;
    e[7] += w * c[1] + mt * u1;
    e[8] += w * c[2] + mt * u2;
}

/* Normal equations e solved by the adjugate (_normal_equations.Normal3) into P;
 * returns the conditioning ``3 det(A) / (tr(A) I2(A))``. */
static double solve3(const double e[9], double P[3]) {
    const double a00 = e[0], a01 = e[1], a02 = e[2], a11 = e[3], a12 = e[4], a22 = e[5];
    const double b0 = e[6], b1 = e[7], b2 = e[8];
    double c00 = a11 * a22 - a12 * a12;
    double c01 = a02 * a12 - a01 * a22;
    double c02 = a01 * a12 - a02 * a11;
    double c11 = a00 * a22 - a02 * a02;
    double c12 = a01 * a02 - a00 * a12;
    double c22 = a00 * a11 - a01 * a01;
    double det = a00 * c00 + a01 * c01 + a02 * c02;
    double inv = 1.0 / det;
    P[0] = (c00 * b0 + c01 * b1 + c02 * b2) * inv;
    P[1] = (c01 * b0 + c11 * b1 + c12 * b2) * inv;
    P[2] = (c02 * b0 + c12 * b1 + c22 * b2) * inv;
    return 3.0 * det / ((a00 + a11 + a22) * (c00 + c11 + c22));
}

/* Points of undistorted observations: _solvers.odle (one depth-weighted pass) and the
 * masking and residuals of FrameTriangulator._solve, point by point. X (N, 3) world
 * points (NaN where bad), n_views (N,); ray_px (C, N) if not NULL (NaN where unseen
 * or bad); rms (N,) if not NULL. x, y must be 0 where unseen. */
static void solve(const Rig *rig, Py_ssize_t N, const double *x, const double *y,
                  const unsigned char *seen, double *X, double *ray_px, double *rms,
                  int64_t *n_views) {
    const Py_ssize_t C = rig->C;
    for (Py_ssize_t n = 0; n < N; ++n) {
        double e[9] = {0.0}, P[3];
        int64_t views = 0;
        for (Py_ssize_t c = 0; c < C; ++c) {
            const Py_ssize_t i = c * N + n;
            const Lens L = rig_lens(rig, c);
            views += seen[i];
            add_ray(&L, x[i], y[i], (double)seen[i], e);
        }
        solve3(e, P);
        /* The depth-weighted pass: each ray's weight times (f / z)^2 at the estimate;
         * an unseen ray adds 0 times that (NaN where it is not finite, as the twin). */
        memset(e, 0, sizeof(e));
        for (Py_ssize_t c = 0; c < C; ++c) {
            const Py_ssize_t i = c * N + n;
            const Lens L = rig_lens(rig, c);
            double z = L.R[6] * P[0] + L.R[7] * P[1] + L.R[8] * P[2];
            z += L.t[2];
            z *= z;
            z = L.f2 / z;
            add_ray(&L, x[i], y[i], (double)seen[i] * z, e);
        }
        const double conditioning = solve3(e, P);
        const int bad = views < 2 || !(conditioning >= rig->min_conditioning);
        double sum2 = 0.0;
        for (Py_ssize_t c = 0; c < C; ++c) {
            const Py_ssize_t i = c * N + n;
            double r = NAN;
            if (seen[i] && !bad) {
                const Lens L = rig_lens(rig, c);
                const double *R = L.R;
                double xc = R[0] * P[0] + R[1] * P[1] + R[2] * P[2] + L.t[0];
                double yc = R[3] * P[0] + R[4] * P[1] + R[5] * P[2] + L.t[1];
                double zc = R[6] * P[0] + R[7] * P[1] + R[8] * P[2] + L.t[2];
                double ex = xc / zc - x[i];
                double ey = yc / zc - y[i];
                r = sqrt((ex * ex + ey * ey) * L.f2);
                sum2 += r * r;
            }
            if (ray_px) ray_px[i] = r;
        }
        double *out = X + 3 * n;
        if (bad) {
            out[0] = out[1] = out[2] = NAN;
        } else {
            out[0] = P[0] + rig->origin[0];
            out[1] = P[1] + rig->origin[1];
            out[2] = P[2] + rig->origin[2];
        }
        n_views[n] = views;
        if (rms) rms[n] = isnan(out[0]) ? NAN : sqrt(sum2 / (double)views);
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
    if (!PyArg_ParseTuple(args, "y*ny*w*w*w*w*", &rb, &N, &uvb, &xb, &yb, &sb, &slb)) return NULL;
    Rig rig;
    Py_ssize_t n_slow = 0;
    if (rig_parse(&rb, &rig) < 0 || check(&uvb, rig.C * N * 2, 8, "uv") < 0 ||
        check(&xb, rig.C * N, 8, "x") < 0 || check(&yb, rig.C * N, 8, "y") < 0 ||
        check(&sb, rig.C * N, 1, "seen") < 0 || check(&slb, rig.C * N, 8, "slow") < 0) {
        RELEASE(&rb, &uvb, &xb, &yb, &sb, &slb);
        return NULL;
    }
    Py_BEGIN_ALLOW_THREADS
    n_slow = undistort(&rig, N, uvb.buf, xb.buf, yb.buf, sb.buf, slb.buf);
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
    Py_buffer rb, uvb, xb, yb, sb, slb, Xb, rmsb, nvb;
    Py_ssize_t N;
    if (!PyArg_ParseTuple(args, "y*ny*w*w*w*w*w*w*w*", &rb, &N, &uvb, &xb, &yb, &sb, &slb, &Xb,
                          &rmsb, &nvb))
        return NULL;
    Rig rig;
    Py_ssize_t n_slow = 0;
    if (rig_parse(&rb, &rig) < 0 || check(&uvb, rig.C * N * 2, 8, "uv") < 0 ||
        check(&xb, rig.C * N, 8, "x") < 0 || check(&yb, rig.C * N, 8, "y") < 0 ||
        check(&sb, rig.C * N, 1, "seen") < 0 || check(&slb, rig.C * N, 8, "slow") < 0 ||
        check(&Xb, N * 3, 8, "X") < 0 || check(&rmsb, N, 8, "rms") < 0 ||
        check(&nvb, N, 8, "n_views") < 0) {
        RELEASE(&rb, &uvb, &xb, &yb, &sb, &slb, &Xb, &rmsb, &nvb);
        return NULL;
    }
    Py_BEGIN_ALLOW_THREADS
    n_slow = undistort(&rig, N, uvb.buf, xb.buf, yb.buf, sb.buf, slb.buf);
    if (n_slow == 0) solve(&rig, N, xb.buf, yb.buf, sb.buf, Xb.buf, NULL, rmsb.buf, nvb.buf);
    Py_END_ALLOW_THREADS
    RELEASE(&rb, &uvb, &xb, &yb, &sb, &slb, &Xb, &rmsb, &nvb);
    return PyLong_FromSsize_t(n_slow);
}

static PyMethodDef methods[] = {
    {"normalize", py_normalize, METH_VARARGS,
     "normalize(rig, N, uv, x, y, seen, slow) -> n_slow (-1: infinite values)\n\n"
     "Undistort uv (C, N, 2) into x, y (C, N) and seen (C, N, bool); the flat indices of\n"
     "observations that did not converge go to slow (C N int64)."},
    {"solve", py_solve, METH_VARARGS,
     "solve(rig, N, x, y, seen, X, ray_px, n_views) -> None\n\n"
     "Depth-weighted ODLE of undistorted observations: X (N, 3), ray_px (C, N),\n"
     "n_views (N, int64)."},
    {"frame", py_frame, METH_VARARGS,
     "frame(rig, N, uv, x, y, seen, slow, X, rms, n_views) -> n_slow\n\n"
     "normalize then, if every observation converged (n_slow 0), solve with the RMS of\n"
     "the ray residuals in rms (N,) instead of ray_px."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_c_frame",
    "Compiled twin of FrameTriangulator's numpy path (one live frame).", -1, methods,
    NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__c_frame(void) { return PyModule_Create(&module); }
