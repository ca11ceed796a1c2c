/*
 * Compiled cores of the leg-edge detectors (the vision/detect/ package), called
 * through ctypes by vision/kernels.py. Each function computes exactly what the numpy
 * path of vision/detect/ computes (same decisions, same arithmetic order; compiled with
 * -ffp-contract=off so that no multiply-add is fused), and the tests check that the
 * two agree. All arrays are C-contiguous; sizes are given explicitly.
 *
 *   omni_scan   seed 003's circle scan: polar sampling, threshold half-way to the
 *               median, dark bands, association to the predicted legs, sub-sample
 *               edges at the gradient peaks.
 *   fit_planes  robust batched plane fit through the origin (smallest eigenvector of
 *               the scatter matrix, outlier rejection, refit), oriented like the
 *               prediction.
 *   omni_detect both, for a camera with fx = fy and no skew (the rays of a circle
 *               share their elevation): one call per frame.
 *   track_points, track_pass, align_shift  the perspective tracker's search pass (the
 *               edge points; with the rays and the fit for an ideal lens) and its
 *               alignment.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

#define PI_ 3.141592653589793
#define TWO_PI_ (2.0 * PI_)

/* numpy's remainder (floor modulo, sign of the divisor). */
static double py_mod(double a, double b) {
  double m = fmod(a, b);
  if (m != 0.0) {
    if ((b < 0) != (m < 0)) m += b;
  } else {
    m = copysign(0.0, b);
  }
  return m;
}

/* (a + pi) % (2 pi) - pi, as vision.detect.omni._wrap. */
static double wrap_angle(double a) { return py_mod(a + PI_, TWO_PI_) - PI_; }

static int64_t imod(int64_t a, int64_t n) {
  int64_t m = a % n;
  return m < 0 ? m + n : m;
}

static double bilinear(const uint8_t *img, const int64_t *base, const double *fx,
                       const double *fy, int64_t W, int64_t k) {
  int64_t b = base[k];
  double x = fx[k], y = fy[k];
  double v00 = img[b], v01 = img[b + 1], v10 = img[b + W], v11 = img[b + W + 1];
  return (1 - y) * ((1 - x) * v00 + x * v01) + y * ((1 - x) * v10 + x * v11);
}

/* Azimuth [rad] of the edge at the transition at sample j of a circle: the strongest
 * gradient of polarity `sign` (-1: falling, band start; +1: rising, band end) among
 * the central differences at samples j-2 .. j+1 of the bilinear signal, refined by a
 * parabola (vision.detect.OmniDetector._scan). */
static double edge_azimuth(const uint8_t *img, const int64_t *base, const double *fx,
                           const double *fy, int64_t W, int64_t row, int64_t N, int64_t j,
                           double sign) {
  double b[6], g[4];
  for (int o = 0; o < 6; ++o) b[o] = bilinear(img, base, fx, fy, W, row + imod(j + o - 3, N));
  for (int m = 0; m < 4; ++m) g[m] = 0.5 * (b[m + 2] - b[m]) * sign;
  int k = 0;
  for (int m = 1; m < 4; ++m)
    if (g[m] > g[k]) k = m;
  if (k < 1) k = 1;
  if (k > 2) k = 2;
  double gm = g[k - 1], g0 = g[k], gp = g[k + 1];
  double den = gm - 2 * g0 + gp;
  double frac = 0.0;
  if (den < 0) frac = 0.5 * (gm - gp) / den;
  if (frac < -0.5) frac = -0.5;
  if (frac > 0.5) frac = 0.5;
  return ((double)(j - 2 + k) + frac) * (TWO_PI_ / (double)N);
}

/*
 * img: (H*W) uint8. idx: (C*N) nearest-pixel flat indices. base, fx, fy: (C*N)
 * bilinear data. axis_ref, gate_ref, width_ref: (6*C); e1_first: (6*C) 0/1.
 * pts_a: (6*2*C) out, azimuth [rad] of each edge point, NaN where none.
 * Returns 0, or 1 if out of memory.
 */
