/* Subsoil vertical stress below the two tracks (Söhne / Fröhlich): the table lookup and
 * superposition of symtrack/terrain/subsoil.py's stress_at for one point, the same operations in
 * the same order (tested to 1e-12 against numpy in tests/test_subsoil.py; docs/subsoil.md).
 *
 * Per depth k a table of the prefix integrals of the strip kernel, H0(x, t) (odd in x) and
 * H1(x, t) (even in x), on x_i = i / inv_x_step[k] (i < n_x[k]), t_j = j / inv_t_step[k] (j < n_t[k]):
 * data[offset[k] + 2 (i n_t[k] + j) + 0 | 1]. Track k's stress at a point is
 *   p_lin(s) [H0(x_a, t) - H0(x_b, t)] - beta [H1(x_a, t) - H1(x_b, t)]
 * with [s_a, s_b] the loaded part of the track (p = max(0, alpha + beta s)), x_a = s - s_a,
 * x_b = s - s_b. Bilinear in (|x|, |t|); |x| past the grid saturates; |t| past it gives 0.
 *
 * No allocation, no libm call. Include after <math.h>.
 */
#ifndef SYMTRACK_SUBSOIL_H
#define SYMTRACK_SUBSOIL_H

typedef struct {
  int n_depths;
  const double *inv_x_step; /* n_depths: 1 / x step [1/m] */
  const double *inv_t_step; /* n_depths: 1 / t step [1/m] */
  const int *n_x;          /* n_depths, >= 2 */
  const int *n_t;          /* n_depths, >= 2 */
  const long long *offset; /* n_depths: start of depth k's table in data (in doubles) */
  const double *data;      /* (H0, H1) pairs */
} subsoil_tables_t;

/* the t part of a lookup at depth k: row j, weight ft; 0 when |t| is past the table (no load) */
static inline int subsoil_row_(const subsoil_tables_t *T, int k, double t, long long *j, double *ft) {
  const int nt = T->n_t[k];
  const double ut = (t < 0 ? -t : t) * T->inv_t_step[k];
  if (!(ut < (double)(nt - 1))) return 0;
  long long jj = (long long)ut;
  if (jj > nt - 2) jj = nt - 2;
  *j = jj;
  *ft = ut - (double)jj;
  return 1;
}

/* (H0, H1) of depth k at (x, row j / weight ft) */
static inline void subsoil_lookup_(const subsoil_tables_t *T, int k, double x, long long j, double ft, double *h0,
                                   double *h1) {
  const int nx = T->n_x[k], nt = T->n_t[k];
  double ux = (x < 0 ? -x : x) * T->inv_x_step[k];
  if (ux > (double)(nx - 1)) ux = (double)(nx - 1);
  long long i = (long long)ux;
  if (i > nx - 2) i = nx - 2;
  const double fx = ux - (double)i;
  const double gx = 1.0 - fx, gt = 1.0 - ft;
  const double *r0 = T->data + T->offset[k] + 2 * (i * nt + j);
  const double *r1 = r0 + 2 * nt;
  const double v = gx * (gt * r0[0] + ft * r0[2]) + fx * (gt * r1[0] + ft * r1[2]);
  *h1 = gx * (gt * r0[1] + ft * r0[3]) + fx * (gt * r1[1] + ft * r1[3]);
  *h0 = x < 0 ? -v : v;
}

/* sigma_out[k] = vertical stress [Pa] at depth k below the world point (px, py) from both tracks;
 * a = (X, Y, cos psi, sin psi, alpha_L, beta_L, alpha_R, beta_R), geo = (l, b, B, e, cell, end strip) */
static void subsoil_stress(const subsoil_tables_t *T, const double a[8], const double geo[6], double px, double py,
                           double *sigma_out /* n_depths */) {
  const double l = geo[0], B = geo[2], e = geo[3];
  const double c = a[2], s = a[3];
  const double ddx = px - a[0], ddy = py - a[1];
  const double xb = c * ddx + s * ddy;
  const double yb = -s * ddx + c * ddy;
  const double s_pt = (l / 2 - e) - xb;
  for (int k = 0; k < T->n_depths; ++k) sigma_out[k] = 0.0;
  for (int side = 0; side < 2; ++side) {
    const double alpha = a[4 + 2 * side], beta = a[5 + 2 * side];
    double sa, sb;
    if (beta == 0.0) {
      if (!(alpha > 0.0)) continue;
      sa = 0.0;
      sb = l;
    } else {
      const double s0 = -alpha / beta;
      if (beta < 0.0) {
        sa = 0.0;
        sb = l < s0 ? l : s0;
      } else {
        sa = s0 > 0.0 ? s0 : 0.0;
        sb = l;
      }
      if (!(sb > sa)) continue;
    }
    const double t = yb - (side == 0 ? 1.0 : -1.0) * B / 2;
    const double p_lin = alpha + beta * s_pt;
    const double xa = s_pt - sa, xe = s_pt - sb;
    for (int k = 0; k < T->n_depths; ++k) {
      long long j;
      double ft, h0a, h1a, h0b, h1b;
      if (!subsoil_row_(T, k, t, &j, &ft)) continue;
      subsoil_lookup_(T, k, xa, j, ft, &h0a, &h1a);
      subsoil_lookup_(T, k, xe, j, ft, &h0b, &h1b);
      sigma_out[k] += p_lin * (h0a - h0b) - beta * (h1a - h1b);
    }
  }
}

#endif
