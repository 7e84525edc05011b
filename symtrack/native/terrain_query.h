/* The terrain query in C (symtrack/terrain/query.py, the same rule and numbers): the ground's
 * height, its surface normal and the cell under a point of the field.
 *
 * The field: nx x ny cells of size dx from the lower-left corner (x0, y0), the sinkage z and the
 * phase of cell (i, j) at i * ny + j (the engine's storage: grid_engine.c's eng_t). Cell (i, j)
 * covers [x0 + i dx, x0 + (i + 1) dx) x [y0 + j dx, y0 + (j + 1) dx); a point on the upper edge
 * belongs to the last cell.
 *
 * height = elevation - sinkage (the undisturbed surface, flat today: elevation 0, minus the rut);
 * normal = the undisturbed surface's unit normal, (0, 0, 1) on a flat field.
 *
 * grid_engine.c includes it and exports it on its own storage (eng_surface; TerrainEngine.surface);
 * terrain_query_check.c wraps it alone for the tests. The planar vehicle does not ask for the height
 * yet (it rides the flat field); a 3D vehicle's contact will. */
#ifndef SYMTRACK_TERRAIN_QUERY_H
#define SYMTRACK_TERRAIN_QUERY_H

#include <math.h>

typedef struct {
  long long nx, ny;
  double x0, y0, dx;
  const double *z;            /* sinkage, nx * ny */
  const signed char *phase;   /* nx * ny */
} tq_field_t;

typedef struct {
  long long cell;     /* i * ny + j; -1 outside the field */
  double elevation_m; /* the undisturbed surface */
  double sinkage_m;   /* the cell's stored sinkage */
  double height_m;    /* elevation - sinkage */
  double normal[3];   /* the undisturbed surface's unit normal */
  int phase;          /* the cell's phase; -1 outside */
} tq_result_t;

/* The query at (x, y): returns 0, or 1 outside the field (then cell = -1, phase = -1 and the
 * numbers NaN; the caller reports the point and the field's extent). */
static inline int terrain_query(const tq_field_t *F, double x, double y, tq_result_t *r) {
  const double x1 = F->x0 + (double)F->nx * F->dx, y1 = F->y0 + (double)F->ny * F->dx;
  if (!(x >= F->x0 && x <= x1 && y >= F->y0 && y <= y1)) { /* NaN: outside */
    r->cell = -1;
    r->phase = -1;
    r->elevation_m = r->sinkage_m = r->height_m = NAN;
    r->normal[0] = r->normal[1] = r->normal[2] = NAN;
    return 1;
  }
  long long i = (long long)floor((x - F->x0) / F->dx), j = (long long)floor((y - F->y0) / F->dx);
  if (i > F->nx - 1) i = F->nx - 1;
  if (j > F->ny - 1) j = F->ny - 1;
  const long long c = i * F->ny + j;
  r->cell = c;
  r->phase = F->phase[c];
  r->elevation_m = 0.0; /* flat fields (issue 22: the field's elevation map) */
  r->sinkage_m = F->z[c];
  r->height_m = r->elevation_m - r->sinkage_m;
  r->normal[0] = 0.0;
  r->normal[1] = 0.0;
  r->normal[2] = 1.0;
  return 0;
}

/* The query over many points: per point n cell[n], phase[n] and out[6 n ..] = (elevation, sinkage,
 * height, normal x, y, z); returns how many points lie outside the field. */
static inline long long terrain_query_points(const tq_field_t *F, const double *px, const double *py,
                                             long long n_points, long long *cell, int *phase, double *out) {
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

#endif