int omni_scan(const uint8_t *img, const int64_t *idx, const int64_t *base, const double *fx,
              const double *fy, int64_t W, int64_t C, int64_t N, const double *axis_ref,
              const double *gate_ref, const double *width_ref, const uint8_t *e1_first,
              double min_contrast, double width_tol, double *pts_a) {
  uint8_t *sig = malloc((size_t)N);
  int64_t *starts = malloc(sizeof(int64_t) * (size_t)N);
  int64_t *ends = malloc(sizeof(int64_t) * (size_t)N);
  if (!sig || !starts || !ends) {
    free(sig); free(starts); free(ends);
    return 1;
  }
  for (int64_t k = 0; k < 6 * 2 * C; ++k) pts_a[k] = NAN;
  const double step_a = TWO_PI_ / (double)N;
  for (int64_t c = 0; c < C; ++c) {
    const int64_t row = c * N;
    uint8_t lo = 255;
    int64_t hist[256] = {0};
    for (int64_t j = 0; j < N; ++j) {
      uint8_t s = img[idx[row + j]];
      sig[j] = s;
      if (s < lo) lo = s;
      ++hist[s];
    }
    /* background: the lower median, sample of rank (N - 1) / 2 */
    int64_t rank = (N - 1) / 2, acc = 0;
    unsigned bg = 0;
    for (unsigned v = 0; v < 256; ++v) {
      acc += hist[v];
      if (acc > rank) {
        bg = v;
        break;
      }
    }
    uint8_t thr_i = (uint8_t)(((unsigned)lo + bg + 1u) / 2u);
    if ((double)bg - (double)lo < min_contrast) continue; /* flat circle: no band */
    int64_t ns = 0, ne = 0;
    int prev = sig[N - 1] < thr_i;
    for (int64_t j = 0; j < N; ++j) {
      int d = sig[j] < thr_i;
      if (d && !prev) starts[ns++] = j;
      if (!d && prev) ends[ne++] = j;
      prev = d;
    }
    if (ns == 0 || ne == 0) continue;
    double best_d[6];
    int64_t best_s[6], best_e[6];
    for (int l = 0; l < 6; ++l) best_s[l] = -1;
    int64_t e_ptr = 0;
    for (int64_t b = 0; b < ns; ++b) {
      int64_t js = starts[b];
      while (e_ptr < ne && ends[e_ptr] < js) ++e_ptr;
      int64_t je = e_ptr < ne ? ends[e_ptr] : ends[0];
      int64_t span = imod(je - js, N);
      double a_c = ((double)js + 0.5 * (double)span) * step_a;
      double width = (double)span * step_a;
      int leg = 0;
      double dbest = INFINITY;
      for (int l = 0; l < 6; ++l) {
        double d = fabs(wrap_angle(a_c - axis_ref[l * C + c]));
        if (l == 0 || d < dbest) {
          dbest = d;
          leg = l;
        }
      }
      double w_ref = width_ref[leg * C + c];
      int ok = (dbest < gate_ref[leg * C + c]) && (width < width_tol * w_ref + step_a) &&
               (width > w_ref / width_tol - step_a);
      if (ok && (best_s[leg] < 0 || dbest < best_d[leg])) {
        best_d[leg] = dbest;
        best_s[leg] = js;
        best_e[leg] = je;
      }
    }
    for (int l = 0; l < 6; ++l) {
      if (best_s[l] < 0) continue;
      double a_start = edge_azimuth(img, base, fx, fy, W, row, N, best_s[l], -1.0);
      double a_end = edge_azimuth(img, base, fx, fy, W, row, N, best_e[l], 1.0);
      int first1 = e1_first[l * C + c] != 0;
      pts_a[(l * 2 + 0) * C + c] = first1 ? a_start : a_end;
      pts_a[(l * 2 + 1) * C + c] = first1 ? a_end : a_start;
    }
  }
  free(sig); free(starts); free(ends);
  return 0;
}

