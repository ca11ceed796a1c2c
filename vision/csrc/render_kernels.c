/*
 * Exact-coverage polygon filling for the renderer (vision/render.py), called through
 * ctypes by vision/kernels.py.
 *
 * The coverage of a pixel is the area of its unit square inside the shape (the box
 * filter of an ideal sensor pixel), computed exactly by signed-area accumulation:
 * every edge adds, to the cells of each row it crosses, the signed area between
 * itself and the cell's left side; a running sum along the row then gives the
 * winding-weighted area of each pixel. Several contours are filled as one shape
 * (nonzero rule: each contour is oriented to positive area, the coverage is
 * min(|sum|, 1)). Pixel (i, j) covers [i - 1/2, i + 1/2] x [j - 1/2, j + 1/2] in the
 * camera's pixel coordinates (OpenCV's convention: integers at pixel centres).
 *
 * The image is blended by coverage: v <- v + (level - v) * coverage, rounded.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define MAX_RANGES 8 /* touched cell ranges kept per row; more: the row is scanned whole */

typedef struct {
  double *acc;     /* H * (W + 2) accumulation cells, zero between calls */
  int64_t *lo;     /* H: first touched cell of each row (W + 2 if none) */
  int64_t *hi;     /* H: last touched cell of each row (-1 if none) */
  int64_t *rx;     /* H * MAX_RANGES * 2: touched cell ranges [x0, x1] of each row */
  int64_t *rn;     /* H: number of ranges of each row (MAX_RANGES + 1: overflow) */
  int64_t W, H;
} Raster;

static void touch(Raster *r, int64_t y, int64_t x0, int64_t x1) {
  if (x0 < r->lo[y]) r->lo[y] = x0;
  if (x1 > r->hi[y]) r->hi[y] = x1;
  int64_t n = r->rn[y];
  if (n < MAX_RANGES) {
    r->rx[(y * MAX_RANGES + n) * 2] = x0;
    r->rx[(y * MAX_RANGES + n) * 2 + 1] = x1;
  }
  if (n <= MAX_RANGES) r->rn[y] = n + 1;
}

/* Adds the signed area of one segment lying in one row band, with x already inside
 * [0, W] (cells 0 .. W + 1 of the row). d = signed height of the segment in the row. */
static void cell_line(Raster *r, int64_t y, double xa, double xb, double d) {
  double *a = r->acc + y * (r->W + 2);
  double x0 = xa < xb ? xa : xb, x1 = xa < xb ? xb : xa;
  double x0f = floor(x0);
  int64_t x0i = (int64_t)x0f;
  double x1c = ceil(x1);
  int64_t x1i = (int64_t)x1c;
  if (x1i <= x0i + 1) {
    /* within one cell: the area right of the segment's mean x */
    double xm = 0.5 * (xa + xb) - x0f;
    a[x0i] += d - d * xm;
    a[x0i + 1] += d * xm;
    touch(r, y, x0i, x0i + 1);
    return;
  }
  double s = 1.0 / (x1 - x0);
  double fx0 = x0 - x0f;
  double a0 = 0.5 * s * (1.0 - fx0) * (1.0 - fx0);
  double fx1 = x1 - x1c + 1.0;
  double am = 0.5 * s * fx1 * fx1;
  a[x0i] += d * a0;
  if (x1i == x0i + 2) {
    a[x0i + 1] += d * (1.0 - a0 - am);
  } else {
    double a1 = s * (1.5 - fx0);
    a[x0i + 1] += d * (a1 - a0);
    for (int64_t xi = x0i + 2; xi < x1i - 1; ++xi) a[xi] += d * s;
    double a2 = a1 + (double)(x1i - x0i - 3) * s;
    a[x1i - 1] += d * (1.0 - a2 - am);
  }
  a[x1i] += d * am;
  touch(r, y, x0i, x1i);
}

/* One edge from (xa, ya) to (xb, yb) in cell coordinates (pixel i spans [i, i+1]),
 * with x inside [0, W]; sign = +1 or -1 (orientation of its contour). */
