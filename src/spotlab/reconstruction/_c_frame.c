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
 * The loops run over chunks of 64 observations or points with the arithmetic in
 * straight lines (selects, no branches, no calls) so that the compiler vectorises them
 * at the baseline instruction set; -ffp-contract=off keeps every rounding as written.
 *
 * The rig is one float64 buffer built by Python once per rig (_frame_kernel.pack):
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
#define CHUNK 64      /* observations per vectorised pass */
/* Coefficients of the start polynomials g, a, h (_rays._DEGREES plus one). */
#define NG 7
#define NA 4
#define NH 4

/* Inlined into the loops, which the compiler vectorises only without calls. */
#if defined(__GNUC__)
#define INLINE static inline __attribute__((always_inline))
#else
#define INLINE static inline
#endif

typedef struct {
    const double *p; /* the camera's block */
    const double *g, *a, *h, *R, *t, *centre;
    double f2;
} Lens;

typedef struct {
    Py_ssize_t C;
    double min_conditioning;
    const double *origin;
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
    if (rig->C < 1 || d[5] != NG || d[6] != NA || d[7] != NH) {
        PyErr_SetString(PyExc_ValueError, "rig buffer header invalid");
        return -1;
    }
    rig->block = 27 + NG + NA + NH;
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
    L.g = L.p + 11;
    L.a = L.g + NG;
    L.h = L.a + NA;
    L.R = L.h + NH;
    L.t = L.R + 9;
    L.f2 = L.t[3];
    L.centre = L.t + 4;
    return L;
}

