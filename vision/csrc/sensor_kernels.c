/* The simulated camera's arithmetic, many rows in one call: the rotation noise of
 * vision/noise.py rotation_noise_batch (after its draws), the image lines and the
 * estimated camera's normals of benchmarks/sim/sensors.py noisy_features, and the leg
 * directions of vision/legs.py directions_from_edges.
 *
 * Operation for operation as their numpy path (the tests hold the two equal bit for
 * bit): the elementwise ufuncs round each operation (compiled with
 * -ffp-contract=off); numpy's matmul sums through its BLAS, whose kernels sum the
 * three products of a 3x3 product left to right, fused (fma, on processors with FMA)
 * or each rounded: the caller passes which (vision/kernels.py blas_mode, found by
 * comparing the two paths on a probe); numpy's einsum "...ij,...j->...i" sums a
 * three-term product in the two lanes of its baseline SIMD loop, (p0 + p2) + p1, and
 * adds that to its zeroed output; np.sin and np.cos of float64 are libm's.
 */
#include <math.h>
#include <stdint.h>

/* fma() inline where the processor has it (GCC's function multi-versioning on x86-64
 * Linux, chosen when loaded; elsewhere libm's): the same exact operation */
#if defined(__x86_64__) && defined(__linux__) && defined(__GNUC__) && !defined(__clang__)
#define FMA_CLONES __attribute__((target_clones("fma", "default")))
#else
#define FMA_CLONES
#endif

/* a . b as numpy's matmul sums it (see above) */
static inline double blas_dot3(int64_t fused, double a0, double a1, double a2, double b0,
                               double b1, double b2) {
  if (fused) return fma(a2, b2, fma(a1, b1, a0 * b0));
  return (a0 * b0 + a1 * b1) + a2 * b2;
}

/* x / |x| as vision.cameras.checks.unit (hexapod.se3.norms: (x0^2 + x1^2) + x2^2) */
static inline void unit3(double *x) {
  double norm = sqrt((x[0] * x[0] + x[1] * x[1]) + x[2] * x[2]);
  x[0] /= norm;
  x[1] /= norm;
  x[2] /= norm;
}

/* m vectors v (m, 3) rotated by the rotation noise of their draws: axes (m, 3) the
 * standard normals, fractions (m,) the uniforms in [0, 1), a the maximal angle [rad];
 * out (m, 3) = exp_so3(unit(axis) * fraction * a) v (hexapod.se3.exp_so3). */
FMA_CLONES
void hexapod_rotation_noise(const double *axes, const double *fractions, const double *v,
                            int64_t m, double a, int64_t fused, double *out) {
  for (int64_t i = 0; i < m; ++i) {
    const double *x = axes + 3 * i, *vi = v + 3 * i;
    double x0 = x[0], x1 = x[1], x2 = x[2];
    double norm = sqrt((x0 * x0 + x1 * x1) + x2 * x2);
    if (norm < 1e-12) {
      x0 = 0.0;
      x1 = 0.0;
      x2 = 1.0;
      norm = 1.0;
    }
    double f = fractions[i] * a;
    double w0 = x0 / norm * f, w1 = x1 / norm * f, w2 = x2 / norm * f;
    double theta = sqrt((w0 * w0 + w1 * w1) + w2 * w2);
    double ca, cb; /* I + ca K + cb K^2 */
    if (theta < 1e-6) {
      ca = 1.0 - theta * theta / 6.0;
      cb = 0.5 - theta * theta / 24.0;
    } else {
      ca = sin(theta) / theta;
      cb = (1.0 - cos(theta)) / (theta * theta);
    }
    const double K[3][3] = {{0.0, -w2, w1}, {w2, 0.0, -w0}, {-w1, w0, 0.0}};
    for (int r = 0; r < 3; ++r) {
      double R[3];
      for (int c = 0; c < 3; ++c) {
        double kk = blas_dot3(fused, K[r][0], K[r][1], K[r][2], K[0][c], K[1][c], K[2][c]);
        R[c] = (ca * K[r][c] + (r == c ? 1.0 : 0.0)) + kk * cb;
      }
      out[3 * i + r] = ((R[0] * vi[0] + R[2] * vi[2]) + R[1] * vi[1]) + 0.0;
    }
  }
}

/* The image lines of n rows of m normals (n, m, 3), row k through its true camera's
 * normal_to_line_matrix maps[k] (3, 3): lines = unit(normal maps[k]); and the normals
 * the estimated camera gives them back, normals_out = unit(line line_matrix) with the
 * estimated camera's line_matrix (3, 3). Row-major matrices; NaN stays NaN. */
FMA_CLONES
void hexapod_lines_normals(const double *normals, int64_t n, int64_t m, const double *maps,
                           const double *line_matrix, int64_t fused, double *lines,
                           double *normals_out) {
  const double *L = line_matrix;
  for (int64_t k = 0; k < n; ++k) {
    const double *M = maps + 9 * k;
    for (int64_t j = 0; j < m; ++j) {
      const double *x = normals + 3 * (m * k + j);
      double *l = lines + 3 * (m * k + j), *y = normals_out + 3 * (m * k + j);
      for (int c = 0; c < 3; ++c)
        l[c] = blas_dot3(fused, x[0], x[1], x[2], M[c], M[3 + c], M[6 + c]);
      unit3(l);
      for (int c = 0; c < 3; ++c)
        y[c] = blas_dot3(fused, l[0], l[1], l[2], L[c], L[3 + c], L[6 + c]);
      unit3(y);
    }
  }
}

/* vision.legs.directions_from_edges of count legs: normals (count, 2, 3) -> out (count,
 * 3), u = (n2 x n1) / |n2 x n1|. */
void hexapod_directions_from_edges(const double *normals, int64_t count, double *out) {
  for (int64_t i = 0; i < count; ++i) {
    const double *b = normals + 6 * i, *a = b + 3;
    double *d = out + 3 * i;
    d[0] = a[1] * b[2] - a[2] * b[1];
    d[1] = a[2] * b[0] - a[0] * b[2];
    d[2] = a[0] * b[1] - a[1] * b[0];
    unit3(d);
  }
}
