/* Observation of the legs by a camera, a batch of worlds in one call.
 *
 * The C version of vision.legs.observe_legs (the numpy reference): for each item,
 * its own robot (base and platform joint centres, leg radius, platform disc radius),
 * its own camera (pose, intrinsics, unified-model xi, OpenCV distortion) and its own
 * platform pose; the edges of the six cylindrical legs, and the visibility of each edge
 * sampled at n_samples points (imaged inside the image, not hidden by another leg's
 * solid finite cylinder nor by the platform disc).
 *
 * Leg-leg occlusion is tested point by point as in vision.occlusion (three intervals of
 * the ray parameter; the terms that do not depend on the sample computed once per leg,
 * those that do for 16 samples at once), after an exact culling: the segments from the projection centre to
 * the samples of one edge fill a triangle (the centre, the first and the last sample) of
 * that edge's interpretation plane, so a leg whose cylinder lies entirely outside one of
 * the four half-spaces bounding that triangle (the plane itself on either side, the two
 * planes through the centre and the end samples, the plane through the edge; both axis
 * ends farther than the radius outside it) hides none of them.
 *
 * Layout of one item's parameters (doubles), see vision/fast_observe.py:
 *   R (9, row-major) t (3): platform pose in the base frame
 *   A (18): base joint centres, base frame; E (18): platform joint centres, platform frame
 *   r, rho: leg radius, platform disc radius
 *   Rc (9, row-major) tc (3): camera_from_base
 *   fx, s, cx, fy, cy, xi, k1, k2, p1, p2, k3, rfold (12): intrinsics, OpenCV distortion
 *   (vision.distortion.RadialTangential), and the undistorted radius below which the
 *   distortion does not fold (0: no fold; radial distortion only: a fold radius that
 *   depends on the direction is not handled here, vision/fast_observe.py checks it)
 * = 74 doubles (vision/fast_observe.py INPUTS, whose names and sizes are these).
 * Outputs of one item: normals (36), exists (6), fraction (12), visible (12, 0/1),
 * A_cam (18), u (18), q (6), interval (24: s_first, s_last per edge), centre (3),
 * disc normal (3) = 138 doubles (vision/fast_observe.py OUTPUTS).
 */
#include <math.h>
#include <stddef.h>
#include <stdlib.h>

#define OBS_N_IN 74
#define OBS_N_OUT 138

static void mat_vec(const double *M, const double *x, double *y) {
  y[0] = M[0] * x[0] + M[1] * x[1] + M[2] * x[2];
  y[1] = M[3] * x[0] + M[4] * x[1] + M[5] * x[2];
  y[2] = M[6] * x[0] + M[7] * x[1] + M[8] * x[2];
}