static void edge_clamped(Raster *r, double xa, double ya, double xb, double yb, double sign) {
  if (ya == yb) return;
  double dir = sign;
  if (ya > yb) {
    double t = xa; xa = xb; xb = t;
    t = ya; ya = yb; yb = t;
    dir = -dir;
  }
  double dxdy = (xb - xa) / (yb - ya);
  int64_t y0 = (int64_t)floor(ya);
  int64_t y1 = (int64_t)ceil(yb);
  if (y0 < 0) y0 = 0;
  if (y1 > r->H) y1 = r->H;
  for (int64_t y = y0; y < y1; ++y) {
    double top = (double)y > ya ? (double)y : ya;
    double bot = (double)(y + 1) < yb ? (double)(y + 1) : yb;
    if (bot <= top) continue;
    double xt = xa + (top - ya) * dxdy, xbt = xa + (bot - ya) * dxdy;
    if (xt < 0.0) xt = 0.0;
    if (xbt < 0.0) xbt = 0.0;
    double Wd = (double)r->W;
    if (xt > Wd) xt = Wd;
    if (xbt > Wd) xbt = Wd;
    cell_line(r, y, xt, xbt, dir * (bot - top));
  }
}

/* Splits an edge where it crosses x = 0 and x = W, so that the parts outside the
 * image become vertical segments on its border (their area lies wholly left of, or
 * wholly right of, every pixel of the row). */
static void edge(Raster *r, double xa, double ya, double xb, double yb, double sign) {
  double Wd = (double)r->W;
  double ts[4] = {0.0, 1.0, 1.0, 1.0};
  int n = 1;
  if (xa != xb) {
    double t0 = (0.0 - xa) / (xb - xa), tW = (Wd - xa) / (xb - xa);
    double lo = t0 < tW ? t0 : tW, hi = t0 < tW ? tW : t0;
    if (lo > 0.0 && lo < 1.0) ts[n++] = lo;
    if (hi > 0.0 && hi < 1.0) ts[n++] = hi;
  }
  ts[n++] = 1.0;
  for (int k = 0; k + 1 < n; ++k) {
    double ta = ts[k], tb = ts[k + 1];
    if (tb <= ta) continue;
    double x0 = xa + ta * (xb - xa), y0 = ya + ta * (yb - ya);
    double x1 = xa + tb * (xb - xa), y1 = ya + tb * (yb - ya);
    if (k + 2 == n) { x1 = xb; y1 = yb; }
    if (k == 0) { x0 = xa; y0 = ya; }
    edge_clamped(r, x0, y0, x1, y1, sign);
  }
}

/* Writes coverage c to pixels [x0, x1] of a row (clipped to the image). */
static void put_run(uint8_t *row, double *crow, int64_t W, int64_t x0, int64_t x1, double c,
                    double lv, uint8_t full) {
  if (x0 < 0) x0 = 0;
  if (x1 > W - 1) x1 = W - 1;
  if (x1 < x0) return;
  if (c >= 1.0 - 1e-12) {
    if (row) memset(row + x0, full, (size_t)(x1 - x0 + 1));
    if (crow)
      for (int64_t x = x0; x <= x1; ++x) crow[x] = 1.0;
  } else if (c > 1e-12) {
    for (int64_t x = x0; x <= x1; ++x) {
      if (row) {
        double v = (double)row[x];
        v += (lv - v) * c;
        row[x] = (uint8_t)floor(v + 0.5);
      }
      if (crow) crow[x] = c;
    }
  }
}

/* Resolves one row: running sum of its cells (zeroing them) over the touched ranges,
 * constant runs between them. */
static void resolve_row(Raster *r, int64_t y, uint8_t *row, double *crow, double lv,
                        uint8_t full) {
  double *a = r->acc + y * (r->W + 2);
  int64_t W = r->W;
  int64_t n = r->rn[y];
  int64_t xs[MAX_RANGES], xe[MAX_RANGES];
  if (n > MAX_RANGES) {
    n = 1;
    xs[0] = r->lo[y];
    xe[0] = r->hi[y];
  } else {
    for (int64_t k = 0; k < n; ++k) {
      int64_t a0 = r->rx[(y * MAX_RANGES + k) * 2], a1 = r->rx[(y * MAX_RANGES + k) * 2 + 1];
      int64_t j = k;
      while (j > 0 && xs[j - 1] > a0) { /* insertion sort by start */
        xs[j] = xs[j - 1];
        xe[j] = xe[j - 1];
        --j;
      }
      xs[j] = a0;
      xe[j] = a1;
    }
  }
  double s = 0.0;
  int64_t done = -1; /* last cell summed */
  int64_t k = 0;
  while (k < n) {
    int64_t x0 = xs[k], x1 = xe[k];
    while (k + 1 < n && xs[k + 1] <= x1 + 1) { /* merge touching ranges */
      ++k;
      if (xe[k] > x1) x1 = xe[k];
    }
    ++k;
    if (x0 <= done) x0 = done + 1;
    if (done >= 0 && x0 > done + 1) put_run(row, crow, W, done + 1, x0 - 1, fabs(s), lv, full);
    for (int64_t x = x0; x <= x1; ++x) {
      s += a[x];
      a[x] = 0.0;
      if (x < W) put_run(row, crow, W, x, x, fabs(s), lv, full);
    }
    if (x1 > done) done = x1;
  }
}

