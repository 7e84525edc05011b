/* Subsoil vertical stress below the two tracks (Söhne / Fröhlich): the table lookup and
 * superposition of symtrack/soil/subsoil.py's stress_at for one point, the same operations in
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

#if defined(__AVX2__)
#include <immintrin.h>
#endif

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

/* the loaded part [*sa, *sb] of [0, l] of the pressure line p = max(0, alpha + beta s); 0 when unloaded */
static inline int subsoil_active_(double alpha, double beta, double l, double *sa, double *sb) {
  if (beta == 0.0) {
    if (!(alpha > 0.0)) return 0;
    *sa = 0.0;
    *sb = l;
    return 1;
  }
  const double s0 = -alpha / beta;
  if (beta < 0.0) {
    *sa = 0.0;
    *sb = l < s0 ? l : s0;
  } else {
    *sa = s0 > 0.0 ? s0 : 0.0;
    *sb = l;
  }
  return *sb > *sa;
}

/* sigma_out[k] = vertical stress [Pa] at depth k below the world point (px, py) from both tracks;
 * a = (X, Y, cos psi, sin psi, alpha_L, beta_L, alpha_R, beta_R), geo = (l, b, B, e, cell, end strip)
 * (the scalar reference of subsoil_stress_block, which the engine uses) */
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
    if (!subsoil_active_(alpha, beta, l, &sa, &sb)) continue;
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

/* ---- many points at once: the same operations per point as subsoil_stress, in loops over the points
 * that a vectorising compiler turns into SIMD code (gathers for the table reads; the engine's -O3
 * -march=native -ffp-contract=off: no contraction, so every point's sums are subsoil_stress's to the
 * last bit, tested in tests/test_subsoil.py). A point whose row is past the table adds +0.0 instead of
 * nothing (a difference only in the sign of a zero). */
#define SUBSOIL_BLOCK 64
#define SUBSOIL_MAX_DEPTHS 8 /* symtrack/terrain/settings.py MAX_SUBSOIL_DEPTHS */