/* sum_i coef[i] rho^i, lowest power first (degree >= 1): _rays._horner. */
INLINE double horner(double rho, const double *coef, int n) {
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
INLINE int newton_step(double *px, double *py, double xd, double yd, const double *k) {
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
INLINE void start(const Lens *L, double xd, double yd, double *px, double *py) {
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

/* The fitted start and one Newton step for m observations of lens L (its coefficients
 * in local memory), pixel k at puv[k ns], puv[k ns + 1]: px, py (m,) the result (0
 * where unseen), state (m,) 0 unseen, 1 converged, 2 more steps to take. */
static void start_and_step(const Lens *L, const double *restrict puv, Py_ssize_t ns,
                           double *restrict px, double *restrict py, double *restrict state,
                           Py_ssize_t m) {
    const double cx = L->p[0], cy = L->p[1], skew = L->p[2], fx_inv = L->p[3];
    const double fy_inv = L->p[4];
    for (Py_ssize_t k = 0; k < m; ++k) {
        const double u = puv[k * ns], v = puv[k * ns + 1];
        const int s = !isnan(u) & !isnan(v);
        double yd = v - cy;
        yd *= fy_inv;
        double xd = u - cx;
        xd -= skew * yd;
        xd *= fx_inv;
        double xu, yu;
        start(L, xd, yd, &xu, &yu);
        const int done = newton_step(&xu, &yu, xd, yd, L->p + 5);
        px[k] = s ? xu : 0.0;
        py[k] = s ? yu : 0.0;
        state[k] = s ? (done ? 1.0 : 2.0) : 0.0;
    }
}

/* Undistort the N observations of every camera. uv (C, N, 2), or (N, C, 2) if
 * by_marker (the layout of a frame block's values); x, y (C, N) get the
 * ideal normalised coordinates (0 where unseen), seen (C, N) 0/1. Flat indices of the
 * observations still short after the extra Newton steps go to slow; returns their
 * count, or -1 if uv holds an infinite value (nothing else is then meaningful).
 *
 * The twin takes unseen observations at the principal point and replaces their result
 * by 0; here the arithmetic runs on the NaN (quietly) and the result is replaced by 0.
 * The first loop over a chunk of observations has no branch and stores doubles only
 * (no integer stores, the NaN test by isnan), so that the compiler vectorises it; the
 * second takes the few observations that need more steps. */
static Py_ssize_t undistort(const Rig *rig, Py_ssize_t N, const double *uv, int by_marker,
                            double *x, double *y, unsigned char *seen, int64_t *slow) {
    const Py_ssize_t C = rig->C;
    /* Strides (numbers) of uv between cameras and between markers. */
    const Py_ssize_t cs = by_marker ? 2 : 2 * N, ns = by_marker ? 2 * C : 2;
    int64_t any_inf = 0;
    for (Py_ssize_t i = 0; i < 2 * C * N; ++i) any_inf |= isinf(uv[i]) != 0;
    if (any_inf) return -1;
    Py_ssize_t n_slow = 0;
    double state[CHUNK]; /* per observation: 0 unseen, 1 done, 2 more steps to take */
    for (Py_ssize_t c = 0; c < C; ++c) {
        /* The lens in local copies: the compiler then knows the stores below do not
         * change them, and vectorises the loop (alias checks on every coefficient
         * would exceed its limit). */
        Lens L = rig_lens(rig, c);
        double p[11], g[NG], a[NA], h[NH];
        memcpy(p, L.p, sizeof p);
        memcpy(g, L.g, sizeof g);
        memcpy(a, L.a, sizeof a);
        memcpy(h, L.h, sizeof h);
        L.p = p;
        L.g = g;
        L.a = a;
        L.h = h;
        const double cx = p[0], cy = p[1], skew = p[2], fx_inv = p[3], fy_inv = p[4];
        const int distorted = p[10] != 0.0;
        for (Py_ssize_t n0 = 0; n0 < N; n0 += CHUNK) {
            const Py_ssize_t m = N - n0 < CHUNK ? N - n0 : CHUNK;
            const double *puv = uv + c * cs + n0 * ns;
            double *px = x + c * N + n0, *py = y + c * N + n0;
            if (!distorted) { /* the normalised pixel is the ray */
                for (Py_ssize_t k = 0; k < m; ++k) {
                    const double u = puv[k * ns], v = puv[k * ns + 1];
                    const int s = !isnan(u) & !isnan(v); /* infinities refused above */
                    double yd = v - cy;
                    yd *= fy_inv;
                    double xd = u - cx;
                    xd -= skew * yd; /* skew 0: xd unchanged */
                    xd *= fx_inv;
                    px[k] = s ? xd : 0.0;
                    py[k] = s ? yd : 0.0;
                    state[k] = s ? 1.0 : 0.0;
                }
            } else {
                start_and_step(&L, puv, ns, px, py, state, m);
            }
            for (Py_ssize_t k = 0; k < m; ++k) {
                seen[c * N + n0 + k] = state[k] != 0.0;
                if (state[k] != 2.0) continue;
                double yd = puv[k * ns + 1] - cy;
                yd *= fy_inv;
                double xd = puv[k * ns] - cx;
                xd -= skew * yd;
                xd *= fx_inv;
                int done = 0;
                for (int s = 0; !done && s < EXTRA_STEPS; ++s) {
                    done = newton_step(px + k, py + k, xd, yd, L.p + 5);
                }
                if (!done) slow[n_slow++] = (int64_t)(c * N + n0 + k);
            }
        }
    }
    return n_slow;
}

/* Add the rays of camera L to the normal equations of m points, e (9, CHUNK): for each
 * ``A += w (I - d d' / d'd)``, ``b += A c`` (_solvers.odle's sums) for the ray of the
 * ideal normalised point (x, y) with weight ``w`` (0 for unseen rays, whose x, y are
 * then 0). ``d = R' m`` with ``m = (x, y, 1)`` is the ray's direction, ``d'd = m'm``,
 * and ``A c = w c + (w / m'm) (m't) d`` since ``R c = -t``: the sums of the twin's
 * product of 7 numbers per ray, in a third of the operations. */
static void add_rays(const Lens *L, const double *restrict x, const double *restrict y,
                     const double *restrict w, double (*restrict e)[CHUNK], Py_ssize_t m) {
    double R[9], t[3], c[3];
    memcpy(R, L->R, sizeof R);
    memcpy(t, L->t, sizeof t);
    memcpy(c, L->centre, sizeof c);
    for (Py_ssize_t k = 0; k < m; ++k) {
        const double xv = x[k], yv = y[k], wk = w[k];
        double mm = xv * xv;
        mm += yv * yv;
        mm += 1.0;
        const double wn = wk / mm;
        const double d0 = R[0] * xv + R[3] * yv + R[6];
        const double d1 = R[1] * xv + R[4] * yv + R[7];
        const double d2 = R[2] * xv + R[5] * yv + R[8];
        const double u0 = wn * d0, u1 = wn * d1, u2 = wn * d2;
        e[0][k] += wk - u0 * d0;
        e[1][k] -= u0 * d1;
        e[2][k] -= u0 * d2;
        e[3][k] += wk - u1 * d1;
        e[4][k] -= u1 * d2;
        e[5][k] += wk - u2 * d2;
        const double mt = xv * t[0] + yv * t[1] + t[2];
        e[6][k] += wk * c[0] + mt * u0;
        e[7][k] += wk * c[1] + mt * u1;
        e[8][k] += wk * c[2] + mt * u2;
    }
}

/* The normal equations e (9, CHUNK) of m points solved by the adjugate
 * (_normal_equations.Normal3) into P (3, CHUNK), with the conditioning
 * ``3 det(A) / (tr(A) I2(A))``. */
static void solve3(double (*restrict e)[CHUNK], double (*restrict P)[CHUNK],
                   double *restrict conditioning, Py_ssize_t m) {
    for (Py_ssize_t k = 0; k < m; ++k) {
        const double a00 = e[0][k], a01 = e[1][k], a02 = e[2][k], a11 = e[3][k];
        const double a12 = e[4][k], a22 = e[5][k], b0 = e[6][k], b1 = e[7][k], b2 = e[8][k];
        double c00 = a11 * a22 - a12 * a12;
        double c01 = a02 * a12 - a01 * a22;
        double c02 = a01 * a12 - a02 * a11;
        double c11 = a00 * a22 - a02 * a02;
        double c12 = a01 * a02 - a00 * a12;
        double c22 = a00 * a11 - a01 * a01;
        double det = a00 * c00 + a01 * c01 + a02 * c02;
        double inv = 1.0 / det;
        P[0][k] = (c00 * b0 + c01 * b1 + c02 * b2) * inv;
        P[1][k] = (c01 * b0 + c11 * b1 + c12 * b2) * inv;
        P[2][k] = (c02 * b0 + c12 * b1 + c22 * b2) * inv;
        conditioning[k] = 3.0 * det / ((a00 + a11 + a22) * (c00 + c11 + c22));
    }
}

/* The weight of each ray of camera L in the depth-weighted pass: w times (f / z)^2 at
 * the first estimate P (an unseen ray: 0 times that, NaN where it is not finite, as
 * in the twin). */
static void depth_weights(const Lens *L, double (*restrict P)[CHUNK], const double *restrict w,
                          double *restrict wz, Py_ssize_t m) {
    const double r0 = L->R[6], r1 = L->R[7], r2 = L->R[8], tz = L->t[2], f2 = L->f2;
    for (Py_ssize_t k = 0; k < m; ++k) {
        double z = r0 * P[0][k] + r1 * P[1][k] + r2 * P[2][k];
        z += tz;
        z *= z;
        z = f2 / z;
        wz[k] = w[k] * z;
    }
}

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
    n_slow = undistort(&rig, N, uvb.buf, by_marker, xb.buf, yb.buf, sb.buf, slb.buf);
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
    n_slow = undistort(&rig, N, uvb.buf, by_marker, x, y, seen, slow);
    if (n_slow == 0) solve(&rig, N, x, y, seen, Xb.buf, NULL, rmsb.buf, nvb.buf);
    Py_END_ALLOW_THREADS
    PyMem_Free(work);
    RELEASE(&rb, &uvb, &Xb, &rmsb, &nvb);
    return PyLong_FromSsize_t(n_slow);
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
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_c_frame",
    "Compiled twin of FrameTriangulator's numpy path (one live frame).", -1, methods,
    NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__c_frame(void) { return PyModule_Create(&module); }
