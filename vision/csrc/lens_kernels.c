#include <math.h>
#include <stdint.h>

/* Lens maps of the camera models (vision/cameras/) and their Jacobians, the same
 * arithmetic as their numpy reference (parts_numpy), operation by operation (compiled
 * with -ffp-contract=off). Each writes (x_d, y_d, j11, j12, j21, j22) at n points into
 * out: 6 arrays of n, one after the other. */

/* OpenCV's 14-coefficient distortion (vision/cameras/distortion_full.py,
 * OpenCVLens.parts_numpy): the map (x_d, y_d) and its Jacobian (j11, j12, j21, j22)
 * at n points; c: the 14 coefficients, T: the tilt matrix (3x3, row-major), tilted:
 * whether tau_x or tau_y is nonzero. out: 6 arrays of n, one after the other. */
static void opencv_lens_parts(const double *xs, const double *ys, int64_t n, const double *c,
                       const double *T, int64_t tilted, double *out) {
    const double k1 = c[0], k2 = c[1], p1 = c[2], p2 = c[3], k3 = c[4], k4 = c[5],
                 k5 = c[6], k6 = c[7], s1 = c[8], s2 = c[9], s3 = c[10], s4 = c[11];
    double *oxd = out, *oyd = out + n, *o11 = out + 2 * n, *o12 = out + 3 * n,
           *o21 = out + 4 * n, *o22 = out + 5 * n;
    for (int64_t i = 0; i < n; i++) {
        const double x = xs[i], y = ys[i];
        const double r2 = x * x + y * y;
        const double num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        const double den = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6));
        const double dnum = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2);
        const double dden = k4 + r2 * (2.0 * k5 + 3.0 * k6 * r2);
        const double L = num / den;
        const double Lr = (dnum * den - num * dden) / (den * den);
        const double xy = x * y;
        const double px = s1 + 2.0 * s2 * r2;
        const double py = s3 + 2.0 * s4 * r2;
        const double xu = x * L + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x * x) + r2 * (s1 + s2 * r2);
        const double yu = y * L + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xy + r2 * (s3 + s4 * r2);
        const double a11 = L + 2.0 * x * x * Lr + 2.0 * p1 * y + 6.0 * p2 * x + 2.0 * x * px;
        const double a12 = 2.0 * xy * Lr + 2.0 * p1 * x + 2.0 * p2 * y + 2.0 * y * px;
        const double a21 = 2.0 * xy * Lr + 2.0 * p1 * x + 2.0 * p2 * y + 2.0 * x * py;
        const double a22 = L + 2.0 * y * y * Lr + 6.0 * p1 * y + 2.0 * p2 * x + 2.0 * y * py;
        if (!tilted) {
            oxd[i] = xu; oyd[i] = yu; o11[i] = a11; o12[i] = a12; o21[i] = a21; o22[i] = a22;
            continue;
        }
        const double w = T[6] * xu + T[7] * yu + T[8];
        const double inv = (w != 0) ? 1.0 / w : 1.0;
        const double xd = (T[0] * xu + T[1] * yu + T[2]) * inv;
        const double yd = (T[3] * xu + T[4] * yu + T[5]) * inv;
        const double b11 = (T[0] - xd * T[6]) * inv;
        const double b12 = (T[1] - xd * T[7]) * inv;
        const double b21 = (T[3] - yd * T[6]) * inv;
        const double b22 = (T[4] - yd * T[7]) * inv;
        oxd[i] = xd; oyd[i] = yd;
        o11[i] = b11 * a11 + b12 * a21; o12[i] = b11 * a12 + b12 * a22;
        o21[i] = b21 * a11 + b22 * a21; o22[i] = b21 * a12 + b22 * a22;
    }
}