/* Eigenvector of the smallest eigenvalue of a symmetric 3x3 matrix (cyclic Jacobi). */
static void smallest_eigenvector(const double M[9], double out[3]) {
  double a[3][3], v[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) a[i][j] = M[3 * i + j];
  for (int sweep = 0; sweep < 50; ++sweep) {
    double off = fabs(a[0][1]) + fabs(a[0][2]) + fabs(a[1][2]);
    double scale = fabs(a[0][0]) + fabs(a[1][1]) + fabs(a[2][2]);
    if (off == 0.0 || off <= 1e-300 || off < 1e-18 * scale) break;
    for (int p = 0; p < 2; ++p) {
      for (int q = p + 1; q < 3; ++q) {
        if (a[p][q] == 0.0) continue;
        double theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
        double t = (theta >= 0 ? 1.0 : -1.0) / (fabs(theta) + sqrt(theta * theta + 1.0));
        double c = 1.0 / sqrt(t * t + 1.0), s = t * c;
        for (int k = 0; k < 3; ++k) { /* A <- A J */
          double akp = a[k][p], akq = a[k][q];
          a[k][p] = c * akp - s * akq;
          a[k][q] = s * akp + c * akq;
        }
        for (int k = 0; k < 3; ++k) { /* A <- J^T A */
          double apk = a[p][k], aqk = a[q][k];
          a[p][k] = c * apk - s * aqk;
          a[q][k] = s * apk + c * aqk;
        }
        for (int k = 0; k < 3; ++k) { /* V <- V J */
          double vkp = v[k][p], vkq = v[k][q];
          v[k][p] = c * vkp - s * vkq;
          v[k][q] = s * vkp + c * vkq;
        }
      }
    }
  }
  int m = 0;
  for (int i = 1; i < 3; ++i)
    if (a[i][i] < a[m][m]) m = i;
  double nrm = sqrt(v[0][m] * v[0][m] + v[1][m] * v[1][m] + v[2][m] * v[2][m]);
  for (int k = 0; k < 3; ++k) out[k] = v[k][m] / nrm;
}

/*
 * Robust plane fit of E edges of up to N rays each (vision.detect.common._robust_fit).
 * rays: (E*N*3) unit rays (anything where not valid); valid: (E*N) 0/1;
 * px_per_rad: (E*N); predicted: (E*3). Out: normals (E*3, NaN where not visible),
 * visible (E), count (E), rms (E, NaN where not visible), inliers (E*N).
 *
 * Per edge: w = valid; up to iterations + 1 times: fit the weighted points (at
 * least 2, else the edge keeps no normal and stops), residuals of every valid ray
 * [px], new weights = valid and residual <= outlier_px; stop when unchanged.
 */
