/* The terrain engine's hot path (symtrack/integrators/engine/, docs/terrain.md "The terrain engine").
 *
 * Per macro step: the footprint, release and sector assignment of the world manager
 * (symtrack/terrain/world.py, same rules and the same floating-point expressions), the vehicle's
 * step (generated from CasADi: eng_vehicle_step), each active cell's step (two-stage SDIRK with a
 * safeguarded scalar Newton per stage on the generated law eng_cell_law_<v>), INFO_OUT (history of
 * the active channels only), the channel sums, the outputs (eng_outputs) and the coverage check.
 * This file is the one home of the world manager's rules (footprint, release, sector assignment,
 * INFO_IN, INFO_OUT, the collision and coverage errors): the engine runs them inside eng_run, the
 * IDAS reference path (symtrack/integrators/engine/manager.py, ChannelManager) through eng_assign,
 * eng_info_out and eng_uncovered on the World's channel tables. tests/engine_oracle.py mirrors every
 * line of it in Python (the test oracle, checked against this file).
 *
 * Compiled with the CasADi-generated C of the eng_* Functions included (engine_gen.inc).
 */
#include <math.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* fmax / fmin as inline comparisons with C99's NaN rule (a non-NaN argument wins): without
   -ffinite-math-only gcc calls libm's through the PLT, 3 to 5 times per law evaluation */
static inline double eng_fmax_(double x, double y) { return x > y ? x : (y == y ? y : x); }
static inline double eng_fmin_(double x, double y) { return x < y ? x : (y == y ? y : x); }
#define fmax(x, y) eng_fmax_(x, y)
#define fmin(x, y) eng_fmin_(x, y)

/* the generated Functions in this translation unit, internal: the compiler inlines the small ones */
#define CASADI_SYMBOL_EXPORT static
/* the cells' lanes (cell_step_block below; engine_soils.inc's laws over the lanes) */
#ifndef CELL_LANES
#define CELL_LANES 8
#endif
#include "engine_gen.inc"
#include "engine_soils.inc" /* ENG_LAW_CALL: the law Function a soil's law row runs (generated) */
#include "subsoil.h" /* the subsoil stress below the tracks (symtrack/soil/subsoil.py) */
#include "terrain_query.h" /* the ground's height, normal and cell under a point (symtrack/terrain/query.py) */
#include "distance_stop.h" /* the distance stop (one copy for the compiled runs) */

#define EXPORT __attribute__((visibility("default")))
#define NV ENG_NV /* generated: engine_soils.inc (grid_engine_model.engine_layout_c) */
#define NW ENG_NW
#define NA ENG_NA /* 8: the pose and the pressure lines; the 3D vehicle adds its segment pressures (engine_soils.inc) */
#define NS 10     /* the cell sums */
#define NS_MAX (NS + 2 + 2 * ENG_N_TRACK_SOIL) /* with a soil map: + the soil under each track (SOIL_SUM_NAMES) */
#define NGEO ENG_NGEO /* generated: the entries of geo (grid_engine_model.engine_layout_c, ENG_GEO_*) */
/* a Newton step inside the bracket below this fraction of |Z| is the last one (engine.py NEWTON_ACCEPT_STEP) */
#define NEWTON_ACCEPT 1e-4

/* error codes (engine.py turns them into SimulationError messages) */
#define ERR_FIELD 1       /* the footprint leaves the field: err_x = (cx, cy) */
#define ERR_COLLISION 2   /* err_a, err_b: the two cells; err_ch: the channel */
#define ERR_UNCOVERED 3   /* err_a: a loaded cell without a channel; err_b: how many */
#define ERR_NONFINITE 4   /* the vehicle step returned a non-finite state */
#define ERR_NEWTON 5      /* a cell's stage equation did not converge; err_a: the cell */

/* eng_t, the engine's struct, written once as this list: F(type, name) a field, A(type, name, n) an
 * array of n. The struct below and the table of its fields that the library exports (eng_struct_size,
 * eng_field_*) are both made from it; the ctypes binding (symtrack/integrators/engine/state.py
 * EngineStruct) is checked against that table when the library is loaded (kernel.check_struct). */
#define ENG_FIELDS(F, A) \
  /* grid */ \
  F(long long, nx) F(long long, ny) F(long long, M) F(long long, n_ch) \
  F(double, x0) F(double, y0) F(double, dx) \
  /* storage, flat i * ny + j */ \
  F(double *, z) F(double *, zdot) F(double *, zmax) F(double *, pmax) \
  F(signed char *, phase) \
  F(unsigned char *, touched) \
  /* channels */ \
  F(long long *, ch_cell) F(long long *, ch_foot) F(long long *, ch_new_stamp) F(long long *, ch_new_cell) \
  F(double *, ch_z) F(double *, ch_v) F(double *, ch_zmax) F(double *, ch_pmax) F(double *, ch_p) \
  F(double *, ch_cx) F(double *, ch_cy) \
  F(double *, ch_g) /* NGEO per channel */ \
  F(double *, ch_dp) /* dp/dz at the channel's state */ \
  F(double *, ch_pw) /* its compaction power over the last step (2) */ \
  F(double *, ch_vr) /* dz/dt at the step end from the quadratic through the last substep's stages */ \
  F(unsigned char *, ch_new) /* 1: assigned at this step's start (its first geometry is evaluated here) */ \
  F(long long *, act) F(long long *, new_list) \
  F(long long, n_act) F(long long, n_new) F(long long, peak_active) F(long long, stamp) \
  /* constants */ \
  F(double *, pv) /* parameters of the vehicle Functions; the last NS entries are the channel sums */ \
  F(double *, geo) /* 7: l, b, B, e, dx, end strip, 1 / dx */ \
  F(double *, wv) /* NW: the vehicle's states and accelerations */ \
  F(double *, a) /* NA: pose and pressure lines at wv */ \
  F(double *, work) /* the generated Functions' work vector (the largest sz_w) */ \
  F(double *, agrid) /* scratch: NA (n + 1) for n = exit_substeps */ \
  /* substeps: every cell's, the entry windows' (both not below cell_substeps; engine.py) */ \
  F(long long, n_pv) F(long long, ny_out) F(long long, cell_substeps) F(long long, entry_substeps) \
  F(long long, power_mode) /* 0: step mean, 1: instantaneous */ \
  F(double, pad) F(double, release_rate) F(double, areal_mass) F(double, damping) F(double, gamma) \
  F(double, entry_fraction) \
  /* error and statistics */ \
  F(long long, err_code) F(long long, err_a) F(long long, err_b) F(long long, err_ch) \
  A(double, err_x, 2) \
  F(long long, n_newton) F(long long, n_cell_stages) F(long long, n_vehicle_steps) \
  /* wall time (ns) of the parts: world manager (footprint, release, assignment, INFO_IN; coverage \
     check), vehicle step, cells (geometry, integration, INFO_OUT), sums and outputs */ \
  F(long long, ns_manager) F(long long, ns_vehicle) F(long long, ns_cells) F(long long, ns_outputs) \
  /* the cycle law (symtrack/soil/cell.py): storage z_off and cycle count per cell; per channel the \
     stay's z_off at its start, its increment delta, its progress d_c, and whether it has counted */ \
  F(double *, zoff) \
  F(unsigned short *, cycles) \
  F(double *, ch_zoff) F(double *, ch_delta) F(double *, ch_dc) \
  F(unsigned char *, ch_counted) \
  /* the subsoil stress: tables (NULL: off), this pass's largest stress per cell and depth \
     (n_depths per cell), and the time spent on it */ \
  F(const subsoil_tables_t *, subsoil) \
  F(float *, sig_pass) \
  F(long long, n_depths) F(long long, ns_subsoil) \
  /* the soil map: each cell's soil (storage), each channel's, and per soil the cohesion, friction \
     angle and shear modulus the traction uses; n_sums = NS, or NS_MAX with a soil map */ \
  F(unsigned char *, soil_index) F(unsigned char *, ch_soil) \
  F(const double *, soil_veh) \
  /* per soil its law row (ENG_LAW_ROW: the soil law's vector and the repeated-loading exponent), the \
     input ``law`` of the cell Functions (grid_engine_model.law_row): the soils' values at run time */ \
  F(const double *, soil_law) \
  F(long long, n_sums) \
  /* the exit windows' substeps (not below cell_substeps; their poses: agrid), the entry windows' poses: \
     NA (entry_substeps + 1) */ \
  F(long long, exit_substeps) \
  F(double *, agrid_entry) \
  /* 1: the cells outside the windows by implicit Euler (engine.py EngineSettings.steady_method) */ \
  F(long long, steady_euler) \
  /* a cell whose transient about its quasi-static path exceeds ring_tol |z| takes an entry window \
     (ringing below; 0: off) */ \
  F(double, ring_tol) \
  /* the field's initial elevation per cell (terrain_query.h; NULL: flat): read by eng_surface only */ \
  F(const double *, elev) \
  /* the bulk density's mean normal stress (symtrack/soil/density.py): tables of p (NULL: off; same \
     depths as subsoil) and this pass's largest p per cell and depth (n_depths per cell) */ \
  F(const subsoil_tables_t *, subsoil_p) \
  F(float *, p_pass) \
  /* the vehicle step's error control (vehicle_step_controlled; 0: off) and how many steps it halved */ \
  F(double, vehicle_rtol) F(double, vehicle_atol) \
  F(long long, vehicle_max_halvings) F(long long, n_vehicle_halved) \
  /* the vehicle's Functions' integer work (a raster's interpolant; sized by state.py vehicle_work_sizes) */ \
  F(long long *, iwork)