static double dot3(const double *a, const double *b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

static void cross3(const double *a, const double *b, double *c) {
  c[0] = a[1] * b[2] - a[2] * b[1];
  c[1] = a[2] * b[0] - a[0] * b[2];
  c[2] = a[0] * b[1] - a[1] * b[0];
}

/* Whether a camera-frame point projects inside the image (vision.cameras.Camera.project). */
static int imaged(const double *X, const double *cam, int unified, double width,
                  double height) {
  double fx = cam[0], sk = cam[1], cx = cam[2], fy = cam[3], cy = cam[4], xi = cam[5];
  double z, rho;
  if (!unified || xi == 0.0) {
    z = X[2];
    if (!(z > 0.0)) return 0;
  } else {
    double cos_limit = xi < 1.0 / xi ? xi : 1.0 / xi;
    rho = sqrt(X[0] * X[0] + X[1] * X[1] + X[2] * X[2]);
    if (!(X[2] > -cos_limit * rho && rho > 0.0)) return 0;
    z = X[2] + xi * rho;
  }
  double x = X[0] / z, y = X[1] / z;
  double k1 = cam[6], k2 = cam[7], p1 = cam[8], p2 = cam[9], k3 = cam[10], rfold = cam[11];
  if (k1 != 0.0 || k2 != 0.0 || p1 != 0.0 || p2 != 0.0 || k3 != 0.0) {
    /* vision.distortion.RadialTangential.apply, operation for operation */
    double r2 = x * x + y * y;
    if (rfold > 0.0 && !(sqrt(r2) < rfold)) return 0;
    double L = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
    double xy2 = 2.0 * x * y;
    double xd = x * L + p1 * xy2 + p2 * (r2 + 2.0 * x * x);
    double yd = y * L + p1 * (r2 + 2.0 * y * y) + p2 * xy2;
    x = xd;
    y = yd;
  }
  double u = fx * x + sk * y + cx, v = fy * y + cy;
  return u >= -0.5 && u <= width - 0.5 && v >= -0.5 && v <= height - 0.5;
}

/* Whether every point of the segment P0-P1 is certainly imaged (then so are the samples
 * between them, without projecting each). Only without distortion:
 * - perspective, both ends in front (z > 0): the image of the segment is the segment
 *   between the images of its ends, and the image rectangle is convex: both ends inside
 *   (by 1e-6 px) suffice;
 * - unified: the projection is radially symmetric and its normalised radius
 *   sin(theta) / (cos(theta) + xi) grows with the angle theta to the axis wherever the
 *   model is valid (cos(theta) > -min(xi, 1/xi)). Along the segment, the direction runs
 *   over an arc (shorter than half a turn) of a great circle, on which cos(theta) is a
 *   sinusoid: it has at most one critical point there, and its minimum is at an end
 *   unless the derivative is negative at the start and positive at the end (the sign
 *   of d/ds (z / |P|) is that of d_z |P|^2 - z (P . d), d = P1 - P0). Then both ends
 *   valid and within the largest centred disc that the intrinsics map inside the image
 *   (radius: the distance of the principal point to the nearest border over the largest
 *   singular value of [[fx, s], [0, fy]], less 1e-9 relative) suffice.
 * 0 says nothing (the caller tests every sample). */
typedef struct {
  int mode; /* 0: no shortcut (a distortion, or no room), 1: perspective, 2: unified */
  double fx, sk, cx, fy, cy, xi, umin, umax, vmin, vmax, r_in2, cos_limit;
} ImageBox;

/* What all_imaged needs of a camera, computed once per item. */
static void image_box(const double *cam, int unified, double width, double height,
                      ImageBox *b) {
  b->fx = cam[0]; b->sk = cam[1]; b->cx = cam[2]; b->fy = cam[3]; b->cy = cam[4];
  b->xi = cam[5];
  b->mode = 0;
  if (cam[6] != 0.0 || cam[7] != 0.0 || cam[8] != 0.0 || cam[9] != 0.0 || cam[10] != 0.0)
    return;
  if (!unified || b->xi == 0.0) {
    b->umin = -0.5 + 1e-6; b->umax = width - 0.5 - 1e-6;
    b->vmin = -0.5 + 1e-6; b->vmax = height - 0.5 - 1e-6;
    b->mode = 1;
    return;
  }
  if (!(b->xi > 0.0)) return;
  double border = fmin(fmin(b->cx + 0.5, width - 0.5 - b->cx),
                       fmin(b->cy + 0.5, height - 0.5 - b->cy));
  if (!(border > 0.0)) return;
  double T = b->fx * b->fx + b->sk * b->sk + b->fy * b->fy, D = b->fx * b->fy;
  double disc = T * T - 4.0 * D * D;
  double smax = sqrt(0.5 * (T + sqrt(disc > 0.0 ? disc : 0.0)));
  double r_in = border / smax * (1.0 - 1e-9);
  b->r_in2 = r_in * r_in;
  b->cos_limit = b->xi < 1.0 / b->xi ? b->xi : 1.0 / b->xi;
  b->mode = 2;
}

/* The test above (ends compared without dividing: both sides multiplied by the positive
 * depth; the margins of the box cover the rounding). */
static int all_imaged(const double *P0, const double *P1, const ImageBox *b) {
  const double *P[2] = {P0, P1};
  if (b->mode == 0) return 0;
  if (b->mode == 1) {
    for (int k = 0; k < 2; ++k) {
      double Z = P[k][2];
      if (!(Z > 0.0)) return 0;
      double U = b->fx * P[k][0] + b->sk * P[k][1] + b->cx * Z;
      double V = b->fy * P[k][1] + b->cy * Z;
      if (!(U >= b->umin * Z && U <= b->umax * Z && V >= b->vmin * Z && V <= b->vmax * Z))
        return 0;
    }
    return 1;
  }
  double d[3] = {P1[0] - P0[0], P1[1] - P0[1], P1[2] - P0[2]}, slope[2];
  for (int k = 0; k < 2; ++k) {
    double rho2 = dot3(P[k], P[k]), rho = sqrt(rho2);
    if (!(rho > 0.0 && P[k][2] > -b->cos_limit * rho)) return 0;
    double z = P[k][2] + b->xi * rho; /* > 0 there */
    if (!(P[k][0] * P[k][0] + P[k][1] * P[k][1] <= b->r_in2 * (z * z))) return 0;
    slope[k] = d[2] * rho2 - P[k][2] * dot3(P[k], d);
  }
  return !(slope[0] < 0.0 && slope[1] > 0.0) && !isnan(slope[0]) && !isnan(slope[1]);
}

/* all_imaged for a batch of camera-frame segments (n x 6 doubles: P0, P1), one camera;
 * the test entry of the shortcut (vision.fast_observe.segments_certainly_imaged). */
void hexapod_segments_imaged(const double *segments, long long n, const double *cam,
                             long long unified, double width, double height,
                             double *out) {
  ImageBox box;
  image_box(cam, (int)unified, width, height, &box);
  for (long long k = 0; k < n; ++k)
    out[k] = all_imaged(segments + 6 * k, segments + 6 * k + 3, &box);
}

/* What legs_hit needs of leg j that does not depend on the sample: computed once per
 * item (the same operations as when they were computed for every sample). */
typedef struct {
  const double *u;
  double q, Au, Ap[3], c;
} LegAxis;

static void leg_axis(const double *A, const double *u, double q, double r, LegAxis *L) {
  L->u = u;
  L->q = q;
  L->Au = dot3(A, u);
  for (int k = 0; k < 3; ++k) L->Ap[k] = A[k] - L->Au * u[k];
  L->c = dot3(L->Ap, L->Ap) - r * r;
}

/* Whether the open segments from the origin to CHUNK samples cross leg l
 * (vision.occlusion; P[m][j]: coordinate m of sample j): first the quadratic's terms of
 * every sample, without a branch (vectorised), then the intervals of the samples whose
 * line meets the cylinder (the others miss it whatever the intervals). */
#define CHUNK 16
#if defined(__GNUC__) /* inlined: compiled for its caller's instruction set */
#define INLINE_IN_CLONES inline __attribute__((always_inline))
#else
#define INLINE_IN_CLONES inline
#endif
static INLINE_IN_CLONES void legs_hit(const double P[3][CHUNK], const LegAxis *L,
                                      unsigned char *hit) {
  const double *u = L->u;
  double Au = L->Au, q = L->q, c = L->c;
  double Pu[CHUNK], a[CHUNK], b[CHUNK], disc[CHUNK];
  for (int j = 0; j < CHUNK; ++j) {
    Pu[j] = P[0][j] * u[0] + P[1][j] * u[1] + P[2][j] * u[2];
    double Pp0 = P[0][j] - Pu[j] * u[0], Pp1 = P[1][j] - Pu[j] * u[1],
           Pp2 = P[2][j] - Pu[j] * u[2];
    a[j] = Pp0 * Pp0 + Pp1 * Pp1 + Pp2 * Pp2;
    b[j] = -2.0 * (Pp0 * L->Ap[0] + Pp1 * L->Ap[1] + Pp2 * L->Ap[2]);
    disc[j] = b[j] * b[j] - 4.0 * a[j] * c;
  }
  for (int j = 0; j < CHUNK; ++j) {
    int par = a[j] <= 1e-300;
    hit[j] = 0;
    if (!(disc[j] > 0.0 || par)) continue;
    double sq = sqrt(disc[j] > 0.0 ? disc[j] : 0.0);
    double a_safe = a[j] > 0.0 ? a[j] : 1.0;
    double s1, s2;
    if (par) {
      s1 = c < 0.0 ? -INFINITY : INFINITY;
      s2 = c < 0.0 ? INFINITY : -INFINITY;
    } else {
      s1 = (-b[j] - sq) / (2.0 * a_safe);
      s2 = (-b[j] + sq) / (2.0 * a_safe);
    }
    double lo_ax, hi_ax;
    if (Pu[j] == 0.0) {
      int inside = (-Au >= 0.0) && (-Au <= q);
      lo_ax = inside ? -INFINITY : INFINITY;
      hi_ax = inside ? INFINITY : -INFINITY;
    } else {
      double t0 = Au / Pu[j], t1 = (Au + q) / Pu[j];
      lo_ax = Pu[j] > 0.0 ? t0 : t1;
      hi_ax = Pu[j] > 0.0 ? t1 : t0;
    }
    double lo = fmax(fmax(s1, lo_ax), 0.0);
    double hi = fmin(fmin(s2, hi_ax), 1.0 - 1e-9);
    hit[j] = lo < hi;
  }
}

/* Whether the open segment from the origin to P crosses the platform disc. */
static int hits_disc(const double *P, const double *c, const double *nd, double rho) {
  double den = dot3(nd, P), num = dot3(nd, c);
  if (den == 0.0) return 0;
  double s = num / den;
  if (!(s > 0.0 && s < 1.0 - 1e-9)) return 0;
  double d[3] = {s * P[0] - c[0], s * P[1] - c[1], s * P[2] - c[2]};
  return dot3(d, d) <= rho * rho;
}

/* Compiled for the baseline instruction set and for AVX2, chosen when loaded (GCC's
 * function multi-versioning on x86-64 Linux; legs_hit inlined in each version): the same
 * IEEE operations, the samples' terms four at a time (no FMA: the flags keep
 * -ffp-contract=off). Returns 1 without memory for the samples' table, else 0. */
#if defined(__x86_64__) && defined(__linux__) && defined(__GNUC__) && !defined(__clang__)
__attribute__((target_clones("avx2", "default")))
#endif
int hexapod_observe_batch(const double *params, double *out, long long n, double width,
                          double height, long long unified, long long n_samples,
                          double min_fraction, long long occlusion) {
  /* each sample's parameter (k + 1/2) / n_samples, whole chunks (past the last sample:
     the last again, unused) */
  long long n_tab = (n_samples + CHUNK - 1) / CHUNK * CHUNK;
  double *s_tab = malloc((size_t)(n_tab > 0 ? n_tab : 1) * sizeof(double));
  if (s_tab == NULL) return 1;
  for (long long k = 0; k < n_tab; ++k)
    s_tab[k] = ((k < n_samples ? k : n_samples - 1) + 0.5) / (double)n_samples;
  for (long long item = 0; item < n; ++item) {
    const double *p = params + OBS_N_IN * item;
    double *o = out + OBS_N_OUT * item;
    const double *R = p, *t = p + 9, *Ab = p + 12, *E = p + 30;
    double r = p[48], rho_disc = p[49];
    const double *Rc = p + 50, *tc = p + 59, *cam = p + 62;
    double *normals = o, *exists = o + 36, *frac = o + 42, *vis = o + 54, *Ac = o + 66;
    double *uc = o + 84, *qc = o + 102, *interval = o + 108, *centre = o + 132;
    double *dnormal = o + 135;
    /* legs in the camera frame */
    for (int i = 0; i < 6; ++i) {
      double B[3], L[3], Lc[3];
      mat_vec(R, E + 3 * i, B);
      for (int k = 0; k < 3; ++k) L[k] = B[k] + t[k] - Ab[3 * i + k];
      double q = sqrt(L[0] * L[0] + L[1] * L[1] + L[2] * L[2]);
      for (int k = 0; k < 3; ++k) L[k] /= q;
      mat_vec(Rc, L, Lc);
      mat_vec(Rc, Ab + 3 * i, Ac + 3 * i);
      for (int k = 0; k < 3; ++k) {
        Ac[3 * i + k] += tc[k];
        uc[3 * i + k] = Lc[k];
      }
      qc[i] = q;
    }
    double ends[18]; /* far ends A_i + q_i u_i */
    for (int i = 0; i < 6; ++i)
      for (int k = 0; k < 3; ++k) ends[3 * i + k] = Ac[3 * i + k] + qc[i] * uc[3 * i + k];
    LegAxis axes[6];
    for (int l = 0; l < 6; ++l) leg_axis(Ac + 3 * l, uc + 3 * l, qc[l], r, &axes[l]);
    ImageBox box;
    image_box(cam, (int)unified, width, height, &box);
    mat_vec(Rc, t, centre);
    for (int k = 0; k < 3; ++k) centre[k] += tc[k];
    double ez[3] = {R[2], R[5], R[8]}; /* third column of R */
    mat_vec(Rc, ez, dnormal);
    /* edges */
    for (int i = 0; i < 6; ++i) {
      double *A = Ac + 3 * i, *u = uc + 3 * i, h[3], w[3];
      cross3(A, u, h);
      double hn = sqrt(dot3(h, h));
      exists[i] = hn > r ? 1.0 : 0.0;
      if (!(hn > r)) {
        for (int k = 0; k < 6; ++k) normals[6 * i + k] = NAN;
        continue;
      }
      double hh[3] = {h[0] / hn, h[1] / hn, h[2] / hn};
      cross3(u, hh, w);
      double s = r / hn;
      double cc = 1.0 - s * s;
      cc = sqrt(cc > 0.0 ? cc : 0.0);
      for (int k = 0; k < 3; ++k) {
        normals[6 * i + k] = cc * hh[k] - s * w[k];
        normals[6 * i + 3 + k] = -cc * hh[k] - s * w[k];
      }
    }
    /* visibility of the samples */
    for (int i = 0; i < 6; ++i) {
      for (int j = 0; j < 2; ++j) {
        int e = 2 * i + j;
        double *nrm = normals + 6 * i + 3 * j;
        interval[2 * e] = NAN;
        interval[2 * e + 1] = NAN;
        if (exists[i] == 0.0) {
          frac[e] = 0.0;
          vis[e] = 0.0;
          continue;
        }
        int cull[6], need_planes = 0;
        double P0[3], P1[3];
        double s0 = 0.5 / (double)n_samples, s1 = (n_samples - 0.5) / (double)n_samples;
        double base[3]; /* the edge's point at s = 0 */
        for (int m = 0; m < 3; ++m) {
          base[m] = Ac[3 * i + m] + r * nrm[m];
          P0[m] = base[m] + (s0 * qc[i]) * uc[3 * i + m];
          P1[m] = base[m] + (s1 * qc[i]) * uc[3 * i + m];
        }
        /* first culling: leg l wholly on one side of this edge's interpretation plane */
        for (int l = 0; l < 6; ++l) {
          cull[l] = 1;
          if (l == i || !occlusion) continue;
          double d0 = dot3(nrm, Ac + 3 * l), d1 = dot3(nrm, ends + 3 * l);
          cull[l] = (d0 > r && d1 > r) || (d0 < -r && d1 < -r);
          need_planes |= !cull[l];
        }
        /* second culling, only for the legs the first one kept: the three other planes
           of the triangle (the centre, the first and the last sample) */
        if (need_planes) {
          double m0[3], m1[3], m2[3], dl[3];
          for (int m = 0; m < 3; ++m) dl[m] = P1[m] - P0[m];
          cross3(nrm, P0, m0);
          cross3(nrm, P1, m1);
          cross3(nrm, dl, m2);
          double l0 = sqrt(dot3(m0, m0)), l1 = sqrt(dot3(m1, m1)), l2 = sqrt(dot3(m2, m2));
          if (l0 > 0.0 && l1 > 0.0 && l2 > 0.0) {
            double f0 = dot3(m0, P1) < 0.0 ? -1.0 / l0 : 1.0 / l0;
            double f1 = dot3(m1, P0) < 0.0 ? -1.0 / l1 : 1.0 / l1;
            double f2 = dot3(m2, P0) > 0.0 ? -1.0 / l2 : 1.0 / l2;
            for (int m = 0; m < 3; ++m) {
              m0[m] *= f0;
              m1[m] *= f1;
              m2[m] *= f2;
            }
            for (int l = 0; l < 6; ++l) {
              if (cull[l]) continue;
              const double *a = Ac + 3 * l, *end = ends + 3 * l;
              cull[l] = (dot3(m0, a) < -r && dot3(m0, end) < -r) ||
                        (dot3(m1, a) < -r && dot3(m1, end) < -r) ||
                        (dot3(m2, a) - dot3(m2, P0) < -r && dot3(m2, end) - dot3(m2, P0) < -r);
            }
          }
        }
        /* the platform disc can hide a sample only if its plane separates the sample
           from the centre: not when the centre and both end samples are on one side */
        double c_side = -dot3(dnormal, centre);
        double e0 = dot3(dnormal, P0) + c_side, e1 = dot3(dnormal, P1) + c_side;
        int disc_test = !((c_side > 0.0 && e0 > 0.0 && e1 > 0.0) ||
                          (c_side < 0.0 && e0 < 0.0 && e1 < 0.0));
        int inside = all_imaged(P0, P1, &box);
        int tests = !inside || (occlusion && disc_test);
        for (int l = 0; l < 6 && !tests; ++l) tests = occlusion && !cull[l];
        if (!tests) { /* every sample imaged, none can be hidden */
          frac[e] = 1.0;
          vis[e] = 1.0 >= min_fraction - 1e-12 ? 1.0 : 0.0;
          interval[2 * e] = 0.5 / (double)n_samples;
          interval[2 * e + 1] = (n_samples - 0.5) / (double)n_samples;
          continue;
        }
        int count = 0, first = -1, last = -1, near[6], n_near = 0;
        for (int l = 0; l < 6; ++l) /* the legs the culling kept, in order */
          if (!cull[l]) near[n_near++] = l;
        for (long long k0 = 0; k0 < n_samples; k0 += CHUNK) {
          int nk = n_samples - k0 < CHUNK ? (int)(n_samples - k0) : CHUNK;
          double P[3][CHUNK];
          unsigned char ok[CHUNK];
          for (int m = 0; m < 3; ++m)
            for (int j = 0; j < CHUNK; ++j)
              P[m][j] = base[m] + (s_tab[k0 + j] * qc[i]) * uc[3 * i + m];
          for (int j = 0; j < nk; ++j) {
            double X[3] = {P[0][j], P[1][j], P[2][j]};
            ok[j] = inside || imaged(X, cam, (int)unified, width, height);
          }
          if (occlusion) {
            for (int l = 0; l < n_near; ++l) {
              unsigned char hit[CHUNK];
              legs_hit(P, &axes[near[l]], hit);
              for (int j = 0; j < nk; ++j) ok[j] &= !hit[j];
            }
            if (disc_test)
              for (int j = 0; j < nk; ++j) {
                double X[3] = {P[0][j], P[1][j], P[2][j]};
                if (ok[j] && hits_disc(X, centre, dnormal, rho_disc)) ok[j] = 0;
              }
          }
          for (int j = 0; j < nk; ++j)
            if (ok[j]) {
              ++count;
              if (first < 0) first = (int)(k0 + j);
              last = (int)(k0 + j);
            }
        }
        frac[e] = count / (double)n_samples;
        vis[e] = frac[e] >= min_fraction - 1e-12 ? 1.0 : 0.0;
        if (count) {
          interval[2 * e] = (first + 0.5) / (double)n_samples;
          interval[2 * e + 1] = (last + 0.5) / (double)n_samples;
        }
      }
    }
  }
  free(s_tab);
  return 0;
}