void fit_planes(const double *rays, const uint8_t *valid, const double *px_per_rad,
                const double *predicted, int64_t E, int64_t N, double outlier_px,
                int64_t min_points, double max_rms_px, int64_t iterations, double *normals,
                uint8_t *visible, int64_t *count, double *rms, uint8_t *inliers) {
  for (int64_t e = 0; e < E; ++e) {
    const double *X = rays + e * N * 3;
    const uint8_t *val = valid + e * N;
    const double *ppr = px_per_rad + e * N;
    uint8_t *w = inliers + e * N;
    double n[3] = {NAN, NAN, NAN};
    int64_t cnt = 0;
    for (int64_t k = 0; k < N; ++k) {
      w[k] = val[k] ? 1 : 0;
      cnt += w[k];
    }
    int fitted = 0;
    double ss = 0.0;
    for (int64_t it = 0; it <= iterations; ++it) {
      if (cnt < 2) break;
      double M[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
      for (int64_t k = 0; k < N; ++k) {
        if (!w[k]) continue;
        const double *x = X + 3 * k;
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) M[3 * i + j] += x[i] * x[j];
      }
      smallest_eigenvector(M, n);
      fitted = 1;
      int changed = 0;
      int64_t new_cnt = 0;
      ss = 0.0;
      for (int64_t k = 0; k < N; ++k) {
        uint8_t nw = 0;
        double r_px = 0.0;
        if (val[k]) {
          const double *x = X + 3 * k;
          r_px = fabs(x[0] * n[0] + x[1] * n[1] + x[2] * n[2]) * ppr[k];
          nw = r_px <= outlier_px;
        }
        if (nw != w[k]) changed = 1;
        w[k] = nw;
        new_cnt += nw;
        if (nw) ss += r_px * r_px;
      }
      /* rms over the new weights with the residuals of this fit (as numpy) */
      cnt = new_cnt;
      if (!changed) break;
    }
    const double *pr = predicted + 3 * e;
    int pred_ok = isfinite(pr[0]) && isfinite(pr[1]) && isfinite(pr[2]);
    double r = sqrt(ss / (double)(cnt > 1 ? cnt : 1));
    int vis = fitted && cnt >= min_points && r <= max_rms_px && pred_ok;
    count[e] = cnt;
    visible[e] = (uint8_t)vis;
    rms[e] = vis ? r : NAN;
    double s = n[0] * pr[0] + n[1] * pr[1] + n[2] * pr[2];
    double sg = s < 0 ? -1.0 : 1.0;
    for (int i = 0; i < 3; ++i) normals[3 * e + i] = vis ? sg * n[i] : NAN;
    if (!vis)
      for (int64_t k = 0; k < N; ++k) w[k] = 0;
  }
}

/*
 * The whole omnidirectional detection of one frame (OmniDetector.detect with an
 * isotropic camera): omni_scan, then the ray of each edge point on its circle
 * (elevation z[c], azimuth a), then fit_planes, then the inlier pixels.
 * radii, z, ppr_circle: (C). predicted: (12*3).
 * Work: pts_a (12*C), rays (12*C*3), valid (12*C), ppr (12*C).
 * Out: normals (12*3), visible (12), count (12), rms (12), inliers (12*C),
 * points (12*C*2, NaN where not an inlier).
 */
int omni_detect(const uint8_t *img, const int64_t *idx, const int64_t *base, const double *fx,
                const double *fy, int64_t W, int64_t C, int64_t N, const double *axis_ref,
                const double *gate_ref, const double *width_ref, const uint8_t *e1_first,
                double min_contrast, double width_tol, const double *radii, const double *z,
                const double *ppr_circle, double cx, double cy, const double *predicted,
                double outlier_px, int64_t min_points, double max_rms_px, int64_t iterations,
                double *pts_a, double *rays, uint8_t *valid, double *ppr, double *normals,
                uint8_t *visible, int64_t *count, double *rms, uint8_t *inliers,
                double *points) {
  if (omni_scan(img, idx, base, fx, fy, W, C, N, axis_ref, gate_ref, width_ref, e1_first,
                min_contrast, width_tol, pts_a))
    return 1;
  for (int64_t e = 0; e < 12; ++e) {
    for (int64_t c = 0; c < C; ++c) {
      int64_t k = e * C + c;
      double a = pts_a[k];
      int ok = !isnan(a) && !isinf(a);
      valid[k] = (uint8_t)ok;
      if (!ok) a = 0.0;
      double zc = z[c];
      double q = 1.0 - zc * zc;
      double rho = sqrt(q > 0.0 ? q : 0.0);
      double ca = cos(a), sa = sin(a);
      rays[3 * k + 0] = rho * ca;
      rays[3 * k + 1] = rho * sa;
      rays[3 * k + 2] = zc;
      ppr[k] = ppr_circle[c];
      pts_a[k] = a; /* reused below for the pixels */
    }
  }
  fit_planes(rays, valid, ppr, predicted, 12, C, outlier_px, min_points, max_rms_px,
             iterations, normals, visible, count, rms, inliers);
  for (int64_t e = 0; e < 12; ++e) {
    for (int64_t c = 0; c < C; ++c) {
      int64_t k = e * C + c;
      if (inliers[k]) {
        points[2 * k + 0] = cx + radii[c] * cos(pts_a[k]);
        points[2 * k + 1] = cy + radii[c] * sin(pts_a[k]);
      } else {
        points[2 * k + 0] = NAN;
        points[2 * k + 1] = NAN;
      }
    }
  }
  return 0;
}