/*
 * Fills shapes in order (painter's algorithm). A shape is one or more contours filled
 * together (nonzero rule: each contour is oriented to positive area, the coverage is
 * min(|sum|, 1)). xy: (sum(counts) * 2) vertices in pixel coordinates; counts:
 * (n_contours) vertices per contour; shape_contours: (n_shapes) contours per shape;
 * levels: (n_shapes). For every pixel with coverage c > 0: if img is given,
 * img <- round(img + (level - img) * c); if cov is given (H*W doubles, zero on
 * entry), cov <- c (the last shape's coverage where shapes overlap).
 * acc (H * (W + 2)) must be zero on entry and is left zero; lo, hi, rn: (H) and
 * rx: (H * 16) work arrays.
 * Returns 0, or 1 for a non-finite vertex (nothing drawn).
 */
int fill_shapes(uint8_t *img, double *cov, int64_t W, int64_t H, const double *xy,
                const int64_t *counts, const int64_t *shape_contours, const double *levels,
                int64_t n_shapes, double *acc, int64_t *lo, int64_t *hi, int64_t *rx,
                int64_t *rn) {
  int64_t n_contours = 0, total = 0;
  for (int64_t sh = 0; sh < n_shapes; ++sh) n_contours += shape_contours[sh];
  for (int64_t c = 0; c < n_contours; ++c) total += counts[c];
  for (int64_t k = 0; k < 2 * total; ++k)
    if (!isfinite(xy[k])) return 1;
  Raster r = {acc, lo, hi, rx, rn, W, H};
  const double *p = xy;
  const int64_t *cnt = counts;
  for (int64_t sh = 0; sh < n_shapes; ++sh) {
    int64_t nc = shape_contours[sh];
    double ymin = INFINITY, ymax = -INFINITY;
    int64_t nv = 0;
    for (int64_t c = 0; c < nc; ++c) nv += cnt[c];
    for (int64_t k = 0; k < nv; ++k) {
      double y = p[2 * k + 1] + 0.5;
      if (y < ymin) ymin = y;
      if (y > ymax) ymax = y;
    }
    int64_t ya = nv ? (int64_t)floor(ymin) : 0, yb = nv ? (int64_t)ceil(ymax) : 0;
    if (ya < 0) ya = 0;
    if (yb > H) yb = H;
    for (int64_t y = ya; y < yb; ++y) {
      lo[y] = W + 2;
      hi[y] = -1;
      rn[y] = 0;
    }
    for (int64_t c = 0; c < nc; ++c) {
      int64_t n = cnt[c];
      double area = 0.0;
      for (int64_t k = 0; k < n; ++k) {
        const double *u = p + 2 * k, *v = p + 2 * ((k + 1) % n);
        area += u[0] * v[1] - v[0] * u[1];
      }
      double sign = area < 0 ? -1.0 : 1.0;
      for (int64_t k = 0; k < n; ++k) {
        const double *u = p + 2 * k, *v = p + 2 * ((k + 1) % n);
        edge(&r, u[0] + 0.5, u[1] + 0.5, v[0] + 0.5, v[1] + 0.5, sign);
      }
      p += 2 * n;
    }
    cnt += nc;
    double level = levels[sh];
    const double lv = level < 0.0 ? 0.0 : (level > 255.0 ? 255.0 : level);
    const uint8_t full = (uint8_t)floor(lv + 0.5);
    for (int64_t y = ya; y < yb; ++y) {
      if (hi[y] < 0) continue;
      resolve_row(&r, y, img ? img + y * W : NULL, cov ? cov + y * W : NULL, lv, full);
    }
  }
  return 0;
}
