/*
 * The numeric core shared by spotlab.reconstruction's compiled kernels (_c_frame.c):
 * the rig buffer, undistortion in the order of operations of _rays.py, and the sums and
 * 3x3 solve of _solvers.odle. Static functions only; included by one C file per module.
 *
 * The rig is one float64 buffer built by Python once per rig (_frame_kernel.pack):
 *   header  C, min_conditioning, origin[3], n_g, n_a, n_h
 *   C camera blocks of 27 + n_g + n_a + n_h numbers:
 *           cx, cy, skew, fx_inv, fy_inv, k1, k2, p1, p2, k3, distorted,
 *           g[n_g], a[n_a], h[n_h], R[9] (row-major), t[3] (centred frame), f2,
 *           centre[3] (the perspective centre -R't, centred frame)
 * The loops run over chunks of 64 observations or points with the arithmetic in
 * straight lines (selects, no branches, no calls) so that the compiler vectorises them
 * at the baseline instruction set; -ffp-contract=off keeps every rounding as written.
 */

#ifndef SPOTLAB_FRAME_CORE_H
#define SPOTLAB_FRAME_CORE_H

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

/* The fitted start and one Newton step for m seen observations of lens L (its
 * coefficients in local memory), pixels (u[k], v[k]): px, py (m,) the result, state
 * (m,) 1 converged, 2 more steps to take. */
static void start_and_step(const Lens *L, const double *restrict u, const double *restrict v,
                           double *restrict px, double *restrict py, double *restrict state,
                           Py_ssize_t m) {
    const double cx = L->p[0], cy = L->p[1], skew = L->p[2], fx_inv = L->p[3];
    const double fy_inv = L->p[4];
    for (Py_ssize_t k = 0; k < m; ++k) {
        double yd = v[k] - cy;
        yd *= fy_inv;
        double xd = u[k] - cx;
        xd -= skew * yd;
        xd *= fx_inv;
        double xu, yu;
        start(L, xd, yd, &xu, &yu);
        const int done = newton_step(&xu, &yu, xd, yd, L->p + 5);
        px[k] = xu;
        py[k] = yu;
        state[k] = done ? 1.0 : 2.0;
    }
}

/* start_and_step of the seen ones among m observations, pixel k at puv[k ns],
 * puv[k ns + 1]: they are gathered first (without branches), so that the arithmetic
 * runs on seen observations only; px, py get 0 and state 0 where unseen. */
static void start_and_step_seen(const Lens *L, const double *restrict puv, Py_ssize_t ns,
                                double *restrict px, double *restrict py,
                                double *restrict state, Py_ssize_t m) {
    double u[CHUNK], v[CHUNK], ox[CHUNK], oy[CHUNK], os[CHUNK];
    int idx[CHUNK];
    Py_ssize_t n = 0;
    for (Py_ssize_t k = 0; k < m; ++k) {
        const double uk = puv[k * ns], vk = puv[k * ns + 1];
        idx[n] = (int)k;
        u[n] = uk;
        v[n] = vk;
        n += !isnan(uk) & !isnan(vk);
        px[k] = 0.0;
        py[k] = 0.0;
        state[k] = 0.0;
    }
    start_and_step(L, u, v, ox, oy, os, n);
    for (Py_ssize_t j = 0; j < n; ++j) {
        px[idx[j]] = ox[j];
        py[idx[j]] = oy[j];
        state[idx[j]] = os[j];
    }
}

/* Undistort N observations of every camera: observation n of camera c at
 * uv[c cs + n ns], uv[c cs + n ns + 1] (cs, ns strides in numbers: (C, N, 2) has 2 N
 * and 2, a frame block's (N, C, 2) 2 and 2 C). x, y (C, N) get the ideal normalised
 * coordinates (0 where unseen), seen (C, N) 0/1. Flat indices (c N + n) of the
 * observations still short after the extra Newton steps go to slow; returns their
 * count, or -1 if uv holds an infinite value (nothing else is then meaningful).
 *
 * The twin undistorts the seen observations only and puts 0 where unseen; so does the
 * lens's loop here, on the seen observations of a chunk gathered together (for a lens
 * without distortion the arithmetic runs on the NaN, quietly, and the result is
 * replaced by 0). The arithmetic loops over a chunk have no branch and store doubles
 * only (no integer stores, the NaN test by isnan), so that the compiler vectorises
 * them; a last loop takes the few observations that need more steps. */
static Py_ssize_t undistort(const Rig *rig, Py_ssize_t N, const double *uv, Py_ssize_t cs,
                            Py_ssize_t ns, double *x, double *y, unsigned char *seen,
                            int64_t *slow) {
    const Py_ssize_t C = rig->C;
    int64_t any_inf = 0;
    if (ns == 2) { /* each camera's observations in one run */
        for (Py_ssize_t c = 0; c < C; ++c)
            for (Py_ssize_t i = 0; i < 2 * N; ++i) any_inf |= isinf(uv[c * cs + i]) != 0;
    } else { /* marker by marker: the whole (N, C, 2) block */
        for (Py_ssize_t i = 0; i < 2 * C * N; ++i) any_inf |= isinf(uv[i]) != 0;
    }
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
                start_and_step_seen(&L, puv, ns, px, py, state, m);
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

#endif /* SPOTLAB_FRAME_CORE_H */