/* ------------------------------------------------------------------------------ */
/* Perspective tracker: one search pass (PerspectiveTracker._pass).                 */
/* ------------------------------------------------------------------------------ */
#define NO_GRADIENT (-1e6)

/* Bilinear interpolation, 0 outside [0, W-1] x [0, H-1] (vision.detect.profiles._bilinear_zero). */
static double bilinear_zero(const uint8_t *img, int64_t W, int64_t H, double x, double y) {
  if (!(x >= 0 && x <= (double)(W - 1) && y >= 0 && y <= (double)(H - 1))) return 0.0;
  double fx0 = floor(x), fy0 = floor(y);
  if (fx0 > (double)(W - 2)) fx0 = (double)(W - 2);
  if (fy0 > (double)(H - 2)) fy0 = (double)(H - 2);
  int64_t x0 = (int64_t)fx0, y0 = (int64_t)fy0;
  double fx = x - (double)x0, fy = y - (double)y0;
  const uint8_t *p = img + y0 * W + x0;
  double v00 = p[0], v01 = p[1], v10 = p[W], v11 = p[W + 1];
  return (1 - fy) * ((1 - fx) * v00 + fx * v01) + fy * ((1 - fx) * v10 + fx * v11);
}

/* The element of rank (n - 1) / 2 of v (the lower median; v is reordered):
 * quickselect with the median of three as pivot (the value equals that of a sort). */
static double lower_median(double *v, int64_t n) {
  int64_t lo = 0, hi = n - 1, k = (n - 1) / 2;
  while (hi > lo) {
    int64_t mid = lo + (hi - lo) / 2;
    double a = v[lo], b = v[mid], c = v[hi];
    double pivot = a < b ? (b < c ? b : (a < c ? c : a)) : (a < c ? a : (b < c ? c : b));
    int64_t i = lo, j = hi;
    while (i <= j) {
      while (v[i] < pivot) ++i;
      while (v[j] > pivot) --j;
      if (i <= j) {
        double tmp = v[i];
        v[i] = v[j];
        v[j] = tmp;
        ++i;
        --j;
      }
    }
    if (k <= j) {
      hi = j;
    } else if (k >= i) {
      lo = i;
    } else {
      return v[k];
    }
  }
  return v[k];
}

static double sgn(double x) { return (double)((x > 0) - (x < 0)); }

/* The image bands of the six legs, for the occlusion gate. */
typedef struct {
  double s1[6], c0[6][2], axu[6][2], alen[6];
} Bands;

static void leg_bands(const double *seg, const double *lines, Bands *b) {
  for (int k = 0; k < 6; ++k) {
    const double *l1 = lines + (k * 2 + 0) * 3, *l2 = lines + (k * 2 + 1) * 3;
    b->s1[k] = sgn(l1[0] * l2[0] + l1[1] * l2[1]);
    for (int d = 0; d < 2; ++d) {
      /* seg[k, e, end, d]: centre of the two edges' end points */
      double a0 = 0.5 * (seg[((k * 2 + 0) * 2 + 0) * 2 + d] + seg[((k * 2 + 1) * 2 + 0) * 2 + d]);
      double a1 = 0.5 * (seg[((k * 2 + 0) * 2 + 1) * 2 + d] + seg[((k * 2 + 1) * 2 + 1) * 2 + d]);
      b->c0[k][d] = a0;
      b->axu[k][d] = a1 - a0;
    }
    b->alen[k] = sqrt(b->axu[k][0] * b->axu[k][0] + b->axu[k][1] * b->axu[k][1]);
    b->axu[k][0] /= b->alen[k];
    b->axu[k][1] /= b->alen[k];
  }
}

/* Whether pixel (px, py) lies inside, or within `margin` of, the band of a leg other
 * than `leg` (vision.detect.PerspectiveTracker._contested). */