/* OpenCV's five coefficients (k1, k2, p1, p2, k3): RadialTangential.parts_numpy. */
static void brown_parts(const double *xs, const double *ys, int64_t n, const double *c,
                        double *out) {
    const double k1 = c[0], k2 = c[1], p1 = c[2], p2 = c[3], k3 = c[4];
    for (int64_t i = 0; i < n; i++) {
        const double x = xs[i], y = ys[i];
        const double r2 = x * x + y * y;
        const double L = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        const double M = 2.0 * k1 + r2 * (4.0 * k2 + 6.0 * k3 * r2);
        const double xy2 = 2.0 * x * y;
        const double j12 = x * y * M + 2.0 * p1 * x + 2.0 * p2 * y;
        out[i] = x * L + p1 * xy2 + p2 * (r2 + 2.0 * x * x);
        out[n + i] = y * L + p1 * (r2 + 2.0 * y * y) + p2 * xy2;
        out[2 * n + i] = L + x * x * M + 2.0 * p1 * y + 6.0 * p2 * x;
        out[3 * n + i] = j12;
        out[4 * n + i] = j12;
        out[5 * n + i] = L + y * y * M + 6.0 * p1 * y + 2.0 * p2 * x;
    }
}

/* The factor f(r) and f'(r) / r of the radial models (RadialLens._factor):
 * kind 2 Kannala-Brandt (k1..k4), 3 double sphere (xi, alpha), 4 extended unified
 * (alpha, beta). */
static void radial_factor(int64_t kind, const double *c, double r, double *f, double *h) {
    if (kind == 2) {
        const double k1 = c[0], k2 = c[1], k3 = c[2], k4 = c[3];
        const int small = r <= 1e-8;
        const double rr = small ? 1.0 : r;
        const double theta = atan(rr);
        const double t2 = theta * theta;
        const double t4 = t2 * t2;
        const double t6 = t4 * t2;
        const double t8 = t4 * t4;
        const double theta_d = theta * (1.0 + k1 * t2 + k2 * t4 + k3 * t6 + k4 * t8);
        const double ff = theta_d / rr;
        const double drho = 1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3
                                                                         + 9.0 * k4 * t2)));
        const double hh = (drho / (1.0 + rr * rr) - ff) / (rr * rr);
        *f = small ? 1.0 : ff;
        *h = small ? 2.0 * (k1 - 1.0 / 3.0) : hh;
    } else if (kind == 3) {
        const double xi = c[0], a = c[1];
        const double d1 = sqrt(r * r + 1.0);
        const double w = xi * d1 + 1.0;
        const double d2 = sqrt(r * r + w * w);
        const double den = a * d2 + (1.0 - a) * w;
        const double dden_r = a * (1.0 + w * xi / d1) / d2 + (1.0 - a) * xi / d1;
        *f = 1.0 / den;
        *h = -dden_r / (den * den);
    } else {
        const double a = c[0], b = c[1];
        const double d = sqrt(b * r * r + 1.0);
        const double den = a * d + 1.0 - a;
        *f = 1.0 / den;
        *h = -(a * b / d) / (den * den);
    }
}

/* A radial model: RadialLens.parts_numpy. */
static void radial_parts(int64_t kind, const double *xs, const double *ys, int64_t n,
                         const double *c, double *out) {
    for (int64_t i = 0; i < n; i++) {
        const double x = xs[i], y = ys[i];
        double f, h;
        radial_factor(kind, c, hypot(x, y), &f, &h);
        const double j12 = h * x * y;
        out[i] = x * f;
        out[n + i] = y * f;
        out[2 * n + i] = f + h * x * x;
        out[3 * n + i] = j12;
        out[4 * n + i] = j12;
        out[5 * n + i] = f + h * y * y;
    }
}

/* The lens map of kind 0 (OpenCV's 14 coefficients, T its tilt, tilted: a tilt angle
 * is nonzero), 1 (OpenCV's five), 2, 3 or 4 (radial_factor). */
void lens_parts(int64_t kind, const double *xs, const double *ys, int64_t n,
                const double *c, const double *T, int64_t tilted, double *out) {
    if (kind == 0)
        opencv_lens_parts(xs, ys, n, c, T, tilted, out);
    else if (kind == 1)
        brown_parts(xs, ys, n, c, out);
    else
        radial_parts(kind, xs, ys, n, c, out);
}
