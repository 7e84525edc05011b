/* The terrain query in C (symtrack/terrain/query.py, the same rule and numbers): the ground's
 * height, its surface normal and the cell under a point of the field.
 *
 * The field: nx x ny cells of size dx from the lower-left corner (x0, y0), the sinkage z and the
 * phase of cell (i, j) at i * ny + j (the engine's storage: grid_engine.c's eng_t). Cell (i, j)
 * covers [x0 + i dx, x0 + (i + 1) dx) x [y0 + j dx, y0 + (j + 1) dx); a point on the upper edge
 * belongs to the last cell.
 *
 * elevation = the cell's initial elevation z0 (elev[c]; elev NULL: a flat field, 0);
 * height = elevation - sinkage (the undisturbed surface minus the rut: the ground a body meets);
 * gradient = (dz0/dx, dz0/dy) by central differences of the neighbouring cells' elevations,
 *   (z0[i+1] - z0[i-1]) / (2 dx), one-sided at the field's edge, 0 along an axis of one cell;
 * normal = the undisturbed surface's unit normal (-gx, -gy, 1) / sqrt(gx^2 + gy^2 + 1), (0, 0, 1) flat.
 *
 * grid_engine.c includes it and exports it on its own storage (eng_surface; TerrainEngine.surface);
 * terrain_query_check.c wraps it alone for the tests. The planar vehicle does not ask for the height
 * (it rides a plane); a 3D vehicle's contact will. */
#ifndef SYMTRACK_TERRAIN_QUERY_H
#define SYMTRACK_TERRAIN_QUERY_H

#include <math.h>

typedef struct {
  long long nx, ny;
  double x0, y0, dx;
  const double *z;            /* sinkage, nx * ny */
  const signed char *phase;   /* nx * ny */
  const double *elev;         /* initial elevation z0, nx * ny; NULL: a flat field */
} tq_field_t;

typedef struct {
  long long cell;     /* i * ny + j; -1 outside the field */
  double elevation_m; /* the undisturbed surface */
  double sinkage_m;   /* the cell's stored sinkage */
  double height_m;    /* elevation - sinkage */
  double gradient[2]; /* dz0/dx, dz0/dy of the undisturbed surface */
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
    r->gradient[0] = r->gradient[1] = NAN;
    r->normal[0] = r->normal[1] = r->normal[2] = NAN;
    return 1;
  }
  long long i = (long long)floor((x - F->x0) / F->dx), j = (long long)floor((y - F->y0) / F->dx);
  if (i > F->nx - 1) i = F->nx - 1;
  if (j > F->ny - 1) j = F->ny - 1;
  const long long c = i * F->ny + j;
  r->cell = c;
  r->phase = F->phase[c];
  r->sinkage_m = F->z[c];
  if (!F->elev) { /* a flat field */
    r->elevation_m = 0.0;
    r->gradient[0] = r->gradient[1] = 0.0;
    r->normal[0] = 0.0;
    r->normal[1] = 0.0;
    r->normal[2] = 1.0;
  } else {
    const double *e = F->elev;
    const long long ip = i + 1 < F->nx ? i + 1 : F->nx - 1, im = i > 0 ? i - 1 : 0;
    const long long jp = j + 1 < F->ny ? j + 1 : F->ny - 1, jm = j > 0 ? j - 1 : 0;
    const double gx = ip > im ? (e[ip * F->ny + j] - e[im * F->ny + j]) / ((double)(ip - im) * F->dx) : 0.0;
    const double gy = jp > jm ? (e[i * F->ny + jp] - e[i * F->ny + jm]) / ((double)(jp - jm) * F->dx) : 0.0;
    const double rn = sqrt(gx * gx + gy * gy + 1.0);
    r->elevation_m = e[c];
    r->gradient[0] = gx;
    r->gradient[1] = gy;
    r->normal[0] = -gx / rn;
    r->normal[1] = -gy / rn;
    r->normal[2] = 1.0 / rn;
  }
  r->height_m = r->elevation_m - r->sinkage_m;
  return 0;
}

/* The query over many points: per point n cell[n], phase[n] and out[TQ_OUT n ..] = (elevation, sinkage,
 * height, normal x, y, z, gradient x, y); returns how many points lie outside the field. */
#define TQ_OUT 8
static inline long long terrain_query_points(const tq_field_t *F, const double *px, const double *py,
                                             long long n_points, long long *cell, int *phase, double *out) {
  long long outside = 0;
  for (long long n = 0; n < n_points; ++n) {
    tq_result_t r;
    outside += terrain_query(F, px[n], py[n], &r);
    cell[n] = r.cell;
    phase[n] = r.phase;
    double *o = out + TQ_OUT * n;
    o[0] = r.elevation_m;
    o[1] = r.sinkage_m;
    o[2] = r.height_m;
    o[3] = r.normal[0];
    o[4] = r.normal[1];
    o[5] = r.normal[2];
    o[6] = r.gradient[0];
    o[7] = r.gradient[1];
  }
  return outside;
}

#endif