static int in_other_band(const Bands *b, const double *lines, int64_t leg, double px, double py,
                         double margin) {
  for (int k = 0; k < 6; ++k) {
    if (k == leg) continue;
    const double *l1 = lines + (k * 2 + 0) * 3, *l2 = lines + (k * 2 + 1) * 3;
    double d1 = px * l1[0] + py * l1[1] + l1[2];
    double d2 = px * l2[0] + py * l2[1] + l2[2];
    int between = (d1 * d2 * b->s1[k] <= 0) || fabs(d1) < margin || fabs(d2) < margin;
    double tt = (px - b->c0[k][0]) * b->axu[k][0] + (py - b->c0[k][1]) * b->axu[k][1];
    int along = tt >= -margin && tt <= b->alen[k] + margin;
    if (between && along && isfinite(tt)) return 1;
  }
  return 0;
}

/*
 * The edge points of one search pass (PerspectiveTracker._pass up to the plane fit).
 * P: (12*M*2) samples; out: (12*M*2) outward unit normals of each sample (the same for
 * every sample of a straight edge, the normal of the curve at each sample through a
 * distorted lens); search: (12); R: profile half-length; t: (M) sample positions along
 * the edges; gate: (12*M*2) the samples in the coordinates of the occlusion gate (P
 * itself, or the ideal image's pixels through a distorted lens); seg: (6*2*2*2)
 * predicted segments and lines: (6*2*3) pixel lines with unit (a, b), both in the
 * gate's coordinates; margin: (12*M) occlusion margin of each sample [gate px].
 * Work: prof (2R+1), pairs (M*(M-1)/2). Out: offset (12*M) along out [px], valid
 * (12*M), points (12*M*2) P + offset out (0 where not valid).
 */
