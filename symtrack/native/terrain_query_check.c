/* Test wrapper of terrain_query.h (tests/test_terrain_query.py): terrain_query over many points. */
#include "terrain_query.h"

#define EXPORT __attribute__((visibility("default")))

/* per point n: cell[n], phase[n], out[8 n ..] = (elevation, sinkage, height, normal x, y, z, gradient x, y);
   returns how many points were outside the field */
EXPORT long long terrain_query_many(const tq_field_t *F, const double *px, const double *py, long long n_points,
                                    long long *cell, int *phase, double *out) {
  return terrain_query_points(F, px, py, n_points, cell, phase, out);
}
