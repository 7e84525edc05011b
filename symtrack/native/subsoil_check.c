/* Test and benchmark wrapper of subsoil.h (tests/test_subsoil.py): subsoil_stress over many points. */
#include <math.h>
#include <time.h>

#include "subsoil.h"

#define EXPORT __attribute__((visibility("default")))

/* sigma[n * n_depths + k] for the points (px[n], py[n]), n < n_points */
EXPORT void subsoil_stress_many(const subsoil_tables_t *T, const double *a, const double *geo, const double *px,
                                const double *py, long long n_points, double *sigma) {
  for (long long n = 0; n < n_points; ++n) subsoil_stress(T, a, geo, px[n], py[n], sigma + n * T->n_depths);
}

/* repeats x subsoil_stress_many; returns the wall time in ns (the benchmark) */
EXPORT long long subsoil_stress_bench(const subsoil_tables_t *T, const double *a, const double *geo, const double *px,
                                      const double *py, long long n_points, double *sigma, long long repeats) {
  struct timespec t0, t1;
  clock_gettime(CLOCK_MONOTONIC, &t0);
  for (long long r = 0; r < repeats; ++r) subsoil_stress_many(T, a, geo, px, py, n_points, sigma);
  clock_gettime(CLOCK_MONOTONIC, &t1);
  return (long long)(t1.tv_sec - t0.tv_sec) * 1000000000LL + (t1.tv_nsec - t0.tv_nsec);
}

/* the same points through subsoil_stress_block (the engine's SIMD path), in blocks of SUBSOIL_BLOCK;
   P (NULL: none) into p_out */
EXPORT void subsoil_stress_many_block(const subsoil_tables_t *T, const subsoil_tables_t *P, const double *a,
                                      const double *geo, const double *px, const double *py, long long n_points,
                                      double *sigma, double *p_out) {
  for (long long n = 0; n < n_points; n += SUBSOIL_BLOCK) {
    const int m = (int)(n_points - n < SUBSOIL_BLOCK ? n_points - n : SUBSOIL_BLOCK);
    subsoil_stress_block(T, P, a, geo, px + n, py + n, m, sigma + n * T->n_depths, P ? p_out + n * P->n_depths : 0);
  }
}

/* repeats x subsoil_stress_many_block (P = NULL); returns the wall time in ns (the benchmark) */
EXPORT long long subsoil_stress_block_bench(const subsoil_tables_t *T, const double *a, const double *geo,
                                            const double *px, const double *py, long long n_points, double *sigma,
                                            long long repeats) {
  struct timespec t0, t1;
  clock_gettime(CLOCK_MONOTONIC, &t0);
  for (long long r = 0; r < repeats; ++r) subsoil_stress_many_block(T, 0, a, geo, px, py, n_points, sigma, 0);
  clock_gettime(CLOCK_MONOTONIC, &t1);
  return (long long)(t1.tv_sec - t0.tv_sec) * 1000000000LL + (t1.tv_nsec - t0.tv_nsec);
}