void track_points(const uint8_t *img, int64_t W, int64_t H, const double *P, const double *out,
                  const double *search, int64_t R, int64_t M, const double *t,
                  const double *gate, const double *seg, const double *lines,
                  const double *margin, double min_contrast, double outlier_px, double *offset,
                  uint8_t *valid, double *prof, double *pairs, double *points) {
  const int64_t L0 = 2 * R + 1, L = 2 * R - 1;
  Bands bands;
  leg_bands(seg, lines, &bands);
  for (int64_t e = 0; e < 12; ++e) {
    const int64_t leg = e / 2;
    const double s_e = search[e];
    for (int64_t m = 0; m < M; ++m) {
      const int64_t idx = e * M + m;
      const double px = P[2 * idx], py = P[2 * idx + 1];
      const double ox = out[2 * idx], oy = out[2 * idx + 1];
      valid[idx] = 0;
      offset[idx] = 0.0;
      int finite = 1;
      for (int64_t j = 0; j < L0; ++j) {
        double o = (double)(j - R);
        double x = px + o * ox, y = py + o * oy;
        if (!isfinite(x) || !isfinite(y)) finite = 0;
        prof[j] = bilinear_zero(img, W, H, x, y);
      }
      /* gradient candidates at offsets o = -(R-1) .. R-1 (index k = 0 .. L-1) */
      int64_t kbest = 0;
      double gbest = 0.0;
      for (int64_t k = 0; k < L; ++k) {
        double g = NO_GRADIENT;
        double o = (double)(k + 1 - R);
        double x = px + o * ox, y = py + o * oy;
        int in_img = x >= 0 && x <= (double)(W - 1) && y >= 0 && y <= (double)(H - 1);
        if (fabs(o) <= s_e && in_img) g = 0.5 * (prof[k + 2] - prof[k]);
        if (k == 0 || g > gbest) {
          gbest = g;
          kbest = k;
        }
      }
      if (L < 3 || !finite || kbest < 1 || kbest > L - 2 || !(gbest >= min_contrast)) continue;
      double gv[3];
      for (int d = -1; d <= 1; ++d) {
        int64_t k = kbest + d;
        double o = (double)(k + 1 - R);
        double x = px + o * ox, y = py + o * oy;
        int in_img = x >= 0 && x <= (double)(W - 1) && y >= 0 && y <= (double)(H - 1);
        gv[d + 1] = (fabs(o) <= s_e && in_img) ? 0.5 * (prof[k + 2] - prof[k]) : NO_GRADIENT;
      }
      double den = gv[0] - 2 * gv[1] + gv[2];
      double frac = 0.0;
      if (den < 0 && den > -1e5) frac = 0.5 * (gv[0] - gv[2]) / den;
      if (frac < -0.5) frac = -0.5;
      if (frac > 0.5) frac = 0.5;
      /* occlusion gate: inside (or within the margin of) another leg's band */
      if (in_other_band(&bands, lines, leg, gate[2 * idx], gate[2 * idx + 1], margin[idx]))
        continue;
      offset[idx] = (double)(kbest + 1 - R) + frac;
      valid[idx] = 1;
    }
    /* Theil-Sen line through (t, offset), then residual test */
    const double *off = offset + e * M;
    uint8_t *val = valid + e * M;
    int64_t np_ = 0;
    for (int64_t i = 0; i < M; ++i)
      for (int64_t j = i + 1; j < M; ++j)
        if (val[i] && val[j]) pairs[np_++] = (off[i] - off[j]) / (t[i] - t[j]);
    if (np_ == 0) {
      for (int64_t i = 0; i < M; ++i) val[i] = 0;
    } else {
      double b = lower_median(pairs, np_);
      int64_t nr = 0;
      for (int64_t i = 0; i < M; ++i)
        if (val[i]) pairs[nr++] = off[i] - b * t[i];
      double a = lower_median(pairs, nr);
      for (int64_t i = 0; i < M; ++i)
        if (val[i] && !(fabs(off[i] - (a + b * t[i])) <= 2.0 * outlier_px)) val[i] = 0;
    }
    for (int64_t m = 0; m < M; ++m) {
      const int64_t idx = e * M + m;
      double u = 0.0, v = 0.0;
      if (valid[idx]) {
        u = P[2 * idx] + offset[idx] * out[2 * idx];
        v = P[2 * idx + 1] + offset[idx] * out[2 * idx + 1];
      }
      points[2 * idx] = u;
      points[2 * idx + 1] = v;
    }
  }
}

/*
 * One whole search pass of an ideal lens: track_points, then the rays of the points
 * (Kinv: (9) row-major inverse intrinsics), their pixels per radian (f, cx, cy: mean
 * focal length and principal point [px]), fit_planes (predicted: (12*3) normals).
 * Work: rays (12*M*3), ppr (12*M). Out: as fit_planes, and points (12*M*2; NaN where
 * not an inlier).
 */
int track_pass(const uint8_t *img, int64_t W, int64_t H, const double *P, const double *out,
               const double *search, int64_t R, int64_t M, const double *t, const double *gate,
               const double *seg, const double *lines, const double *margin,
               double min_contrast, double outlier_px, const double *Kinv, double f, double cx,
               double cy, const double *predicted, int64_t min_points, double max_rms_px,
               int64_t iterations, double *offset, uint8_t *valid, double *rays, double *ppr,
               double *prof, double *pairs, double *normals, uint8_t *visible,
               int64_t *count, double *rms, uint8_t *inliers, double *points) {
  track_points(img, W, H, P, out, search, R, M, t, gate, seg, lines, margin, min_contrast,
               outlier_px, offset, valid, prof, pairs, points);
  for (int64_t idx = 0; idx < 12 * M; ++idx) {
    double u = points[2 * idx], v = points[2 * idx + 1];
    double h0 = u * Kinv[0] + v * Kinv[1] + Kinv[2];
    double h1 = u * Kinv[3] + v * Kinv[4] + Kinv[5];
    double h2 = u * Kinv[6] + v * Kinv[7] + Kinv[8];
    double nh = sqrt(h0 * h0 + h1 * h1 + h2 * h2);
    rays[3 * idx] = h0 / nh;
    rays[3 * idx + 1] = h1 / nh;
    rays[3 * idx + 2] = h2 / nh;
    double dx = valid[idx] ? u - cx : 0.0, dy = valid[idx] ? v - cy : 0.0;
    double rho2 = (dx * dx + dy * dy) / (f * f);
    ppr[idx] = f * sqrt(1.0 + rho2);
  }
  fit_planes(rays, valid, ppr, predicted, 12, M, outlier_px, min_points, max_rms_px,
             iterations, normals, visible, count, rms, inliers);
  for (int64_t k = 0; k < 12 * M; ++k) {
    if (!inliers[k]) {
      points[2 * k] = NAN;
      points[2 * k + 1] = NAN;
    }
  }
  return 0;
}

