/* Test wrapper of terrain_query.h (tests/test_terrain_query.py): terrain_query over many points. */
#include "terrain_query.h"

#define EXPORT __attribute__((visibility("default")))

/* per point n: cell[n], phase[n], out[6 n ..] = (elevation, sinkage, height, normal x, y, z);
   returns how many points were outside the field */
EXPORT long long terrain_query_many(const tq_field_t *F, const double *px, const double *py, long long n_points,
                                    long long *cell, int *phase, double *out) {
  long long outside = 0;
  for (long long n = 0; n < n_points; ++n) {
    tq_result_t r;
    outside += terrain_query(F, px[n], py[n], &r);
    cell[n] = r.cell;
    phase[n] = r.phase;
    double *o = out + 6 * n;
    o[0] = r.elevation_m;
    o[1] = r.sinkage_m;
    o[2] = r.height_m;
    o[3] = r.normal[0];
    o[4] = r.normal[1];
    o[5] = r.normal[2];
  }
  return outside;
}