/* acc[k * SUBSOIL_BLOCK + n] += track's contribution at depth k for points n < m */
static inline void subsoil_side_block_(const subsoil_tables_t *T, int m, const double *restrict t,
                                       const double *restrict xa, const double *restrict xe,
                                       const double *restrict p_lin, double beta, double *restrict acc) {
  for (int k = 0; k < T->n_depths; ++k) {
    const int nx = T->n_x[k], nt = T->n_t[k];
    const double ixs = T->inv_x_step[k], its = T->inv_t_step[k];
    const double xlast = (double)(nx - 1), tlast = (double)(nt - 1);
    const double *restrict D = T->data + T->offset[k];
    double *restrict ak = acc + k * SUBSOIL_BLOCK;
    /* no point of the block within the table's reach of this track at this depth: nothing to add
       (the engine groups the points by the track they lie under, so that the other track's shallow
       depths are skipped whole) */
    double tmin = INFINITY;
    for (int n = 0; n < m; ++n) {
      const double ta = t[n] < 0 ? -t[n] : t[n];
      tmin = ta < tmin ? ta : tmin;
    }
    if (!(tmin * its < tlast)) continue;
    /* the lookups' indices and weights of every point (a loop the compiler vectorises), then the table
       reads and the bilinear sums: with AVX2 four points at a time, each point's two 4-double rows read
       as vectors and transposed (gathers are slow on some processors), the same operations per point in
       the same order as the scalar loop (the same bits: tests/test_subsoil.py); the rest one by one */
    int oa[SUBSOIL_BLOCK], ob[SUBSOIL_BLOCK];
    double wft[SUBSOIL_BLOCK], wgt[SUBSOIL_BLOCK], wfa[SUBSOIL_BLOCK], wga[SUBSOIL_BLOCK], wfb[SUBSOIL_BLOCK],
        wgb[SUBSOIL_BLOCK], win[SUBSOIL_BLOCK], sa_[SUBSOIL_BLOCK], sb_[SUBSOIL_BLOCK];
    for (int n = 0; n < m; ++n) {
      const double tn = t[n];
      const double ut = (tn < 0 ? -tn : tn) * its;
      const int inside = ut < tlast;
      const double utc = inside ? ut : 0.0;
      int j = (int)utc;
      j = j > nt - 2 ? nt - 2 : j;
      const double ft = utc - (double)j;
      const double xan = xa[n], xen = xe[n];
      double ua = (xan < 0 ? -xan : xan) * ixs;
      ua = ua > xlast ? xlast : ua;
      int ia = (int)ua;
      ia = ia > nx - 2 ? nx - 2 : ia;
      double ub = (xen < 0 ? -xen : xen) * ixs;
      ub = ub > xlast ? xlast : ub;
      int ib = (int)ub;
      ib = ib > nx - 2 ? nx - 2 : ib;
      oa[n] = 2 * (ia * nt + j);
      ob[n] = 2 * (ib * nt + j);
      wft[n] = ft;
      wgt[n] = 1.0 - ft;
      wfa[n] = ua - (double)ia;
      wga[n] = 1.0 - wfa[n];
      wfb[n] = ub - (double)ib;
      wgb[n] = 1.0 - wfb[n];
      win[n] = inside ? 1.0 : 0.0;
      sa_[n] = xan < 0 ? -1.0 : 1.0;
      sb_[n] = xen < 0 ? -1.0 : 1.0;
    }
    const int o1 = 2 * nt;
    int n0 = 0;
#if defined(__AVX2__)
    const __m256d vbeta = _mm256_set1_pd(beta), zero = _mm256_setzero_pd();
    for (; n0 + 4 <= m; n0 += 4) {
      const __m256d gt = _mm256_loadu_pd(wgt + n0), ft = _mm256_loadu_pd(wft + n0);
      __m256d vv[2], hh[2];
      for (int e = 0; e < 2; ++e) {
        const int *o = e == 0 ? oa : ob;
        __m256d r[2][4];
        for (int row = 0; row < 2; ++row) {
          const __m256d l0 = _mm256_loadu_pd(D + o[n0] + row * o1), l1 = _mm256_loadu_pd(D + o[n0 + 1] + row * o1);
          const __m256d l2 = _mm256_loadu_pd(D + o[n0 + 2] + row * o1), l3 = _mm256_loadu_pd(D + o[n0 + 3] + row * o1);
          const __m256d u0 = _mm256_unpacklo_pd(l0, l1), u1 = _mm256_unpackhi_pd(l0, l1);
          const __m256d u2 = _mm256_unpacklo_pd(l2, l3), u3 = _mm256_unpackhi_pd(l2, l3);
          r[row][0] = _mm256_permute2f128_pd(u0, u2, 0x20); /* H0 at (i, j) of the 4 points */
          r[row][1] = _mm256_permute2f128_pd(u1, u3, 0x20); /* H1 at (i, j) */
          r[row][2] = _mm256_permute2f128_pd(u0, u2, 0x31); /* H0 at (i, j + 1) */
          r[row][3] = _mm256_permute2f128_pd(u1, u3, 0x31); /* H1 at (i, j + 1) */
        }
        const __m256d g = _mm256_loadu_pd((e == 0 ? wga : wgb) + n0), f = _mm256_loadu_pd((e == 0 ? wfa : wfb) + n0);
        /* v = g (gt H0(i, j) + ft H0(i, j + 1)) + f (gt H0(i + 1, j) + ft H0(i + 1, j + 1)); h1 the same on H1 */
        vv[e] = _mm256_add_pd(
            _mm256_mul_pd(g, _mm256_add_pd(_mm256_mul_pd(gt, r[0][0]), _mm256_mul_pd(ft, r[0][2]))),
            _mm256_mul_pd(f, _mm256_add_pd(_mm256_mul_pd(gt, r[1][0]), _mm256_mul_pd(ft, r[1][2]))));
        hh[e] = _mm256_add_pd(
            _mm256_mul_pd(g, _mm256_add_pd(_mm256_mul_pd(gt, r[0][1]), _mm256_mul_pd(ft, r[0][3]))),
            _mm256_mul_pd(f, _mm256_add_pd(_mm256_mul_pd(gt, r[1][1]), _mm256_mul_pd(ft, r[1][3]))));
      }
      /* h0 = -v where x < 0 (a sign flip, exact); c = p_lin (h0a - h0b) - beta (h1a - h1b) */
      const __m256d h0a = _mm256_mul_pd(_mm256_loadu_pd(sa_ + n0), vv[0]);
      const __m256d h0b = _mm256_mul_pd(_mm256_loadu_pd(sb_ + n0), vv[1]);
      const __m256d c = _mm256_sub_pd(_mm256_mul_pd(_mm256_loadu_pd(p_lin + n0), _mm256_sub_pd(h0a, h0b)),
                                      _mm256_mul_pd(vbeta, _mm256_sub_pd(hh[0], hh[1])));
      const __m256d inside = _mm256_cmp_pd(_mm256_loadu_pd(win + n0), zero, _CMP_GT_OQ);
      _mm256_storeu_pd(ak + n0, _mm256_add_pd(_mm256_loadu_pd(ak + n0), _mm256_blendv_pd(zero, c, inside)));
    }
#endif
    for (int n = n0; n < m; ++n) {
      const double gt = wgt[n], ft = wft[n], ga = wga[n], fa = wfa[n], gb = wgb[n], fb = wfb[n];
      const int a0 = oa[n], b0 = ob[n];
      const double va = ga * (gt * D[a0] + ft * D[a0 + 2]) + fa * (gt * D[a0 + o1] + ft * D[a0 + o1 + 2]);
      const double h1a = ga * (gt * D[a0 + 1] + ft * D[a0 + 3]) + fa * (gt * D[a0 + o1 + 1] + ft * D[a0 + o1 + 3]);
      const double vb = gb * (gt * D[b0] + ft * D[b0 + 2]) + fb * (gt * D[b0 + o1] + ft * D[b0 + o1 + 2]);
      const double h1b = gb * (gt * D[b0 + 1] + ft * D[b0 + 3]) + fb * (gt * D[b0 + o1 + 1] + ft * D[b0 + o1 + 3]);
      const double h0a = sa_[n] * va, h0b = sb_[n] * vb;
      const double c = p_lin[n] * (h0a - h0b) - beta * (h1a - h1b);
      ak[n] += win[n] > 0.0 ? c : 0.0;
    }
  }
}