#define ENG_DECLARE_(type, name) type name;
#define ENG_DECLARE_ARRAY_(type, name, n) type name[n];
typedef struct {
  ENG_FIELDS(ENG_DECLARE_, ENG_DECLARE_ARRAY_)
} eng_t;

/* the struct's layout as the compiler made it: per field its name, C type, offset and size (in
   ENG_FIELDS's order), read by the ctypes binding at load (kernel.check_struct) */
typedef struct {
  const char *name, *type;
  long long offset, size;
} eng_field_t;
#define ENG_ROW_(type, name) {#name, #type, (long long)offsetof(eng_t, name), (long long)sizeof(((eng_t *)0)->name)},
#define ENG_ROW_ARRAY_(type, name, n) \
  {#name, #type "[" #n "]", (long long)offsetof(eng_t, name), (long long)sizeof(((eng_t *)0)->name)},
static const eng_field_t eng_fields[] = {ENG_FIELDS(ENG_ROW_, ENG_ROW_ARRAY_)};
#define ENG_N_FIELDS ((long long)(sizeof eng_fields / sizeof eng_fields[0]))
EXPORT long long eng_struct_size(void) { return (long long)sizeof(eng_t); }
EXPORT long long eng_field_count(void) { return ENG_N_FIELDS; }
/* field i's name, C type, offset and size (NULL, -1 beyond the table) */
EXPORT const char *eng_field_name(long long i) { return i >= 0 && i < ENG_N_FIELDS ? eng_fields[i].name : 0; }
EXPORT const char *eng_field_type(long long i) { return i >= 0 && i < ENG_N_FIELDS ? eng_fields[i].type : 0; }
EXPORT long long eng_field_offset(long long i) { return i >= 0 && i < ENG_N_FIELDS ? eng_fields[i].offset : -1; }
EXPORT long long eng_field_size(long long i) { return i >= 0 && i < ENG_N_FIELDS ? eng_fields[i].size : -1; }

static long long now_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

/* ---- calls of the generated Functions. The cells' take no integer work and no extra arguments
   (kernel.py check_no_work); the vehicle's (eng_vehicle_step, eng_outputs) may, when the ground is an
   elevation raster (CasADi's B-spline interpolant, a call node): engine_soils.inc sizes their arg and
   res arrays (ENG_SZ_ARG, ENG_SZ_RES) and eng_t.iwork their integer work (state.py vehicle_work_sizes). */
#ifndef ENG_SZ_ARG
#define ENG_SZ_ARG 4
#define ENG_SZ_RES 3
#endif
static double *WORK;
static casadi_int *IWORK;
static const double *SOIL_LAW; /* eng_t.soil_law: soil k's law row at SOIL_LAW + ENG_LAW_ROW k */
#define LAW_ROW(soil) (SOIL_LAW + ENG_LAW_ROW * (long long)(soil))

/* hist: (z_max, p_max, z_off, delta, d_c) */
static void law(double z, const double *hist, int soil, double *p, double *dp) {
  const double *row = LAW_ROW(soil);
  const double *arg[3] = {&z, hist, row};
  double *res[2] = {p, dp};
  ENG_LAW_CALL(row, arg, res);
}

static void channel_hist(const eng_t *E, long long ch, double *hist) {
  hist[0] = E->ch_zmax[ch];
  hist[1] = E->ch_pmax[ch];
  hist[2] = E->ch_zoff[ch];
  hist[3] = E->ch_delta[ch];
  hist[4] = E->ch_dc[ch];
}

static void cell_geo(const double *c, const double *a, const double *geo, double *g) {
  const double *arg[3] = {c, a, geo};
  double *res[1] = {g};
  eng_cell_geo(arg, res, 0, WORK, 0);
}

/* 1 when a cell centred at c lies wholly outside both tracks' contact rectangles at the pose a (the
 * rectangles grown by 0.7072 cell, more than the half cell by which eng_cell_geo's overlap reaches
 * out): its geometry (load, fractions, end-strip weights) is then exactly zero (engine.py
 * outside_tracks) */
static int outside_tracks(const double *geo, const double *c, const double *a) {
  const double l = geo[ENG_GEO_CONTACT_LENGTH_M], b = geo[ENG_GEO_TRACK_WIDTH_M], B = geo[ENG_GEO_TRACK_GAUGE_M];
  const double e = geo[ENG_GEO_CG_AHEAD_OF_CONTACT_CENTRE_M], r = 0.7072 * geo[ENG_GEO_CELL_M];
  const double dx = c[0] - a[0], dy = c[1] - a[1];
  const double xb = a[2] * dx + a[3] * dy, yb = -a[3] * dx + a[2] * dy;
  if (fabs(xb + e) > l / 2 + r) return 1;
  return fabs(yb - B / 2) > b / 2 + r && fabs(yb + B / 2) > b / 2 + r;
}

/* 1 when the cell on channel ch rings at the step start (engine.py ringing): its motion about the
 * quasi-static path (p following the load, at the rate (plB - plA) / (h k)) has an amplitude
 * sqrt(d^2 + e^2 m / k) above ring_tol |z|, with k = dp/dz at its state, d = (plA - p - c v) / k its
 * displacement from that path (m a / k) and e = v - (plB - plA) / (h k) its excess rate: the ringing
 * that a load kink (the end of the entry ramp) excites on the lightly damped elastic line
 * (docs/terrain.md, "The cells' ringing") */
static int ringing(const eng_t *E, long long ch, double plA, double plB, double ih) {
  const double k = E->ch_dp[ch];
  if (!(E->ring_tol > 0.0) || !(k > 0.0) || !(ih > 0.0)) return 0;
  const double ik = 1.0 / k, v = E->ch_v[ch];
  const double d = (plA - E->ch_p[ch] - E->damping * v) * ik, ev = v - (plB - plA) * ih * ik;
  const double tz = E->ring_tol * E->ch_z[ch];
  return d * d + E->areal_mass * ev * ev * ik > tz * tz;
}

/* ---- geometry: the tracks' rectangles (their one home: the IDAS path and the plots read them through
   eng_track_rects, ChannelManager.track_corners) ----------------------------------------------------- */
/* track side (0: left, 1: right)'s contact rectangle at the pose (X, Y, psi) with cos c and sin s,
   grown by pad: its centre (cx, cy), half length hl and half width hw */
static inline void track_rect(const double *geo, double X, double Y, double c, double s, double pad, int side,
                              double *cx, double *cy, double *hl, double *hw) {
  double l = geo[ENG_GEO_CONTACT_LENGTH_M], b = geo[ENG_GEO_TRACK_WIDTH_M], B = geo[ENG_GEO_TRACK_GAUGE_M];
  double e = geo[ENG_GEO_CG_AHEAD_OF_CONTACT_CENTRE_M];
  double sg = side == 0 ? 1.0 : -1.0;
  double bx = -e, by = sg * B / 2;
  *cx = X + c * bx - s * by;
  *cy = Y + s * bx + c * by;
  *hl = l / 2 + pad;
  *hw = b / 2 + pad;
}

/* each track's contact rectangle at the pose, grown by pad: out[6 side ..] = (centre x, centre y, cos psi,
   sin psi, half length, half width), left then right (what scan visits) */
EXPORT void eng_track_rects(const eng_t *E, double X, double Y, double psi, double pad, double *out) {
  double c = cos(psi), s = sin(psi);
  for (int side = 0; side < 2; ++side) {
    double *r = out + 6 * side;
    track_rect(E->geo, X, Y, c, s, pad, side, r, r + 1, r + 4, r + 5);
    r[2] = c;
    r[3] = s;
  }
}

/* fn(E, cell, its channel, ctx): the channel from the sector rule, computed here by rows (no integer
   division per cell) */
typedef void (*cell_fn)(eng_t *E, long long cell, long long ch, void *ctx);

static int scan(eng_t *E, double X, double Y, double psi, double pad, int check_field, cell_fn fn, void *ctx) {
  double c = cos(psi), s = sin(psi);
  double dx = E->dx, x0 = E->x0, y0 = E->y0;
  double x1 = x0 + E->nx * dx, y1 = y0 + E->ny * dx;
  for (int side = 0; side < 2; ++side) {
    double cx, cy, hl, hw;
    track_rect(E->geo, X, Y, c, s, pad, side, &cx, &cy, &hl, &hw);
    double ex = fabs(c) * hl + fabs(s) * hw;
    double ey = fabs(s) * hl + fabs(c) * hw;
    if (check_field) {
      double exu = ex - pad * (fabs(c) + fabs(s)), eyu = ey - pad * (fabs(c) + fabs(s));
      if (cx - exu < x0 || cx + exu > x1 || cy - eyu < y0 || cy + eyu > y1) {
        E->err_code = ERR_FIELD;
        E->err_x[0] = cx;
        E->err_x[1] = cy;
        return 1;
      }
    }
    long long i0 = (long long)floor((cx - ex - x0) / dx), i1 = (long long)ceil((cx + ex - x0) / dx);
    long long j0 = (long long)floor((cy - ey - y0) / dx), j1 = (long long)ceil((cy + ey - y0) / dx);
    if (i0 < 0) i0 = 0;
    if (j0 < 0) j0 = 0;
    if (i1 > E->nx - 1) i1 = E->nx - 1;
    if (j1 > E->ny - 1) j1 = E->ny - 1;
    const long long M = E->M, jm0 = j0 % M;
    for (long long i = i0; i <= i1; ++i) {
      double px = x0 + ((double)i + 0.5) * dx;
      const long long row = (i % M) * M;
      long long jm = jm0;
      for (long long j = j0; j <= j1; ++j) {
        double py = y0 + ((double)j + 0.5) * dx;
        double along = (px - cx) * c + (py - cy) * s;
        double across = -(px - cx) * s + (py - cy) * c;
        if (fabs(along) <= hl && fabs(across) <= hw) fn(E, i * E->ny + j, row + jm, ctx);
        if (++jm == M) jm = 0;
      }
    }
  }
  return 0;
}

static long long channel_of(const eng_t *E, long long cell) {
  long long i = cell / E->ny, j = cell % E->ny;
  return (i % E->M) * E->M + (j % E->M);
}

static void mark_footprint(eng_t *E, long long cell, long long ch, void *ctx) {
  (void)ctx;
  if (E->err_code) return;
  if (E->ch_cell[ch] == cell) {
    E->ch_foot[ch] = E->stamp;
  } else if (E->ch_new_stamp[ch] == E->stamp) {
    if (E->ch_new_cell[ch] != cell) {
      E->err_code = ERR_COLLISION;
      E->err_a = E->ch_new_cell[ch];
      E->err_b = cell;
      E->err_ch = ch;
    }
  } else {
    E->ch_new_stamp[ch] = E->stamp;
    E->ch_new_cell[ch] = cell;
    E->new_list[E->n_new++] = cell;
  }
}

/* Release and assignment for a step of length h from the current state (the ChannelManager of the IDAS path calls it too: integrators/engine/manager.py). */
EXPORT int eng_assign(eng_t *E, double h) {
  WORK = E->work;
  IWORK = (casadi_int *)E->iwork;
  SOIL_LAW = E->soil_law;
  const double *w = E->wv;
  double X = w[ENG_W_X], Y = w[ENG_W_Y], psi = w[ENG_W_YAW], u = w[ENG_W_U], v = w[ENG_W_V], r = w[ENG_W_R];
  double c = cos(psi), s = sin(psi);
  double X1 = X + h * (u * c - v * s), Y1 = Y + h * (u * s + v * c), psi1 = psi + h * r;
  E->stamp += 1;
  E->n_new = 0;
  if (scan(E, X, Y, psi, E->pad, 1, mark_footprint, 0)) return E->err_code;
  if (scan(E, X1, Y1, psi1, E->pad, 1, mark_footprint, 0)) return E->err_code;
  if (E->err_code) return E->err_code;
  /* release (the order of the active list is kept) */
  long long k = 0;
  for (long long q = 0; q < E->n_act; ++q) {
    long long ch = E->act[q];
    if (E->ch_foot[ch] != E->stamp && E->ch_p[ch] <= 0.0 && fabs(E->ch_v[ch]) <= E->release_rate) {
      E->ch_cell[ch] = -1;
      E->ch_z[ch] = 0.0;
      E->ch_v[ch] = 0.0;
      E->ch_p[ch] = 0.0;
    } else {
      E->act[k++] = ch;
    }
  }
  E->n_act = k;
  /* assignment, INFO_IN */
  for (long long q = 0; q < E->n_new; ++q) {
    long long cell = E->new_list[q], ch = channel_of(E, cell);
    if (E->ch_cell[ch] >= 0) {
      E->err_code = ERR_COLLISION;
      E->err_a = cell;
      E->err_b = E->ch_cell[ch];
      E->err_ch = ch;
      return E->err_code;
    }
  }
  for (long long q = 0; q < E->n_new; ++q) {
    long long cell = E->new_list[q], ch = channel_of(E, cell);
    long long i = cell / E->ny, j = cell % E->ny;
    E->ch_cell[ch] = cell;
    E->ch_cx[ch] = E->x0 + ((double)i + 0.5) * E->dx;
    E->ch_cy[ch] = E->y0 + ((double)j + 0.5) * E->dx;
    E->ch_z[ch] = E->z[cell];
    E->ch_v[ch] = E->zdot[cell];
    E->ch_zmax[ch] = E->zmax[cell];
    E->ch_pmax[ch] = E->pmax[cell];
    E->ch_zoff[ch] = E->zoff[cell];
    E->ch_delta[ch] = 0.0;
    E->ch_dc[ch] = 0.0;
    E->ch_counted[ch] = 0;
    E->ch_soil[ch] = E->soil_index[cell];
    {
      double hist[5], ncyc = (double)E->cycles[cell], zc = E->ch_z[ch];
      channel_hist(E, ch, hist);
      const double *arg[4] = {&zc, hist, &ncyc, LAW_ROW(E->ch_soil[ch])};
      double *res[1] = {E->ch_delta + ch};
      eng_cell_entry(arg, res, 0, WORK, 0);
    }
    E->ch_p[ch] = 0.0;
    E->ch_pw[2 * ch] = 0.0;
    E->ch_pw[2 * ch + 1] = 0.0;
    E->ch_vr[ch] = E->ch_v[ch];
    {
      double hist[5];
      channel_hist(E, ch, hist);
      law(E->ch_z[ch], hist, E->ch_soil[ch], &E->ch_p[ch], &E->ch_dp[ch]);
    }
    E->touched[cell] = 1;
    double cc[2] = {E->ch_cx[ch], E->ch_cy[ch]};
    cell_geo(cc, E->a, E->geo, E->ch_g + NGEO * ch);
    E->act[E->n_act++] = ch;
  }
  if (E->n_act > E->peak_active) E->peak_active = E->n_act;
  return 0;
}

/* ---- one cell ---------------------------------------------------------------------------------- */
/* (a, 1 / a, g) of a stage of length gh (the same for every stage of a cell step: computed once
   there rather than divided out in every stage) */
static inline void stage_coefficients(const eng_t *E, double gh, double *a, double *ia, double *g) {
  const double m = E->areal_mass, cd = E->damping;
  *a = (1.0 + gh * cd / m) / gh;
  *ia = 1.0 / *a;
  *g = gh / m;
}

/* INFO_OUT of one channel after its step: the history (cell.history_update, generated:
 * eng_cell_history, on the channel's soil's law row) and the storage; hist: the history the step was
 * integrated with */
static void info_out(eng_t *E, long long ch, const double *hist) {
  double zc = E->ch_z[ch], p = E->ch_p[ch], hn[5];
  {
    const double *arg[4] = {&zc, &p, hist, LAW_ROW(E->ch_soil[ch])};
    double *res[1] = {hn};
    eng_cell_history(arg, res, 0, WORK, 0);
  }
  double zm1 = hn[0], pm1 = hn[1], dc1 = hn[2];
  long long cell = E->ch_cell[ch];
  E->z[cell] = zc;
  E->zdot[cell] = E->ch_v[ch];
  E->zmax[cell] = zm1;
  E->pmax[cell] = pm1;
  E->phase[cell] = zm1 > 0 ? (signed char)hn[4] : 0;
  E->zoff[cell] = E->ch_zoff[ch] + dc1;
  if (hn[3] > 0.0 && !E->ch_counted[ch]) {
    E->ch_counted[ch] = 1;
    if (E->cycles[cell] < 65535) E->cycles[cell] += 1;
  }
  E->ch_zmax[ch] = zm1; /* ch_p stays p(z) on the old history, as the IDAS path's p_soil */
  E->ch_pmax[ch] = pm1;
  E->ch_dc[ch] = dc1;
}

/* ---- many cells at once: the operations of stage / cell_step per cell, interleaved over up to
 * CELL_LANES cells (lanes) so that the processor overlaps their Newton iterations (each lane's
 * iteration is a chain of dependent divisions and a square root: one cell alone waits on it).
 * Every lane runs exactly the scalar functions' sequence of operations on its own numbers, so the
 * results are theirs to the last bit: tests/test_terrain_engine.py builds the engine with one lane and
 * compares every state, output and stored field bit for bit (measured: the cells' time per macro step
 * of validation_grid 64 -> 47 us at 8 lanes; docs/terrain.md, "Speed"). */

/* law() for CELL_LANES lanes, all on soil ``soil``: z[i], hist[c CELL_LANES + i] (by component) -> p[i],
   dp[i]. engine_soils.inc's ENG_LAW_LANES (grid_engine_model.law_lanes_c): the generated law in a loop
   over the lanes that the compiler turns into SIMD code, each lane's result law()'s to the last bit;
   without it, law() lane by lane. */
static void law_lanes(const double *z, const double *hist, int soil, double *p, double *dp) {
#ifdef ENG_LAW_LANES
  const double *row = LAW_ROW(soil);
  ENG_LAW_LANES(row, z, hist, p, dp);
#else
  for (int i = 0; i < CELL_LANES; ++i) {
    double h[5];
    for (int c = 0; c < 5; ++c) h[c] = hist[c * CELL_LANES + i];
    law(z[i], h, soil, p + i, dp + i);
  }
#endif
}

/* one Newton update of every lane of stage_block's one-soil iteration (the scalar iteration's
   operations as selects; a function of its own so that the compiler vectorises the loop) */
static __attribute__((noinline)) void newton_lanes(double a, double g, double *restrict x, double *restrict p,
                                                   double *restrict dp, double *restrict hi, double *restrict lo,
                                                   const double *restrict pv, const double *restrict dpv,
                                                   const double *restrict zl, const double *restrict ol,
                                                   const double *restrict pll, int *restrict runv, int *restrict fix,
                                                   int *restrict mv, double *restrict xs) {
  for (int i = 0; i < CELL_LANES; ++i) {
    const int r = runv[i];
    const double pi = r ? pv[i] : p[i], dpi = r ? dpv[i] : dp[i];
    const double F = a * (x[i] - zl[i]) + g * pi - ol[i] - g * pll[i];
    const int up = F > 0.0, down = F < 0.0;
    const double h2 = (r & up) ? x[i] : hi[i];
    const double l2 = (r & down) ? x[i] : lo[i];
    const double xn = x[i] - F / (a + g * dpi);
    const double dx = fabs(xn - x[i]);
    const int moving = up | down;
    const int conv = moving & (dx <= 1e-13 * fabs(xn) + 1e-18);
    const int inside = (xn < h2) & (xn > l2);
    const int acc = moving & !conv & (dx <= NEWTON_ACCEPT * fabs(xn)) & inside;
    const int step = moving & !conv & !acc;
    p[i] = r ? (acc ? fmax(0.0, pi + dpi * (xn - x[i])) : pi) : p[i];
    dp[i] = dpi;
    hi[i] = h2;
    lo[i] = l2;
    xs[i] = xn;
    fix[i] = r & step & !inside & (l2 == -INFINITY);
    mv[i] = r & (acc | step);
    runv[i] = r & step;
  }
}

/* the lanes' new iterates after newton_lanes (and the rare bracket of stage_block): a step that left
   the bracket [lo, hi] is replaced by its midpoint */
static __attribute__((noinline)) void newton_lanes_x(double *restrict x, const double *restrict hi,
                                                     const double *restrict lo, const int *restrict runv,
                                                     const int *restrict mv, const double *restrict xs) {
  for (int i = 0; i < CELL_LANES; ++i) {
    const double xn = (runv[i] & !((xs[i] < hi[i]) & (xs[i] > lo[i]))) ? 0.5 * (lo[i] + hi[i]) : xs[i];
    x[i] = mv[i] ? xn : x[i];
  }
}

/* stage() for lanes i < m: zeta, omega, pl, zs, ps, dps per lane, (a, ia, g) shared; Z, pz, dpz
   written after every read of ps, dps (they may alias). Returns the first lane whose stage did not
   converge, or -1. */
static int stage_block(eng_t *E, int m, const double *zeta, const double *omega, const double *pl, double a,
                       double ia, double g, const double *hist, const int *soil, const double *zs, const double *ps,
                       const double *dps, double *Z, double *pz, double *dpz) {
  double hi[CELL_LANES], lo[CELL_LANES], x[CELL_LANES], p[CELL_LANES], dp[CELL_LANES];
  int run[CELL_LANES], left = m;
  for (int i = 0; i < m; ++i) {
    hi[i] = zeta[i] + (omega[i] + g * pl[i]) * ia;
    lo[i] = -INFINITY;
    x[i] = (a * zeta[i] + omega[i] + g * (pl[i] - ps[i] + dps[i] * zs[i])) / (a + g * dps[i]);
    if (!(x[i] < hi[i])) x[i] = hi[i];
    run[i] = 1;
  }
  int same_soil = 1;
  for (int i = 1; i < m; ++i) same_soil &= soil[i] == soil[0];
  if (same_soil) {
    /* the lanes on one soil (always without a soil map): every lane's iteration at once, in loops over
       all CELL_LANES lanes without branches that the compiler turns into SIMD code (law_lanes, then the
       Newton update as selects): a lane that has stopped, or past m, computes numbers that are not used,
       and every running lane does the scalar iteration's operations in its order (the same bits) */
    double hl[5 * CELL_LANES], zl[CELL_LANES], ol[CELL_LANES], pll[CELL_LANES];
    int runv[CELL_LANES];
    for (int i = 0; i < CELL_LANES; ++i) {
      const int k = i < m ? i : 0;
      for (int c = 0; c < 5; ++c) hl[c * CELL_LANES + i] = hist[5 * k + c];
      zl[i] = zeta[k];
      ol[i] = omega[k];
      pll[i] = pl[k];
      x[i] = x[k];
      hi[i] = hi[k];
      lo[i] = lo[k];
      p[i] = dp[i] = 0.0;
      runv[i] = i < m;
    }
    for (int it = 0; it < 100 && left > 0; ++it) {
      double pv[CELL_LANES], dpv[CELL_LANES], xs[CELL_LANES];
      int fix[CELL_LANES], mv[CELL_LANES];
      law_lanes(x, hl, soil[0], pv, dpv);
      E->n_newton += left;
      newton_lanes(a, g, x, p, dp, hi, lo, pv, dpv, zl, ol, pll, runv, fix, mv, xs);
      left = 0;
      for (int i = 0; i < m; ++i) {
        left += runv[i];
        if (fix[i]) { /* rare: no bracket below yet (the scalar iteration's law at hi) */
          double ph, dph;
          law(hi[i], hist + 5 * i, soil[i], &ph, &dph);
          lo[i] = hi[i] - g * ph * ia;
        }
      }
      newton_lanes_x(x, hi, lo, runv, mv, xs);
    }
  } else {
    for (int it = 0; it < 100 && left > 0; ++it) {
      for (int i = 0; i < m; ++i)
        if (run[i]) law(x[i], hist + 5 * i, soil[i], p + i, dp + i);
      for (int i = 0; i < m; ++i) {
        if (!run[i]) continue;
        E->n_newton += 1;
        double F = a * (x[i] - zeta[i]) + g * p[i] - omega[i] - g * pl[i];
        if (F > 0.0) hi[i] = x[i];
        else if (F < 0.0) lo[i] = x[i];
        else {
          run[i] = 0;
          --left;
          continue;
        }
        double xn = x[i] - F / (a + g * dp[i]);
        if (fabs(xn - x[i]) <= 1e-13 * fabs(xn) + 1e-18) {
          run[i] = 0;
          --left;
          continue;
        }
        if (fabs(xn - x[i]) <= NEWTON_ACCEPT * fabs(xn) && xn < hi[i] && xn > lo[i]) {
          p[i] = fmax(0.0, p[i] + dp[i] * (xn - x[i]));
          x[i] = xn;
          run[i] = 0;
          --left;
          continue;
        }
        if (!(xn < hi[i] && xn > lo[i])) {
          if (lo[i] == -INFINITY) {
            double ph, dph;
            law(hi[i], hist + 5 * i, soil[i], &ph, &dph);
            lo[i] = hi[i] - g * ph * ia;
          }
          if (!(xn < hi[i] && xn > lo[i])) xn = 0.5 * (lo[i] + hi[i]);
        }
        x[i] = xn;
      }
    }
  }
  int bad = -1;
  for (int i = 0; i < m; ++i) {
    if (bad < 0 && !(fabs(a * (x[i] - zeta[i]) + g * p[i] - omega[i] - g * pl[i]) <=
                     (1e-6 * fabs(x[i]) + 1e-18) * (a + g * dp[i])))
      bad = i;
  }
  for (int i = 0; i < m; ++i) {
    Z[i] = x[i];
    pz[i] = p[i];
    dpz[i] = dp[i];
  }
  return bad;
}

/* a batch of cells that take the same step: n substeps, Euler or SDIRK (cell_step's two methods);
   lane i: channel ch[i], its history hist[5 i..], its load pl[i (n + 1) + k] and fractions
   fr[2 (n + 1) i + 2 k + t] at the substep ends (cell_step's pl, f) */
typedef struct {
  int m, euler;
  long long n;
  long long ch[CELL_LANES];
  int soil[CELL_LANES];
  double hist[5 * CELL_LANES];
  double *pl, *fr;
} cell_batch_t;

/* cell_step for every lane of B over a step h: the lanes' (z, v, p, dp, vr) in and out of the
   channel arrays, work[2 i + t] as cell_step's work. Returns the first lane that failed, or -1. */
static int cell_step_block(eng_t *E, cell_batch_t *B, double h, double *work) {
  const int m = B->m;
  const long long n = B->n, n1 = n + 1;
  double gam = E->gamma, hs = h / (double)n, gh = gam * hs;
  double z0[CELL_LANES], v0[CELL_LANES], pz[CELL_LANES], dpz[CELL_LANES], vr[CELL_LANES];
  double Z1[CELL_LANES], Z2[CELL_LANES], plk[CELL_LANES], p0[CELL_LANES], p1[CELL_LANES];
  double zeta[CELL_LANES], omega[CELL_LANES];
  for (int i = 0; i < m; ++i) {
    const long long ch = B->ch[i];
    z0[i] = E->ch_z[ch];
    v0[i] = E->ch_v[ch];
    pz[i] = E->ch_p[ch];
    dpz[i] = E->ch_dp[ch];
    vr[i] = E->ch_vr[ch];
    work[2 * i] = work[2 * i + 1] = 0.0;
  }
  int bad = -1;
  if (B->euler) {
    double ae, iae, ge, ihs = 1.0 / hs;
    stage_coefficients(E, hs, &ae, &iae, &ge);
    for (long long k = 0; k < n; ++k) {
      for (int i = 0; i < m; ++i) {
        p0[i] = pz[i];
        plk[i] = B->pl[i * n1 + k + 1];
      }
      if ((bad = stage_block(E, m, z0, v0, plk, ae, iae, ge, B->hist, B->soil, z0, pz, dpz, Z1, pz, dpz)) >= 0)
        return bad;
      for (int i = 0; i < m; ++i) {
        const double *f = B->fr + 2 * n1 * i;
        double w1 = 0.5 * (p0[i] + pz[i]) * fmax(Z1[i] - z0[i], 0.0);
        for (int t = 0; t < 2; ++t) work[2 * i + t] += 0.5 * (f[2 * k + t] + f[2 * k + 2 + t]) * w1;
        v0[i] = (Z1[i] - z0[i]) * ihs;
        vr[i] = v0[i];
        z0[i] = Z1[i];
      }
      E->n_cell_stages += m;
    }
  } else {
    double a, ia, g, igh = 1.0 / gh, ihs = 1.0 / hs;
    stage_coefficients(E, gh, &a, &ia, &g);
    const double q0 = (1.0 - gam) / gam * ihs, q1 = ihs / (gam * (gam - 1.0)), q2 = (2.0 - gam) / (1.0 - gam) * ihs;
    for (long long k = 0; k < n; ++k) {
      for (int i = 0; i < m; ++i) {
        double plA = B->pl[i * n1 + k], plB = B->pl[i * n1 + k + 1];
        p0[i] = pz[i];
        plk[i] = plA + (plB - plA) * gam;
      }
      if ((bad = stage_block(E, m, z0, v0, plk, a, ia, g, B->hist, B->soil, z0, pz, dpz, Z1, pz, dpz)) >= 0)
        return bad;
      for (int i = 0; i < m; ++i) {
        p1[i] = pz[i];
        double V1 = (Z1[i] - z0[i]) * igh;
        double A1 = (V1 - v0[i]) * igh;
        zeta[i] = z0[i] + hs * (1.0 - gam) * V1;
        omega[i] = v0[i] + hs * (1.0 - gam) * A1;
        plk[i] = B->pl[i * n1 + k + 1];
      }
      if ((bad = stage_block(E, m, zeta, omega, plk, a, ia, g, B->hist, B->soil, Z1, pz, dpz, Z2, pz, dpz)) >= 0)
        return bad;
      double m1 = 0.5 * gam, m2 = 0.5 * (gam + 1.0);
      for (int i = 0; i < m; ++i) {
        const double *f = B->fr + 2 * n1 * i;
        double w1 = 0.5 * (p0[i] + p1[i]) * fmax(Z1[i] - z0[i], 0.0), w2 = 0.5 * (p1[i] + pz[i]) * fmax(Z2[i] - Z1[i], 0.0);
        for (int t = 0; t < 2; ++t) {
          double fa = f[2 * k + t], fb = f[2 * k + 2 + t];
          work[2 * i + t] += (fa + (fb - fa) * m1) * w1 + (fa + (fb - fa) * m2) * w2;
        }
        v0[i] = (Z2[i] - zeta[i]) * igh;
        vr[i] = z0[i] * q0 + Z1[i] * q1 + Z2[i] * q2;
        z0[i] = Z2[i];
      }
      E->n_cell_stages += 2 * m;
    }
  }
  for (int i = 0; i < m; ++i) {
    const long long ch = B->ch[i];
    E->ch_z[ch] = z0[i];
    E->ch_v[ch] = v0[i];
    E->ch_p[ch] = pz[i];
    E->ch_dp[ch] = dpz[i];
    E->ch_vr[ch] = vr[i];
  }
  return -1;
}

/* integrate the batch, then each lane's compaction power (power: 1) and INFO_OUT; 0, or -ERR_NEWTON
   with err_a the cell */
static int cell_batch_flush(eng_t *E, cell_batch_t *B, double h, double ih, int power) {
  if (B->m == 0) return 0;
  double work[2 * CELL_LANES];
  int bad = cell_step_block(E, B, h, work);
  if (bad >= 0) {
    E->err_code = ERR_NEWTON;
    E->err_a = E->ch_cell[B->ch[bad]];
    B->m = 0;
    return -ERR_NEWTON;
  }
  for (int i = 0; i < B->m; ++i) {
    const long long ch = B->ch[i];
    if (power) {
      double *pw = E->ch_pw + 2 * ch;
      pw[0] = work[2 * i] * ih;
      pw[1] = work[2 * i + 1] * ih;
    }
    info_out(E, ch, B->hist + 5 * i);
  }
  B->m = 0;
  return 0;
}

static void check_cover(eng_t *E, long long cell, long long ch, void *ctx) {
  long long *missing = (long long *)ctx;
  if (E->ch_cell[ch] != cell) {
    if (missing[0] == 0) missing[1] = cell;
    missing[0] += 1;
  }
}

/* The coverage check at the pose (X, Y, psi): every cell whose centre lies in a track's contact
 * rectangle padded by half a cell (every cell the tracks load) holds a channel. Returns the number
 * that do not (0: covered); then ERR_UNCOVERED with err_a the first, err_b their number. Called by
 * eng_run at each step end and by the IDAS reference path (ChannelManager.check_covered). */
EXPORT long long eng_uncovered(eng_t *E, double X, double Y, double psi) {
  long long missing[2] = {0, -1};
  scan(E, X, Y, psi, 0.5 * E->dx, 0, check_cover, missing);
  if (missing[0]) {
    E->err_code = ERR_UNCOVERED;
    E->err_a = missing[1];
    E->err_b = missing[0];
  }
  return missing[0];
}

/* INFO_OUT of every active channel after a step of the IDAS reference path
 * (ChannelManager.after_step): the channels' z and dz/dt as the DAE's integrator left them, ch_p
 * the reaction of the integrated model's law at that state on the history the step was integrated
 * with (given by the caller). The engine's own steps call info_out with their cell step's last stage. */
EXPORT void eng_info_out(eng_t *E) {
  WORK = E->work;
  IWORK = (casadi_int *)E->iwork;
  SOIL_LAW = E->soil_law;
  for (long long q = 0; q < E->n_act; ++q) {
    long long ch = E->act[q];
    double hist[5];
    channel_hist(E, ch, hist);
    info_out(E, ch, hist);
  }
}

#if ENG_NSEG > 0
/* The 3D vehicle's segment sums of one cell (grid_engine_model.SegmentSumsTerrain, SEG_FIELDS): the
 * cell's load fraction under track t times the hat function of its position s along the track about
 * the centres of the equal segments (constant beyond the first and last centre), then per segment the
 * weight and the weight times (z, z_max, p_max, z_off, delta, d_c); S: the 2 ENG_NSEG ENG_SEG_NF sums */
#define NSEG_SUMS (2 * ENG_NSEG * ENG_SEG_NF)
static void seg_sums(const eng_t *E, long long ch, const double *g, double *S) {
  if (!(g[1] > 0.0) && !(g[2] > 0.0)) return;
  const double *a = E->a, *geo = E->geo;
  const double l = geo[ENG_GEO_CONTACT_LENGTH_M], e = geo[ENG_GEO_CG_AHEAD_OF_CONTACT_CENTRE_M];
  const double xb = a[2] * (E->ch_cx[ch] - a[0]) + a[3] * (E->ch_cy[ch] - a[1]);
  const double u = ((l / 2 - e) - xb) * (double)ENG_NSEG / l - 0.5; /* in segments from the first centre */
  long long i0 = (long long)floor(u);
  double th = u - (double)i0;
  if (i0 < 0) {
    i0 = 0;
    th = 0.0;
  } else if (i0 >= ENG_NSEG - 1) {
    i0 = ENG_NSEG - 1;
    th = 0.0;
  }
  const double q[ENG_SEG_NF] = {1.0, E->ch_z[ch], E->ch_zmax[ch], E->ch_pmax[ch], E->ch_zoff[ch], E->ch_delta[ch],
                                E->ch_dc[ch]};
  for (int t = 0; t < 2; ++t) {
    const double f = g[1 + t];
    if (!(f > 0.0)) continue;
    double *St = S + (long long)t * ENG_NSEG * ENG_SEG_NF;
    for (int r = 0; r < 2; ++r) {
      const double w = f * (r == 0 ? 1.0 - th : th);
      if (!(w > 0.0)) continue;
      double *Si = St + (i0 + r) * ENG_SEG_NF;
      for (int m = 0; m < ENG_SEG_NF; ++m) Si[m] += w * q[m];
    }
  }
}
#else
#define NSEG_SUMS 0
#endif

/* The channel sums (the vehicle's view of the terrain) into pv's last NS: the compaction power of
 * each track over the last step (energy-consistent), the end-strip sinkages at the current state
 * (and with the 3D vehicle its segment sums after them: seg_sums). */
static void sums(eng_t *E) {
  double S[NS_MAX + NSEG_SUMS];
  for (int i = 0; i < NS_MAX + NSEG_SUMS; ++i) S[i] = 0.0;
  for (long long q = 0; q < E->n_act; ++q) {
    long long ch = E->act[q];
    const double *g = E->ch_g + NGEO * ch;
    double zc = E->ch_z[ch];
    if (E->power_mode == 0) {
      S[0] += E->ch_pw[2 * ch];
      S[1] += E->ch_pw[2 * ch + 1];
    } else {
      double pw = E->ch_p[ch] * fmax(E->ch_vr[ch], 0.0);
      S[0] += g[1] * pw;
      S[1] += g[2] * pw;
    }
    for (int r = 0; r < 4; ++r) {
      S[2 + r] += g[3 + r] * zc;
      S[6 + r] += g[3 + r];
    }
#if ENG_NSEG > 0
    seg_sums(E, ch, g, S + NS);
#endif
    if (NSEG_SUMS == 0 && E->n_sums > NS) { /* the soil under each track, weighted by the load fraction */
      const double *sv = E->soil_veh + ENG_N_TRACK_SOIL * E->ch_soil[ch]; /* ENG_TRACK_SOIL_* */
      for (int t = 0; t < 2; ++t) {
        S[NS + t] += g[1 + t];
        for (int i = 0; i < ENG_N_TRACK_SOIL; ++i) S[NS + 2 + ENG_N_TRACK_SOIL * t + i] += g[1 + t] * sv[i];
      }
    }
  }
  memcpy(E->pv + E->n_pv - E->n_sums, S, (size_t)E->n_sums * sizeof(double));
}

EXPORT void eng_sums(eng_t *E) {
  WORK = E->work;
  IWORK = (casadi_int *)E->iwork;
  SOIL_LAW = E->soil_law;
  sums(E);
}

/* the vehicle's step from w0 over h (eng_vehicle_step): w1, the pressure lines a1 and the step's error
   estimate e1 (the last stage's increment: the difference from the embedded solution of the
   stiffly accurate Rosenbrock method, symtrack/native/rosenbrock.py) */
static void vehicle_step_from(eng_t *E, const double *w0, const double *u, double h, double *w1, double *a1,
                              double *e1) {
  double hh = h;
  const double *arg[ENG_SZ_ARG] = {w0, u, E->pv, &hh};
  double *res[ENG_SZ_RES] = {w1, a1, e1};
  eng_vehicle_step(arg, res, IWORK, WORK, 0);
  E->n_vehicle_steps += 1;
}

/* The vehicle's step with its error controlled (symtrack/integrators/settings.py EngineSettings.vehicle_tolerance): a step
 * whose estimate exceeds vehicle_rtol max(|w0|, |w1|) + vehicle_atol in a differential state is
 * replaced by two steps of half its length, each controlled the same way, down to 2^-vehicle_max_halvings
 * of the macro step (a NaN estimate is halved too). vehicle_rtol = 0: every step taken as it is. */
static void vehicle_step_controlled(eng_t *E, const double *w0, const double *u, double h, int depth, double *w1,
                                    double *a1) {
  double e1[NW];
  vehicle_step_from(E, w0, u, h, w1, a1, e1);
  if (!(E->vehicle_rtol > 0.0) || depth >= E->vehicle_max_halvings) return;
  int ok = 1;
  for (int i = 0; i < NV && ok; ++i) {
    double sc = E->vehicle_atol + E->vehicle_rtol * fmax(fabs(w0[i]), fabs(w1[i]));
    ok = fabs(e1[i]) <= sc;
  }
  if (ok) return;
  E->n_vehicle_halved += 1;
  double wm[NW], am[NA];
  vehicle_step_controlled(E, w0, u, 0.5 * h, depth + 1, wm, am);
  vehicle_step_controlled(E, wm, u, 0.5 * h, depth + 1, w1, a1);
}

static void vehicle_step(eng_t *E, const double *u, double h, double *w1, double *a1) {
  vehicle_step_controlled(E, E->wv, u, h, 0, w1, a1);
}

/* ag[NA j], j = 0..n: the pose and pressure lines at the ends of n equal substeps from a0 (yaw psi0)
 * to a1 (yaw psi1), linear in time (the yaw too: its cosine and sine from it) */
static void pose_grid(double *ag, const double *a0, const double *a1, double psi0, double psi1, long long n) {
  memcpy(ag, a0, NA * sizeof(double));
  for (long long j = 1; j < n; ++j) {
    double th = (double)j / (double)n, psi = psi0 + (psi1 - psi0) * th;
    double *aj = ag + NA * j;
    aj[0] = a0[0] + (a1[0] - a0[0]) * th;
    aj[1] = a0[1] + (a1[1] - a0[1]) * th;
    aj[2] = cos(psi);
    aj[3] = sin(psi);
    for (int i = 4; i < NA; ++i) aj[i] = a0[i] + (a1[i] - a0[i]) * th;
  }
  memcpy(ag + NA * n, a1, NA * sizeof(double));
}

/* agT[k (n + 1) + j] = ag[NA j + k]: pose_grid's n + 1 poses by component */
static void transpose_grid(const double *ag, long long n, double *agT) {
  for (long long j = 0; j <= n; ++j)
    for (int k = 0; k < NA; ++k) agT[k * (n + 1) + j] = ag[NA * j + k];
}

/* the load pl[j] and fractions fr[2 j], fr[2 j + 1] of the cell centred at cc at the inner poses
   j = 1 .. ns - 1 of a window's grid (ag by pose, agT by component: transpose_grid): eng_cell_geo at
   each pose, all poses at once with engine_soils.inc's eng_cell_geo_lanes (the same bits) */
static void geo_window(const eng_t *E, const double *cc, const double *ag, const double *agT, long long ns,
                       double *pl, double *fr) {
#ifdef ENG_GEO_LANES
  (void)ag;
  double gT[3 * ns];
  eng_cell_geo_lanes((int)(ns - 1), cc, agT + 1, ns + 1, E->geo, gT, ns);
  for (long long j = 1; j < ns; ++j) {
    pl[j] = gT[j - 1];
    fr[2 * j] = gT[ns + j - 1];
    fr[2 * j + 1] = gT[2 * ns + j - 1];
  }
#else
  (void)agT;
  for (long long j = 1; j < ns; ++j) {
    double gj[NGEO];
    cell_geo(cc, ag + NA * j, E->geo, gj);
    pl[j] = gj[0];
    fr[2 * j] = gj[1];
    fr[2 * j + 1] = gj[2];
  }
#endif
}

/* gT[k GEO_CHUNK + i] = eng_cell_geo's output k for the cell centred at (cT[i], cT[GEO_CHUNK + i]), i < n,
   at the pose a (engine_soils.inc's eng_cell_geo_cells: all cells at once, the same bits) */
#define GEO_CHUNK 64
static void cells_geo(int n, const double *cT, const double *a, const double *geo, double *gT) {
#ifdef ENG_GEO_LANES
  eng_cell_geo_cells(n, cT, GEO_CHUNK, a, geo, gT, GEO_CHUNK);
#else
  for (int i = 0; i < n; ++i) {
    double c[2] = {cT[i], cT[GEO_CHUNK + i]}, g[NGEO];
    cell_geo(c, a, geo, g);
    for (int k = 0; k < NGEO; ++k) gT[k * GEO_CHUNK + i] = g[k];
  }
#endif
}

/* the vehicle's step retaken over h by the distance stop (distance_stop.h): its end state into w1, a1 and
   its position into xy */
typedef struct {
  eng_t *E;
  const double *u;
  double *w1, *a1;
  double xy[2];
} retake_t;

static int vehicle_retake(void *ctx, double h) {
  retake_t *r = (retake_t *)ctx;
  vehicle_step(r->E, r->u, h, r->w1, r->a1);
  r->xy[0] = r->w1[ENG_W_X];
  r->xy[1] = r->w1[ENG_W_Y];
  return 0;
}

/* n macro steps: step k ends at T[k] (the step starts at t0, then at T[k-1]) with the inputs
 * U[2k..2k+1]. dist[0]: distance covered so far, dist[1]: the stop distance (< 0: none), dist[2]:
 * the time from which distance counts. Writes T_out (the step's end time, shortened on the
 * distance stop), X (NV per step), Y (ny_out per step). Returns 0, or 1 when the distance stop
 * ended the run (at step *n_done - 1), or -err_code. */
EXPORT int eng_run(eng_t *E, long long n, double t0, const double *T, const double *U, double *dist,
                   int check_covered, double *T_out, double *X, double *Y, long long *n_done) {
  double w1[NW], a1[NA];
  double t = t0;
  WORK = E->work;
  IWORK = (casadi_int *)E->iwork;
  SOIL_LAW = E->soil_law;
  *n_done = 0;
  for (long long k = 0; k < n; ++k) {
    double t_next = T[k], h = t_next - t;
    const double *u = U + 2 * k;
    int done = 0;
    long long c0 = now_ns();
    if (eng_assign(E, h)) return -(int)E->err_code;
    WORK = E->work;
    IWORK = (casadi_int *)E->iwork;
    SOIL_LAW = E->soil_law;
    long long c1 = now_ns();
    E->ns_manager += c1 - c0;
    vehicle_step(E, u, h, w1, a1);
    {
      /* the distance stop (distance_stop.h): the vehicle's step taken again over the shortened h */
      retake_t rt = {E, u, w1, a1, {w1[ENG_W_X], w1[ENG_W_Y]}};
      const double xy0[2] = {E->wv[ENG_W_X], E->wv[ENG_W_Y]};
      done = distance_stop(dist, dist[1], dist[2], t, &t_next, &h, xy0, rt.xy, vehicle_retake, &rt);
    }
    for (int i = 0; i < NW; ++i) {
      if (!isfinite(w1[i])) {
        E->err_code = ERR_NONFINITE;
        return -ERR_NONFINITE;
      }
    }
    long long c2 = now_ns();
    E->ns_vehicle += c2 - c1;
    /* the pose and pressure lines at the ends of the transient windows' substeps (shared by all cells):
       the exit windows' (agrid) and the entry windows' (agrid_entry; the same grid when the counts
       are equal, as by default) */
    const double ih = h > 0.0 ? 1.0 / h : 0.0; /* the step's reciprocal (0: a zero step) */
    pose_grid(E->agrid, E->a, a1, E->wv[ENG_W_YAW], w1[ENG_W_YAW], E->exit_substeps);
    const double *grid_entry = E->agrid;
    if (E->entry_substeps != E->exit_substeps) {
      pose_grid(E->agrid_entry, E->a, a1, E->wv[ENG_W_YAW], w1[ENG_W_YAW], E->entry_substeps);
      grid_entry = E->agrid_entry;
    }
    /* the same grids by component (geo_window) */
    double gridT_exit[NA * (E->exit_substeps + 1)], gridT_entry[NA * (E->entry_substeps + 1)];
    transpose_grid(E->agrid, E->exit_substeps, gridT_exit);
    transpose_grid(grid_entry, E->entry_substeps, gridT_entry);
    /* the cells: load from the geometry at the step start (ch_g) to the geometry at its end, in
       batches of cells that take the same step (cell_batch_t: the steady cells, the exit windows, the
       entry windows), each integrated by cell_step_block when full and at the end */
    long long n_big = E->cell_substeps;
    if (E->exit_substeps > n_big) n_big = E->exit_substeps;
    if (E->entry_substeps > n_big) n_big = E->entry_substeps;
    double batch_buf[3 * CELL_LANES * 3 * (n_big + 1)];
    cell_batch_t batches[3];
    for (int b = 0; b < 3; ++b) {
      batches[b].m = 0;
      batches[b].pl = batch_buf + b * CELL_LANES * 3 * (n_big + 1);
      batches[b].fr = batches[b].pl + CELL_LANES * (n_big + 1);
    }
    batches[0].n = E->cell_substeps;
    batches[0].euler = E->steady_euler ? 1 : 0;
    batches[1].n = E->exit_substeps;
    batches[1].euler = 0;
    batches[2].n = E->entry_substeps;
    batches[2].euler = 0;
    /* in chunks of active cells: first the step-end geometry of the chunk's cells that need it, all at
       once (cells_geo), then each cell */
    for (long long q0 = 0; q0 < E->n_act; q0 += GEO_CHUNK) {
      const long long q1 = q0 + GEO_CHUNK < E->n_act ? q0 + GEO_CHUNK : E->n_act;
      double cT[2 * GEO_CHUNK], gBT[NGEO * GEO_CHUNK];
      int slot[GEO_CHUNK], nn = 0;
      for (long long q = q0; q < q1; ++q) {
        long long ch = E->act[q];
        double cc[2] = {E->ch_cx[ch], E->ch_cy[ch]};
        int skip = E->ch_z[ch] == 0.0 && E->ch_v[ch] == 0.0 && E->ch_g[NGEO * ch] == 0.0 &&
                   outside_tracks(E->geo, cc, a1);
        slot[q - q0] = skip ? -1 : nn;
        if (!skip) {
          cT[nn] = cc[0];
          cT[GEO_CHUNK + nn] = cc[1];
          ++nn;
        }
      }
      cells_geo(nn, cT, a1, E->geo, gBT);
      for (long long q = q0; q < q1; ++q) {
        long long ch = E->act[q];
        double *g = E->ch_g + NGEO * ch;
        double gB[NGEO], cc[2] = {E->ch_cx[ch], E->ch_cy[ch]};
        double *pw = E->ch_pw + 2 * ch;
        if (slot[q - q0] < 0) {
          /* an unloaded cell at rest, outside both tracks at the step end: it stays so and its
             geometry is zero (the case below, without evaluating eng_cell_geo) */
          memset(g, 0, NGEO * sizeof(double));
          pw[0] = pw[1] = 0.0;
          E->ch_p[ch] = 0.0;
          E->ch_vr[ch] = 0.0;
          continue;
        }
        for (int k = 0; k < NGEO; ++k) gB[k] = gBT[k * GEO_CHUNK + slot[q - q0]];
        double plA = g[0], plB = gB[0];
        pw[0] = pw[1] = 0.0;
        if (E->ch_z[ch] == 0.0 && E->ch_v[ch] == 0.0 && plA == 0.0 && plB == 0.0) {
          /* an unloaded cell at rest stays so (law(0) = 0 on every branch): nothing to integrate */
          memcpy(g, gB, sizeof gB);
          E->ch_p[ch] = 0.0;
          E->ch_vr[ch] = 0.0;
          continue;
        }
        int b = 0;
        const double *wgrid = 0;
        /* the transient windows, substeps with the geometry evaluated at each substep end (the overlap's
           kinks resolved to a substep): exit (the cell leaving a track's contact, its load falling, on
           its unloading line), else entry (soil reaction below entry_fraction of the load, or ringing) */
        if (plB < plA && gB[1] + gB[2] < g[1] + g[2] && E->ch_z[ch] < E->ch_zmax[ch] + E->ch_zoff[ch] + E->ch_dc[ch]) {
          if (E->exit_substeps > E->cell_substeps) {
            b = 1;
            wgrid = E->agrid;
          }
        } else if (E->ch_p[ch] < E->entry_fraction * fmax(plA, plB) || ringing(E, ch, plA, plB, ih)) {
          if (E->entry_substeps > E->cell_substeps) {
            b = 2;
            wgrid = grid_entry;
          }
        }
        cell_batch_t *B = batches + b;
        const long long ns = B->n;
        const int lane = B->m;
        double *pl = B->pl + lane * (ns + 1), *fr = B->fr + 2 * (ns + 1) * lane;
        pl[0] = plA;
        fr[0] = g[1];
        fr[1] = g[2];
        if (wgrid) {
          geo_window(E, cc, wgrid, wgrid == E->agrid ? gridT_exit : gridT_entry, ns, pl, fr);
        } else {
          for (long long j = 1; j < ns; ++j) {
            double th = (double)j / (double)ns;
            pl[j] = plA + (plB - plA) * th;
            fr[2 * j] = g[1] + (gB[1] - g[1]) * th;
            fr[2 * j + 1] = g[2] + (gB[2] - g[2]) * th;
          }
        }
        pl[ns] = plB;
        fr[2 * ns] = gB[1];
        fr[2 * ns + 1] = gB[2];
        B->ch[lane] = ch;
        B->soil[lane] = E->ch_soil[ch];
        channel_hist(E, ch, B->hist + 5 * lane);
        memcpy(g, gB, sizeof gB);
        if (++B->m == CELL_LANES) {
          int rc = cell_batch_flush(E, B, h, ih, 1);
          if (rc) return rc;
        }
      }
    }
    for (int b = 0; b < 3; ++b) {
      int rc = cell_batch_flush(E, batches + b, h, ih, 1);
      if (rc) return rc;
    }
    long long c3 = now_ns();
    E->ns_cells += c3 - c2;
    if (E->subsoil && E->n_depths > 0) {
      /* the vertical stress at the subsoil depths below every loaded cell at the step end; each
         cell keeps this pass's largest (float: the stored precision) */
      /* in blocks of loaded cells (subsoil_stress_block: SIMD over the cells) */
      double bx[SUBSOIL_BLOCK], by[SUBSOIL_BLOCK], sig[SUBSOIL_BLOCK * SUBSOIL_MAX_DEPTHS],
          sigp[SUBSOIL_BLOCK * SUBSOIL_MAX_DEPTHS];
      long long bcell[SUBSOIL_BLOCK];
      const long long nd = E->n_depths;
      int m = 0;
      /* two sweeps over the loaded cells: those on the left track's side of the centre line, then the
         others (a block then lies under one track, and subsoil_side_block_ skips the depths that the
         other track's stress does not reach) */
      for (int sweep = 0; sweep < 2; ++sweep)
      for (long long q = 0; q <= E->n_act; ++q) {
        if (q < E->n_act) {
          long long ch = E->act[q];
          if (!(E->ch_g[NGEO * ch] > 0.0)) continue;
          const double ybl = -a1[3] * (E->ch_cx[ch] - a1[0]) + a1[2] * (E->ch_cy[ch] - a1[1]);
          if ((ybl > 0.0) != (sweep == 0)) continue;
          bx[m] = E->ch_cx[ch];
          by[m] = E->ch_cy[ch];
          bcell[m] = E->ch_cell[ch];
          if (++m < SUBSOIL_BLOCK) continue;
        }
        if (m == 0) break;
        subsoil_stress_block(E->subsoil, E->subsoil_p, a1, E->geo, bx, by, m, sig, sigp);
        for (int n = 0; n < m; ++n) {
          float *o = E->sig_pass + nd * bcell[n];
          for (long long k = 0; k < nd; ++k) {
            float v = (float)sig[n * nd + k];
            if (v > o[k]) o[k] = v;
          }
          if (E->subsoil_p) {
            float *op = E->p_pass + nd * bcell[n];
            for (long long k = 0; k < nd; ++k) {
              float v = (float)sigp[n * nd + k];
              if (v > op[k]) op[k] = v;
            }
          }
        }
        m = 0;
      }
      long long c3b = now_ns();
      E->ns_subsoil += c3b - c3;
      c3 = c3b;
    }
    memcpy(E->wv, w1, sizeof w1);
    memcpy(E->a, a1, sizeof a1);
    sums(E);
    t = t_next;
    T_out[k] = t;
    memcpy(X + NV * k, w1, NV * sizeof(double));
    {
      const double *arg[ENG_SZ_ARG] = {w1, u, E->pv};
      double *res[ENG_SZ_RES] = {Y + E->ny_out * k};
      eng_outputs(arg, res, IWORK, WORK, 0);
    }
    *n_done = k + 1;
    long long c4 = now_ns();
    E->ns_outputs += c4 - c3;
    if (check_covered && eng_uncovered(E, w1[ENG_W_X], w1[ENG_W_Y], w1[ENG_W_YAW])) return -ERR_UNCOVERED;
    E->ns_manager += now_ns() - c4;
    if (done) return 1;
  }
  return 0;
}

/* The lift at a pass end (TerrainEngine.end_pass and the IDAS path's ChannelManager.end_pass): each active cell's load falls linearly from
 * p_end (its reaction at the pass end, given per channel) to zero over T, the cells alone, steps
 * of h in n substeps each, INFO_OUT after every step; it stops at the first step start t >= T at
 * which every active cell has p <= 0 and |dz/dt| <= release_rate. Returns the steps done, or
 * -err_code; *settled = 1 when the stop rule was met within max_steps. */
EXPORT long long eng_lift(eng_t *E, const double *p_end, double h, double T, long long n, long long max_steps,
                          int *settled) {
  WORK = E->work;
  IWORK = (casadi_int *)E->iwork;
  SOIL_LAW = E->soil_law;
  *settled = 0;
  /* the cells in batches (cell_step_block, SDIRK, n substeps), no overlap fractions (no work) */
  double lift_buf[CELL_LANES * 3 * (n + 1)];
  cell_batch_t B;
  B.m = 0;
  B.n = n;
  B.euler = 0;
  B.pl = lift_buf;
  B.fr = lift_buf + CELL_LANES * (n + 1);
  memset(B.fr, 0, CELL_LANES * 2 * (n + 1) * sizeof(double));
  for (long long k = 0; k < max_steps; ++k) {
    double t0 = (double)k * h;
    if (t0 >= T) {
      int all = 1;
      for (long long q = 0; q < E->n_act && all; ++q) {
        long long ch = E->act[q];
        if (!(E->ch_p[ch] <= 0.0 && fabs(E->ch_v[ch]) <= E->release_rate)) all = 0;
      }
      if (all) {
        *settled = 1;
        return k;
      }
    }
    for (long long q = 0; q <= E->n_act; ++q) {
      if (q < E->n_act) {
        long long ch = E->act[q];
        double pe = p_end[ch];
        if (E->ch_z[ch] == 0.0 && E->ch_v[ch] == 0.0 && pe == 0.0) continue;
        double *pl = B.pl + B.m * (n + 1);
        for (long long j = 0; j <= n; ++j) pl[j] = pe * fmax(0.0, 1.0 - (t0 + h * (double)j / (double)n) / T);
        B.ch[B.m] = ch;
        B.soil[B.m] = E->ch_soil[ch];
        channel_hist(E, ch, B.hist + 5 * B.m);
        if (++B.m < CELL_LANES) continue;
      }
      if (cell_batch_flush(E, &B, h, 0.0, 0)) return -ERR_NEWTON;
    }
  }
  return max_steps;
}

/* dp/dz of every active channel at its state (ch_dp; ch_p kept): the slope the cells' first implicit
 * stage starts from, for a caller whose channels were not stepped here (the IDAS reference path's
 * lift-off, ChannelManager.end_pass, before eng_lift). */
EXPORT void eng_slopes(eng_t *E) {
  WORK = E->work;
  IWORK = (casadi_int *)E->iwork;
  SOIL_LAW = E->soil_law;
  for (long long q = 0; q < E->n_act; ++q) {
    long long ch = E->act[q];
    double hist[5], p;
    channel_hist(E, ch, hist);
    law(E->ch_z[ch], hist, E->ch_soil[ch], &p, E->ch_dp + ch);
  }
}

/* The set-down's rule: the sinkage at which a cell's reaction equals the load it carries at rest,
 * p(z; hist) = pl, by bracketing from its stored z0 and bisection on the monotone law to 1e-15 m (the
 * top of the unloaded set for pl = 0); z0 itself when its reaction already equals the load. */
static double set_down_z(double z0, const double *hist, int soil, double pl) {
  double p, dp;
  law(z0, hist, soil, &p, &dp);
  if (!(pl != p)) return z0;
  int up = pl > p;
  double lo = z0, hi = z0, step = 1e-4;
  for (int it = 0; it < 60; ++it) {
    if (up) hi = lo + step;
    else lo = hi - step;
    law(up ? hi : lo, hist, soil, &p, &dp);
    if (up ? !(p < pl) : !(p > pl)) break;
    step *= 2.0;
  }
  for (int it = 0; it < 200 && hi - lo > 1e-15; ++it) {
    double mid = 0.5 * (lo + hi);
    law(mid, hist, soil, &p, &dp);
    if (p <= pl) lo = mid;
    else hi = mid;
  }
  return 0.5 * (lo + hi);
}

/* The set-down (TerrainEngine.begin_pass): every active cell at its static sinkage (set_down_z) under
 * the load it carries at rest (ch_g[0], evaluated at assignment); rate 0. */
EXPORT void eng_static(eng_t *E) {
  WORK = E->work;
  IWORK = (casadi_int *)E->iwork;
  SOIL_LAW = E->soil_law;
  for (long long q = 0; q < E->n_act; ++q) {
    long long ch = E->act[q];
    int soil = E->ch_soil[ch];
    double hist[5];
    channel_hist(E, ch, hist);
    E->ch_z[ch] = set_down_z(E->ch_z[ch], hist, soil, E->ch_g[NGEO * ch]);
    E->ch_v[ch] = 0.0;
    E->ch_vr[ch] = 0.0;
    law(E->ch_z[ch], hist, soil, E->ch_p + ch, E->ch_dp + ch);
  }
}

/* The set-down's rule on n cells given by their values (the IDAS reference path's set-down,
 * ChannelManager.begin_pass, and the brute-force reference, whose loads are their DAE's): cell k from
 * z0[k] with history hist[5 k ..] (z_max, p_max, z_off, delta, d_c) on soil soil[k] under the load
 * p_load[k] -> z[k]. Only the law table and the work vectors of E are read. */
EXPORT void eng_static_cells(eng_t *E, long long n, const double *z0, const double *hist, const unsigned char *soil,
                             const double *p_load, double *z) {
  WORK = E->work;
  IWORK = (casadi_int *)E->iwork;
  SOIL_LAW = E->soil_law;
  for (long long k = 0; k < n; ++k) z[k] = set_down_z(z0[k], hist + 5 * k, soil[k], p_load[k]);
}

/* The terrain query on the engine's own storage (terrain_query.h; TerrainEngine.surface): per point n
 * cell[n], phase[n] and out[TQ_OUT n ..] = (elevation, sinkage, height, normal x, y, z, gradient x, y);
 * returns how many points lie outside the field (their cell -1, numbers NaN). */
EXPORT long long eng_surface(const eng_t *E, const double *px, const double *py, long long n_points, long long *cell,
                             int *phase, double *out) {
  const tq_field_t F = {E->nx, E->ny, E->x0, E->y0, E->dx, E->z, E->phase, E->elev};
  return terrain_query_points(&F, px, py, n_points, cell, phase, out);
}