/*
 * The image translation aligning the predicted edges with the image
 * (PerspectiveTracker.align). P: (12*M*2) samples on the predicted edges; out:
 * (12*2) outward normals (the profiles' direction: one per edge); gate, seg, lines,
 * margin: the occlusion gate (as track_points); R = ceil(max_shift) + 1. Work: G
 * (12*(2R-1)), prof (2R+1), d (2R-1). Out: shift (2).
 */
void align_shift(const uint8_t *img, int64_t W, int64_t H, const double *P, const double *out,
                 const double *gate, const double *seg, const double *lines,
                 const double *margin, int64_t M, int64_t R, double max_shift, double *G,
                 double *prof, double *d, double *shift) {
  const int64_t L0 = 2 * R + 1, L = 2 * R - 1;
  Bands bands;
  leg_bands(seg, lines, &bands);
  for (int64_t k = 0; k < 12 * L; ++k) G[k] = 0.0;
  for (int64_t e = 0; e < 12; ++e) {
    const double ox = out[2 * e], oy = out[2 * e + 1];
    double *Ge = G + e * L;
    for (int64_t m = 0; m < M; ++m) {
      const int64_t idx = e * M + m;
      const double px = P[2 * idx], py = P[2 * idx + 1];
      if (!(isfinite(px) && isfinite(py))) continue;
      if (in_other_band(&bands, lines, e / 2, gate[2 * idx], gate[2 * idx + 1], margin[idx]))
        continue;
      for (int64_t j = 0; j < L0; ++j) {
        double o = (double)(j - R);
        prof[j] = bilinear_zero(img, W, H, px + o * ox, py + o * oy);
      }
      for (int64_t k = 0; k < L; ++k) {
        double g = 0.5 * (prof[k + 2] - prof[k]);
        Ge[k] += g > 0.0 ? g : 0.0;
      }
    }
    if (!(isfinite(ox) && isfinite(oy)))
      for (int64_t k = 0; k < L; ++k) Ge[k] = 0.0;
  }
  int64_t nd = 0;
  for (int64_t k = -(R - 1); k < R; ++k)
    if (fabs((double)k) <= max_shift) d[nd++] = (double)k;
  double best = -INFINITY, bx = 0.0, by = 0.0;
  for (int64_t a = 0; a < nd; ++a) {
    for (int64_t b = 0; b < nd; ++b) {
      double dx = d[a], dy = d[b], score = 0.0;
      for (int64_t e = 0; e < 12; ++e) {
        double ox = out[2 * e], oy = out[2 * e + 1];
        double o = dx * ox + dy * oy;
        if (isnan(o)) o = 0.0;
        o += (double)(R - 1);
        double fk = floor(o);
        if (fk < 0.0) fk = 0.0;
        if (fk > (double)(L - 2)) fk = (double)(L - 2);
        int64_t k0 = (int64_t)fk;
        double w = o - (double)k0;
        if (w < 0.0) w = 0.0;
        if (w > 1.0) w = 1.0;
        score += (1 - w) * G[e * L + k0] + w * G[e * L + k0 + 1];
      }
      if (score > best) {
        best = score;
        bx = dx;
        by = dy;
      }
    }
  }
  shift[0] = bx;
  shift[1] = by;
}