/* sigma_out[n * n_depths + k] (as subsoil_stress at (px[n], py[n])) for n < m <= SUBSOIL_BLOCK;
 * P (NULL: none) a second set of tables (the same depths) into p_out the same way */
static void subsoil_stress_block(const subsoil_tables_t *T, const subsoil_tables_t *P, const double a[8],
                                 const double geo[6], const double *px, const double *py, int m,
                                 double *sigma_out, double *p_out) {
  const double l = geo[0], B = geo[2], e = geo[3];
  const double c = a[2], s = a[3];
  double s_pt[SUBSOIL_BLOCK], yb[SUBSOIL_BLOCK], t[SUBSOIL_BLOCK], xa[SUBSOIL_BLOCK], xe[SUBSOIL_BLOCK],
      p_lin[SUBSOIL_BLOCK];
  double acc[SUBSOIL_MAX_DEPTHS * SUBSOIL_BLOCK], accp[SUBSOIL_MAX_DEPTHS * SUBSOIL_BLOCK];
  for (int n = 0; n < m; ++n) {
    const double ddx = px[n] - a[0], ddy = py[n] - a[1];
    const double xb = c * ddx + s * ddy;
    yb[n] = -s * ddx + c * ddy;
    s_pt[n] = (l / 2 - e) - xb;
  }
  for (int k = 0; k < T->n_depths; ++k)
    for (int n = 0; n < m; ++n) acc[k * SUBSOIL_BLOCK + n] = 0.0;
  if (P)
    for (int k = 0; k < P->n_depths; ++k)
      for (int n = 0; n < m; ++n) accp[k * SUBSOIL_BLOCK + n] = 0.0;
  for (int side = 0; side < 2; ++side) {
    const double alpha = a[4 + 2 * side], beta = a[5 + 2 * side];
    double sa, sb;
    if (!subsoil_active_(alpha, beta, l, &sa, &sb)) continue;
    const double off = (side == 0 ? 1.0 : -1.0) * B / 2;
    for (int n = 0; n < m; ++n) {
      t[n] = yb[n] - off;
      p_lin[n] = alpha + beta * s_pt[n];
      xa[n] = s_pt[n] - sa;
      xe[n] = s_pt[n] - sb;
    }
    subsoil_side_block_(T, m, t, xa, xe, p_lin, beta, acc);
    if (P) subsoil_side_block_(P, m, t, xa, xe, p_lin, beta, accp);
  }
  for (int n = 0; n < m; ++n)
    for (int k = 0; k < T->n_depths; ++k) sigma_out[n * T->n_depths + k] = acc[k * SUBSOIL_BLOCK + n];
  if (P)
    for (int n = 0; n < m; ++n)
      for (int k = 0; k < P->n_depths; ++k) p_out[n * P->n_depths + k] = accp[k * SUBSOIL_BLOCK + n];
}

#endif
