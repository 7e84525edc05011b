/* symtrack engine FMU: an FMI 2.0 Co-Simulation slave of the vehicle on the million-cell terrain engine.
 *
 * Written by `symtrack export fmu` (symtrack/codegen/engine_fmu.py) from this template; see docs/codegen.md,
 * section "The FMU", and docs/terrain.md, "Files" (the field file). It is the grid standalone program
 * (symtrack/codegen/grid_standalone_main.c) turned into FMI calls: the terrain engine
 * (grid_engine.c, included unchanged, with the scenario's generated Functions engine_gen.inc and
 * engine_soils.inc) over the field's storage arrays allocated here, the scenario's numbers in
 * engine_fmu_model.h.
 *
 * Semantics:
 * - fmi2ExitInitializationMode: the field from the string parameter field_file (a raw field file,
 *   docs/terrain.md "Files"; empty: a virgin field), then what TerrainEngine.begin_pass does: the vehicle
 *   set down at rest at the start pose, the cells under it at their static sinkage (eng_assign,
 *   eng_static), the settling with zero torque, the channels assigned again;
 * - fmi2DoStep: any communication step h > 0. A whole number n >= 1 of macro steps (EF_MACRO_STEP_S,
 *   relative tolerance 1e-9) runs n macro steps of eng_run with the inputs held, on the macro-step grid
 *   (the step k ending at (k + 1) EF_MACRO_STEP_S after the grid's origin, the start: the Python time
 *   loop's output grid); any other h runs floor(h / EF_MACRO_STEP_S) macro steps and then one shorter
 *   step of eng_run to the communication point, which becomes the grid's origin for the next steps (a
 *   master's last step to its stop time, a variable-step master's steps); h <= 0 is fmi2Error. An
 *   engine error (the vehicle left the field, a channel collision, ...) is fmi2Error with its message;
 *   the instance then accepts only free/reset;
 * - outputs are computed on demand from the state and the current inputs (eng_outputs after the
 *   channel sums), as eng_run records them at each step's end;
 * - fmi2Terminate: the vehicle lifted off (TerrainEngine.end_pass: eng_lift, each loaded cell's load
 *   falling to zero over EF_LIFT_TIME_S), the pass folded into the subsoil records (World.fold_pass: the
 *   largest vertical stress, the compression state of density.pass_update; with EF_N_DEPTHS > 0), then,
 *   when field_file_out is not empty, the field written to it
 *   (through a temporary file renamed over it: field_file_out may be field_file). A write error is
 *   fmi2Error with its message.
 *
 * The FMI 2.0 headers are the Modelica Association's (2-clause BSD, the copies fmpy ships). Links libc and
 * libm only. One instance per process (canBeInstantiatedOnlyOncePerProcess): the engine keeps the
 * generated Functions' work pointer in a file-scope variable (grid_engine.c's WORK).
 */
#define _POSIX_C_SOURCE 200809L /* clock_gettime in grid_engine.c under -std=c99 */
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "grid_engine.c"
#include "engine_fmu_model.h"

typedef enum { ST_INSTANTIATED, ST_INIT, ST_STEP, ST_TERMINATED, ST_ERROR } Phase;

#define N_STR 2 /* field_file, field_file_out */

typedef struct {
  fmi2CallbackFunctions cb;
  char name[128];
  int logging;
  Phase phase;
  double t;
  long long k; /* macro steps done since t_grid: the time is t_grid + k EF_MACRO_STEP_S */
  double t_start;
  double t_grid; /* the macro-step grid's origin: the start, or the end of the last shorter step */
  double u[2], pose[3];
  char *str[N_STR];
  eng_t E;
  int allocated;
  double y[EF_NY_OUT];
  int y_valid;
  double dist[3];
  double *p_end;
  float *sigma_max, *specific_volume; /* the subsoil records (n_depths per cell; NULL without depths) */
} Instance;

#if EF_N_DEPTHS > 0
static const subsoil_tables_t ef_subsoil = {EF_N_DEPTHS, ef_sub_inv_x, ef_sub_inv_t, ef_sub_n_x, ef_sub_n_t,
                                            ef_sub_offset, ef_sub_data};
#endif

static void logf_(Instance *c, fmi2Status status, const char *category, const char *fmt, ...) {
  char buf[1024];
  va_list ap;
  if (!c || !c->cb.logger) return;
  if (!c->logging && status == fmi2OK) return;
  va_start(ap, fmt);
  vsnprintf(buf, sizeof buf, fmt, ap);
  va_end(ap);
  c->cb.logger(c->cb.componentEnvironment, c->name, status, category, "%s", buf);
}

#define FAIL(c, ...) (logf_((c), fmi2Error, "logStatusError", __VA_ARGS__), fmi2Error)

static const char *errname(long long code) {
  switch (code) {
    case ERR_FIELD: return "the vehicle left the terrain field";
    case ERR_COLLISION: return "channel collision (raise terrain.channels and export again)";
    case ERR_UNCOVERED: return "a loaded cell without a channel";
    case ERR_NONFINITE: return "the vehicle step returned a non-finite state";
    case ERR_NEWTON: return "a cell's implicit stage did not converge";
    default: return "engine error";
  }
}

/* ---- the engine's arrays (grid_standalone_main.c's, through the environment's allocator) ---- */

static void *zalloc(Instance *c, size_t n, size_t size) { return c->cb.allocateMemory(n ? n : 1, size); }

static void **engine_arrays(eng_t *E, size_t *count) {
  static void *slots[64];
  void *list[] = {E->z, E->zdot, E->zmax, E->pmax, E->phase, E->touched, E->zoff, E->cycles, E->soil_index,
                  E->ch_cell, E->ch_foot, E->ch_new_stamp, E->ch_new_cell, E->ch_z, E->ch_v, E->ch_zmax, E->ch_pmax,
                  E->ch_p, E->ch_cx, E->ch_cy, E->ch_dp, E->ch_vr, E->ch_zoff, E->ch_delta, E->ch_dc, E->ch_g,
                  E->ch_pw, E->ch_new, E->ch_counted, E->ch_soil, E->act, E->new_list, E->pv, E->wv, E->a, E->work,
                  E->agrid, E->agrid_entry};
  *count = sizeof list / sizeof list[0];
  memcpy(slots, list, sizeof list);
  return slots;
}

static void engine_free(Instance *c) {
  if (!c->allocated) return;
  size_t n;
  void **a = engine_arrays(&c->E, &n);
  for (size_t i = 0; i < n; ++i)
    if (a[i]) c->cb.freeMemory(a[i]);
  void *more[] = {c->p_end, c->E.sig_pass, c->E.p_pass, c->sigma_max, c->specific_volume};
  for (size_t i = 0; i < sizeof more / sizeof more[0]; ++i)
    if (more[i]) c->cb.freeMemory(more[i]);
  c->p_end = NULL;
  c->sigma_max = c->specific_volume = NULL;
  memset(&c->E, 0, sizeof c->E);
  c->allocated = 0;
}

/* A fresh engine over a virgin field: every array zero (the allocator's calloc), the channels free. */
static int engine_alloc(Instance *c) {
  eng_t *E = &c->E;
  memset(E, 0, sizeof *E);
  long long n = EF_NX * EF_NY, nch = EF_M * EF_M;
  E->nx = EF_NX; E->ny = EF_NY; E->M = EF_M; E->n_ch = nch;
  E->x0 = EF_X0; E->y0 = EF_Y0; E->dx = EF_DX;
  E->z = zalloc(c, n, sizeof(double)); E->zdot = zalloc(c, n, sizeof(double));
  E->zmax = zalloc(c, n, sizeof(double)); E->pmax = zalloc(c, n, sizeof(double));
  E->phase = zalloc(c, n, 1); E->touched = zalloc(c, n, 1); E->zoff = zalloc(c, n, sizeof(double));
  E->cycles = zalloc(c, n, sizeof(unsigned short)); E->soil_index = zalloc(c, n, 1);
  E->ch_cell = zalloc(c, nch, sizeof(long long)); E->ch_foot = zalloc(c, nch, sizeof(long long));
  E->ch_new_stamp = zalloc(c, nch, sizeof(long long)); E->ch_new_cell = zalloc(c, nch, sizeof(long long));
  double **chd[] = {&E->ch_z, &E->ch_v, &E->ch_zmax, &E->ch_pmax, &E->ch_p, &E->ch_cx, &E->ch_cy, &E->ch_dp,
                    &E->ch_vr, &E->ch_zoff, &E->ch_delta, &E->ch_dc};
  for (size_t i = 0; i < sizeof chd / sizeof chd[0]; ++i) *chd[i] = zalloc(c, nch, sizeof(double));
  E->ch_g = zalloc(c, NGEO * nch, sizeof(double)); E->ch_pw = zalloc(c, 2 * nch, sizeof(double));
  E->ch_new = zalloc(c, nch, 1); E->ch_counted = zalloc(c, nch, 1); E->ch_soil = zalloc(c, nch, 1);
  E->act = zalloc(c, nch, sizeof(long long)); E->new_list = zalloc(c, 4 * nch + 16, sizeof(long long));
  E->pv = zalloc(c, EF_N_PV, sizeof(double));
  E->wv = zalloc(c, NW, sizeof(double)); E->a = zalloc(c, NA, sizeof(double));
  E->work = zalloc(c, EF_WORK, sizeof(double));
  E->agrid = zalloc(c, NA * (EF_EXIT_SUBSTEPS + 1), sizeof(double));
  E->agrid_entry = zalloc(c, NA * (EF_ENTRY_SUBSTEPS + 1), sizeof(double));
  c->p_end = zalloc(c, nch, sizeof(double));
  int sub_ok = 1;
#if EF_N_DEPTHS > 0
  /* the subsoil stress (TerrainEngine: this pass's largest vertical and mean normal stress per cell and
     depth) and the field's records of them */
  E->sig_pass = zalloc(c, (size_t)(n * EF_N_DEPTHS), sizeof(float));
  E->p_pass = zalloc(c, (size_t)(n * EF_N_DEPTHS), sizeof(float));
  c->sigma_max = zalloc(c, (size_t)(n * EF_N_DEPTHS), sizeof(float));
  c->specific_volume = zalloc(c, (size_t)(n * EF_N_DEPTHS), sizeof(float));
  sub_ok = E->sig_pass && E->p_pass && c->sigma_max && c->specific_volume;
  E->subsoil = &ef_subsoil;
  E->n_depths = EF_N_DEPTHS;
#endif
  c->allocated = 1;
  size_t na;
  void **a = engine_arrays(E, &na);
  for (size_t i = 0; i < na; ++i)
    if (!a[i]) {
      engine_free(c);
      return 1;
    }
  if (!c->p_end || !sub_ok) {
    engine_free(c);
    return 1;
  }
  for (long long q = 0; q < nch; ++q) E->ch_cell[q] = E->ch_new_cell[q] = -1;
  memcpy(E->pv, ef_pv, sizeof ef_pv);
  E->geo = (double *)ef_geo;
  E->n_pv = EF_N_PV; E->ny_out = EF_NY_OUT; E->cell_substeps = EF_CELL_SUBSTEPS;
  E->entry_substeps = EF_ENTRY_SUBSTEPS; E->exit_substeps = EF_EXIT_SUBSTEPS; E->steady_euler = EF_STEADY_EULER;
  E->power_mode = EF_POWER_MODE; E->pad = EF_PAD; E->release_rate = EF_RELEASE_RATE; E->areal_mass = EF_AREAL_MASS;
  E->damping = EF_DAMPING; E->gamma = EF_GAMMA; E->entry_fraction = EF_ENTRY_FRACTION; E->ring_tol = EF_RING_TOL;
  E->vehicle_rtol = EF_VEHICLE_RTOL; E->vehicle_atol = EF_VEHICLE_ATOL; E->vehicle_max_halvings = EF_VEHICLE_MAX_HALVINGS;
  E->soil_veh = ef_soil_veh; E->soil_law = ef_soil_law; E->n_sums = EF_N_SUMS;
  return 0;
}

/* ---- the field file (symtrack/terrain/fieldfile.py: the layout; docs/terrain.md "Files") ---- */

#define FIELD_HEADER_BYTES 64
#define FIELD_CELL_BYTES (5 * 8 + 2 + 1)

static int little_endian(void) {
  const uint32_t one = 1;
  unsigned char b[4];
  memcpy(b, &one, 4);
  return b[0] == 1;
}

static fmi2Status read_field(Instance *c, const char *path) {
  eng_t *E = &c->E;
  unsigned char h[FIELD_HEADER_BYTES];
  if (!little_endian()) return FAIL(c, "field_file '%s': field files are little-endian; this host is not", path);
  FILE *f = fopen(path, "rb");
  if (!f) return FAIL(c, "field_file '%s': cannot open it", path);
  fmi2Status st = fmi2Error;
  double *file_values = NULL; /* the file's soil values and the names of its parameter layout */
  char *file_names = NULL;
  if (fread(h, 1, sizeof h, f) != sizeof h || memcmp(h, "SYMFIELD", 8) != 0) {
    (void)FAIL(c, "field_file '%s': not a symtrack field file (no SYMFIELD header; `symtrack terrain convert IN.npz "
         "OUT.field` writes one)", path);
    goto done;
  }
  uint32_t version, hbytes, n_soil, n_depths;
  int64_t nx, ny;
  double x0, y0, dx;
  memcpy(&version, h + 8, 4); memcpy(&hbytes, h + 12, 4);
  memcpy(&nx, h + 16, 8); memcpy(&ny, h + 24, 8);
  memcpy(&x0, h + 32, 8); memcpy(&y0, h + 40, 8); memcpy(&dx, h + 48, 8);
  memcpy(&n_soil, h + 56, 4); memcpy(&n_depths, h + 60, 4);
  if (version != FIELD_VERSION) {
    (void)FAIL(c, "field_file '%s': field file version %u, this FMU reads %d (a version-1 file, which does not name "
         "its soil values: `symtrack terrain convert OLD.field OLD.npz` then `symtrack terrain convert OLD.npz "
         "NEW.field` writes version %d)", path, (unsigned)version, FIELD_VERSION, FIELD_VERSION);
    goto done;
  }
  if (n_soil > 1000 || n_soil < 1 || n_depths > 64 ||
      hbytes != FIELD_HEADER_BYTES + 8u * (n_soil + n_depths) + FIELD_NAME_BYTES * (1u + n_soil)) {
    (void)FAIL(c, "field_file '%s': malformed header (header bytes %u for %u soil values and %u subsoil depths)",
         path, (unsigned)hbytes, (unsigned)n_soil, (unsigned)n_depths);
    goto done;
  }
  if (nx != EF_NX || ny != EF_NY) {
    (void)FAIL(c, "field_file '%s': a field of %lld x %lld cells; this FMU's field has %lld x %lld (terrain.size_m and "
         "terrain.cell_m of scenario %s)", path, (long long)nx, (long long)ny, EF_NX, EF_NY, EF_SCENARIO);
    goto done;
  }
  if (x0 != EF_X0 || y0 != EF_Y0 || dx != EF_DX) {
    (void)FAIL(c, "field_file '%s': origin (%.17g, %.17g) m and cell %.17g m; this FMU's field has (%.17g, %.17g) m and "
         "%.17g m", path, x0, y0, dx, EF_X0, EF_Y0, EF_DX);
    goto done;
  }
  /* the soil values by the names of the file's parameter layout (the soil law's name, then one name per
     value); a file written before soil parameters were added lacks them: they take the registry's
     defaults, a subsoil value its topsoil's (fieldfile.read_field does the same); none may lack both */
  double soil[EF_N_SOIL];
  int have[EF_N_SOIL];
  for (int i = 0; i < EF_N_SOIL; ++i) have[i] = 0;
  file_values = zalloc(c, n_soil, sizeof(double));
  file_names = zalloc(c, 1u + n_soil, FIELD_NAME_BYTES + 1);
  if (!file_values || !file_names) {
    (void)FAIL(c, "field_file '%s': out of memory", path);
    goto done;
  }
  if (fread(file_values, 8, n_soil, f) != (size_t)n_soil ||
      fseek(f, (long)(FIELD_HEADER_BYTES + 8u * (n_soil + n_depths)), SEEK_SET) != 0) {
    (void)FAIL(c, "field_file '%s': truncated in the soil values", path);
    goto done;
  }
  for (uint32_t j = 0; j <= n_soil; ++j) {
    char *nm = file_names + (size_t)j * (FIELD_NAME_BYTES + 1);
    if (fread(nm, 1, FIELD_NAME_BYTES, f) != FIELD_NAME_BYTES) {
      (void)FAIL(c, "field_file '%s': truncated in the parameter layout", path);
      goto done;
    }
    nm[FIELD_NAME_BYTES] = 0;
  }
  if (strcmp(file_names, EF_SOIL_LAW) != 0) {
    (void)FAIL(c, "field_file '%s': the field was made with the soil law %s, this FMU's is %s (model.soil_law of "
         "scenario %s)", path, file_names, EF_SOIL_LAW, EF_SCENARIO);
    goto done;
  }
  for (uint32_t j = 0; j < n_soil; ++j) {
    const char *nm = file_names + (size_t)(j + 1) * (FIELD_NAME_BYTES + 1);
    int i = 0;
    while (i < EF_N_SOIL && strcmp(nm, ef_soil_names[i]) != 0) ++i;
    if (i == EF_N_SOIL || have[i]) {
      (void)FAIL(c, "field_file '%s': the field file holds soil parameter '%s' %s", path, nm,
                 i == EF_N_SOIL ? "that this FMU's soil law does not read" : "twice");
      goto done;
    }
    soil[i] = file_values[j];
    have[i] = 1;
  }
  for (int i = 0; i < EF_N_SOIL; ++i) {
    if (have[i]) continue;
    if (ef_soil_same_as[i] >= 0) { /* a subsoil value of a file written before the subsoil layer: its topsoil's */
      soil[i] = soil[ef_soil_same_as[i]];
      continue;
    }
    if (!ef_soil_has_default[i]) {
      (void)FAIL(c, "field_file '%s': %u soil values, without %s, which has no default", path, (unsigned)n_soil,
                 ef_soil_names[i]);
      goto done;
    }
    soil[i] = ef_soil_defaults[i];
  }
  if (fseek(f, (long)(FIELD_HEADER_BYTES + 8u * n_soil), SEEK_SET) != 0) goto io;
  for (int i = 0; i < EF_N_SOIL; ++i)
    if (ef_soil_checked[i] && soil[i] != ef_soil_values[i]) {
      (void)FAIL(c, "field_file '%s': the field was made with soil %s = %.17g, this FMU has %.17g (the soil of scenario "
           "%s)", path, ef_soil_names[i], soil[i], ef_soil_values[i], EF_SCENARIO);
      goto done;
    }
  if (n_depths != EF_N_DEPTHS) {
    (void)FAIL(c, "field_file '%s': %u subsoil depths, this FMU has %d (terrain.subsoil_depths_m of scenario %s)", path,
         (unsigned)n_depths, EF_N_DEPTHS, EF_SCENARIO);
    goto done;
  }
#if EF_N_DEPTHS > 0
  double depths[EF_N_DEPTHS];
  if (fread(depths, 8, EF_N_DEPTHS, f) != (size_t)EF_N_DEPTHS) goto io;
  for (int k = 0; k < EF_N_DEPTHS; ++k)
    if (depths[k] != ef_depths[k]) {
      (void)FAIL(c, "field_file '%s': subsoil depth %d is %.17g m, this FMU's is %.17g m (terrain.subsoil_depths_m)",
           path, k, depths[k], ef_depths[k]);
      goto done;
    }
#endif
  long long n = EF_NX * EF_NY;
  long long expect = (long long)hbytes + (FIELD_CELL_BYTES + 8LL * EF_N_DEPTHS) * n + 8;
  if (fseek(f, 0, SEEK_END) != 0) goto io;
  long long size = (long long)ftell(f);
  if (size != expect) {
    (void)FAIL(c, "field_file '%s': %lld bytes, a field of %lld x %lld cells takes %lld: the file is truncated or "
         "damaged", path, size, EF_NX, EF_NY, expect);
    goto done;
  }
  if (fseek(f, (long)hbytes, SEEK_SET) != 0) goto io;
  double *fl[] = {E->z, E->zdot, E->zmax, E->pmax, E->zoff};
  for (int i = 0; i < 5; ++i)
    if (fread(fl[i], sizeof(double), (size_t)n, f) != (size_t)n) goto io;
  if (fread(E->cycles, sizeof(unsigned short), (size_t)n, f) != (size_t)n) goto io;
  if (fread(E->phase, 1, (size_t)n, f) != (size_t)n) goto io;
#if EF_N_DEPTHS > 0
  float *sub[2] = {c->sigma_max, c->specific_volume};
  static const char *sub_names[2] = {"sigma_max_Pa", "specific_volume"};
  for (int i = 0; i < 2; ++i) {
    if (fread(sub[i], sizeof(float), (size_t)(n * EF_N_DEPTHS), f) != (size_t)(n * EF_N_DEPTHS)) goto io;
    for (long long q = 0; q < n * EF_N_DEPTHS; ++q)
      if (!isfinite(sub[i][q]) || sub[i][q] < 0.0f) {
        (void)FAIL(c, "field_file '%s': %s of cell %lld at depth %lld is %g: the file is damaged", path, sub_names[i],
             q / EF_N_DEPTHS, q % EF_N_DEPTHS, (double)sub[i][q]);
        goto done;
      }
  }
#endif
  char trailer[8];
  if (fread(trailer, 1, 8, f) != 8 || memcmp(trailer, "ENDFIELD", 8) != 0) {
    (void)FAIL(c, "field_file '%s': no ENDFIELD trailer: the file is damaged", path);
    goto done;
  }
  static const char *names[5] = {"z_m", "z_rate_m_s", "z_max_m", "p_max_Pa", "z_off_m"};
  for (int i = 0; i < 5; ++i)
    for (long long q = 0; q < n; ++q)
      if (!isfinite(fl[i][q]) || (i == 4 && fl[i][q] < 0.0)) {
        (void)FAIL(c, "field_file '%s': %s of cell %lld is %.17g: the file is damaged", path, names[i], q, fl[i][q]);
        goto done;
      }
  for (long long q = 0; q < n; ++q)
    if (E->phase[q] < 0 || E->phase[q] > 2) {
      (void)FAIL(c, "field_file '%s': phase of cell %lld is %d (0, 1 or 2): the file is damaged", path, q, E->phase[q]);
      goto done;
    }
  st = fmi2OK;
  goto done;
io:
  (void)FAIL(c, "field_file '%s': read error", path);
done:
  if (file_values) c->cb.freeMemory(file_values);
  if (file_names) c->cb.freeMemory(file_names);
  fclose(f);
  return st;
}

static fmi2Status write_field(Instance *c, const char *path) {
  const eng_t *E = &c->E;
  if (!little_endian()) return FAIL(c, "field_file_out '%s': field files are little-endian; this host is not", path);
  size_t len = strlen(path);
  char *tmp = zalloc(c, len + 16, 1);
  if (!tmp) return FAIL(c, "field_file_out '%s': out of memory", path);
  snprintf(tmp, len + 16, "%s.tmp", path);
  FILE *f = fopen(tmp, "wb");
  if (!f) {
    (void)FAIL(c, "field_file_out '%s': cannot create '%s' (no such folder, or not writable)", path, tmp);
    c->cb.freeMemory(tmp);
    return fmi2Error;
  }
  unsigned char h[FIELD_HEADER_BYTES];
  uint32_t version = FIELD_VERSION, n_soil = EF_N_SOIL, n_depths = EF_N_DEPTHS;
  uint32_t hbytes = FIELD_HEADER_BYTES + 8u * (EF_N_SOIL + EF_N_DEPTHS) + FIELD_NAME_BYTES * (1u + EF_N_SOIL);
  int64_t nx = EF_NX, ny = EF_NY;
  double x0 = EF_X0, y0 = EF_Y0, dx = EF_DX;
  memcpy(h, "SYMFIELD", 8); memcpy(h + 8, &version, 4); memcpy(h + 12, &hbytes, 4);
  memcpy(h + 16, &nx, 8); memcpy(h + 24, &ny, 8);
  memcpy(h + 32, &x0, 8); memcpy(h + 40, &y0, 8); memcpy(h + 48, &dx, 8);
  memcpy(h + 56, &n_soil, 4); memcpy(h + 60, &n_depths, 4);
  long long n = EF_NX * EF_NY;
  int ok = fwrite(h, 1, sizeof h, f) == sizeof h && fwrite(ef_soil_values, 8, EF_N_SOIL, f) == (size_t)EF_N_SOIL;
#if EF_N_DEPTHS > 0
  ok = ok && fwrite(ef_depths, 8, EF_N_DEPTHS, f) == (size_t)EF_N_DEPTHS;
#endif
  for (int i = -1; i < EF_N_SOIL && ok; ++i) { /* the parameter layout: the soil law, then each value's name */
    char nm[FIELD_NAME_BYTES];
    memset(nm, 0, sizeof nm);
    strncpy(nm, i < 0 ? EF_SOIL_LAW : ef_soil_names[i], FIELD_NAME_BYTES - 1);
    ok = fwrite(nm, 1, FIELD_NAME_BYTES, f) == FIELD_NAME_BYTES;
  }
  const double *fl[] = {E->z, E->zdot, E->zmax, E->pmax, E->zoff};
  for (int i = 0; i < 5 && ok; ++i) ok = fwrite(fl[i], sizeof(double), (size_t)n, f) == (size_t)n;
  ok = ok && fwrite(E->cycles, sizeof(unsigned short), (size_t)n, f) == (size_t)n;
  ok = ok && fwrite(E->phase, 1, (size_t)n, f) == (size_t)n;
#if EF_N_DEPTHS > 0
  ok = ok && fwrite(c->sigma_max, sizeof(float), (size_t)(n * EF_N_DEPTHS), f) == (size_t)(n * EF_N_DEPTHS);
  ok = ok && fwrite(c->specific_volume, sizeof(float), (size_t)(n * EF_N_DEPTHS), f) == (size_t)(n * EF_N_DEPTHS);
#endif
  ok = ok && fwrite("ENDFIELD", 1, 8, f) == 8;
  ok = (fclose(f) == 0) && ok;
  if (!ok || rename(tmp, path) != 0) {
    remove(tmp);
    c->cb.freeMemory(tmp);
    return FAIL(c, "field_file_out '%s': write error (disk full, or the folder is not writable)", path);
  }
  c->cb.freeMemory(tmp);
  return fmi2OK;
}

/* ---- the pass: TerrainEngine.begin_pass, the steps, TerrainEngine.end_pass ---- */

static fmi2Status engine_error(Instance *c, const char *where) {
  const eng_t *E = &c->E;
  c->phase = ST_ERROR;
  if (E->err_code == ERR_FIELD)
    return FAIL(c, "%s at t = %.17g s: %s (a track's contact around (%.2f, %.2f) m; the field spans x in [%g, %g] m, "
                "y in [%g, %g] m)", where, c->t, errname(E->err_code), E->err_x[0], E->err_x[1], EF_X0,
                EF_X0 + EF_NX * EF_DX, EF_Y0, EF_Y0 + EF_NY * EF_DX);
  return FAIL(c, "%s at t = %.17g s: %s (code %lld, cells %lld %lld)", where, c->t, errname(E->err_code), E->err_code,
              E->err_a, E->err_b);
}

static fmi2Status begin_pass(Instance *c) {
  engine_free(c);
  if (engine_alloc(c)) return FAIL(c, "out of memory for the field of %lld x %lld cells", EF_NX, EF_NY);
  const char *in = c->str[0];
  if (in && *in && read_field(c, in) != fmi2OK) return fmi2Error;
  eng_t *E = &c->E;
  E->wv[ENG_W_X] = c->pose[0]; E->wv[ENG_W_Y] = c->pose[1]; E->wv[ENG_W_YAW] = c->pose[2];
  WORK = E->work;
  {
    const double *arg[2] = {E->wv, E->pv};
    double *res[1] = {E->a};
    eng_vehicle_a(arg, res, 0, WORK, 0);
  }
  if (eng_assign(E, 0.0)) return engine_error(c, "the set-down");
  eng_static(E);
  long long nset = EF_SETTLE_STEPS, done = 0;
  if (nset > 0) {
    double dist[3] = {0.0, -1.0, 0.0};
    double *Ts = zalloc(c, nset, sizeof(double)), *Us = zalloc(c, 2 * nset, sizeof(double));
    double *To = zalloc(c, nset, sizeof(double)), *Xs = zalloc(c, NV * nset, sizeof(double));
    double *Ys = zalloc(c, EF_NY_OUT * nset, sizeof(double));
    int rc = -1;
    if (Ts && Us && To && Xs && Ys) {
      for (long long k = 0; k < nset; ++k) Ts[k] = EF_SETTLE_STEP_S * (double)(k + 1);
      rc = eng_run(E, nset, 0.0, Ts, Us, dist, 0, To, Xs, Ys, &done);
    }
    void *bufs[] = {Ts, Us, To, Xs, Ys};
    for (int i = 0; i < 5; ++i)
      if (bufs[i]) c->cb.freeMemory(bufs[i]);
    if (rc < 0) return E->err_code ? engine_error(c, "the settling") : FAIL(c, "out of memory for the settling");
  }
  if (eng_assign(E, 0.0)) return engine_error(c, "the set-down");
  eng_sums(E); /* TerrainEngine.outputs_now */
  c->dist[0] = 0.0; c->dist[1] = -1.0; c->dist[2] = 0.0; /* no distance stop: the master ends the run */
  c->k = 0;
  c->t = c->t_grid = c->t_start;
  c->y_valid = 0;
  return fmi2OK;
}

static fmi2Status outputs(Instance *c) {
  if (c->y_valid) return fmi2OK;
  WORK = c->E.work;
  const double *arg[3] = {c->E.wv, c->u, c->E.pv};
  double *res[1] = {c->y};
  eng_outputs(arg, res, 0, WORK, 0);
  c->y_valid = 1;
  return fmi2OK;
}

static fmi2Status end_pass(Instance *c) {
  eng_t *E = &c->E;
  if (E->n_act) {
    int settled = 0;
    memcpy(c->p_end, E->ch_p, (size_t)E->n_ch * sizeof(double));
    long long rc = eng_lift(E, c->p_end, EF_SETTLE_STEP_S, EF_LIFT_TIME_S, EF_EXIT_SUBSTEPS, EF_LIFT_MAX_STEPS,
                            &settled);
    if (rc < 0) return engine_error(c, "the lift-off");
    if (!settled)
      logf_(c, fmi2Warning, "logStatusWarning", "%lld cells had not unloaded %g s after the vehicle was lifted; "
            "their state is stored", E->n_act, EF_LIFT_MAX_STEPS * EF_SETTLE_STEP_S);
  }
#if EF_N_DEPTHS > 0
  /* World.fold_pass: the pass's largest vertical stress into the record (np.maximum), the same stress
     plus the soil's own weight into the compression state (density.pass_update over the cells the pass touched: a
     depth yields where p > 0 and density.load_update's new v1 is below the current v1, the soil's
     initial v1_0 where the record is 0: the virgin line N - (lambda - kappa) ln(p / 1 kPa), with a
     yield line (m > 0) the k2 line from where the current recompression line meets it, the saturation
     bound v_min + kappa ln p; the same operations in the same order, so the same bits) */
  {
    long long n = EF_NX * EF_NY, m = n * EF_N_DEPTHS;
    for (long long q = 0; q < m; ++q)
      if (E->sig_pass[q] > c->sigma_max[q]) c->sigma_max[q] = E->sig_pass[q];
#if EF_DENSITY
    for (long long cell = 0; cell < n; ++cell) {
      if (!E->touched[cell]) continue;
      /* the state before the pass: what the earlier passes compressed, which the rut's cap keeps */
      double vb[EF_N_DEPTHS];
      for (long long k = 0; k < EF_N_DEPTHS; ++k) {
        const double b = (double)c->specific_volume[cell * EF_N_DEPTHS + k];
        vb[k] = b > 0 ? b : ef_dens_v0[k];
      }
      for (long long k = 0; k < EF_N_DEPTHS; ++k) {
        const long long q = cell * EF_N_DEPTHS + k;
        const double s = (double)E->sig_pass[q], old = (double)c->specific_volume[q];
        const double v_old = old > 0 ? old : ef_dens_v0[k];
        if (!(s > 0)) continue;
        const double p = s + ef_dens_geo[k]; /* the soil's own weight (density.geostatic_table) */
        const double lnp = log(1e-3 * p);
        double line = ef_dens_N[k] - ef_dens_lmk[k] * lnp;
#if EF_DENS_YIELD
        if (ef_dens_m[k] > 0) {
          double xy = (ef_dens_N[k] - ef_dens_lambda[k] * ef_dens_m[k] - v_old) / ef_dens_lmk[k];
          if (!(xy > 0.0)) xy = 0.0;
          const double k2line = v_old - (ef_dens_k2[k] - ef_dens_kappa[k]) * (lnp - xy);
          line = lnp > xy ? (k2line < line ? k2line : line) : v_old;
        }
#endif
        {
          const double bound = ef_dens_vmin[k] + ef_dens_kappa[k] * lnp;
          if (bound > line) line = bound;
        }
        if (line < v_old) c->specific_volume[q] = (float)line;
      }
      /* density.cap_to_rut: the rut bounds the compression below it, the pass's added compression scaled
         back from the state before it (the same operations; each cell's update and cap touch it alone) */
      double v[EF_N_DEPTHS], strain[EF_N_DEPTHS];
      for (long long k = 0; k < EF_N_DEPTHS; ++k) {
        const double old = (double)c->specific_volume[cell * EF_N_DEPTHS + k];
        v[k] = old > 0 ? old : ef_dens_v0[k];
        strain[k] = 1.0 - v[k] / ef_dens_v0[k];
      }
      double total = strain[0] * ef_depths[0];
      for (long long k = 1; k < EF_N_DEPTHS; ++k)
        total = total + 0.5 * (strain[k - 1] + strain[k]) * (ef_depths[k] - ef_depths[k - 1]);
      const double rut = E->z[cell] > 0.0 ? E->z[cell] : 0.0;
      if (total > rut) {
        double sb[EF_N_DEPTHS];
        for (long long k = 0; k < EF_N_DEPTHS; ++k) sb[k] = 1.0 - vb[k] / ef_dens_v0[k];
        double tb = sb[0] * ef_depths[0];
        for (long long k = 1; k < EF_N_DEPTHS; ++k)
          tb = tb + 0.5 * (sb[k - 1] + sb[k]) * (ef_depths[k] - ef_depths[k - 1]);
        double f = 0.0;
        if (total > tb) {
          f = (rut - tb) / (total - tb);
          if (f < 0.0) f = 0.0;
          if (f > 1.0) f = 1.0;
        }
        for (long long k = 0; k < EF_N_DEPTHS; ++k) {
          const long long q = cell * EF_N_DEPTHS + k;
          if (c->specific_volume[q] > 0) c->specific_volume[q] = (float)(vb[k] - f * (vb[k] - v[k]));
        }
      }
    }
#endif
  }
#endif
  const char *out = c->str[1];
  if (out && *out) return write_field(c, out);
  return fmi2OK;
}

/* ---- common functions ---- */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
  Instance *c = (Instance *)comp;
  if (!c) return fmi2Error;
  for (size_t i = 0; i < nCategories; i++) {
    int known = 0;
    for (int k = 0; k < EF_NLOGCAT; k++)
      if (categories[i] && strcmp(categories[i], ef_log_categories[k]) == 0) known = 1;
    if (!known) return FAIL(c, "fmi2SetDebugLogging: unknown log category '%s'", categories[i] ? categories[i] : "");
  }
  c->logging = loggingOn ? 1 : 0;
  return fmi2OK;
}

static fmi2Status set_string(Instance *c, int i, const char *v) {
  size_t n = strlen(v ? v : "") + 1;
  char *s = c->cb.allocateMemory(n, 1);
  if (!s) return FAIL(c, "fmi2SetString: out of memory");
  memcpy(s, v ? v : "", n);
  if (c->str[i]) c->cb.freeMemory(c->str[i]);
  c->str[i] = s;
  return fmi2OK;
}

static void set_start_values(Instance *c) {
  memcpy(c->u, ef_u_start, sizeof c->u);
  memcpy(c->pose, ef_pose_start, sizeof c->pose);
  set_string(c, 0, "");
  set_string(c, 1, "");
  c->t = c->t_start = c->t_grid = 0.0;
  c->k = 0;
  c->y_valid = 0;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
  (void)fmuResourceLocation;
  (void)visible;
  if (!functions || !functions->allocateMemory || !functions->freeMemory) return NULL;
  Instance tmp;
  memset(&tmp, 0, sizeof tmp);
  tmp.cb = *functions;
  snprintf(tmp.name, sizeof tmp.name, "%s", instanceName ? instanceName : "");
  tmp.logging = loggingOn ? 1 : 0;
  if (!instanceName || !*instanceName) {
    logf_(&tmp, fmi2Error, "logStatusError", "fmi2Instantiate: an instance name is required");
    return NULL;
  }
  if (fmuType != fmi2CoSimulation) {
    logf_(&tmp, fmi2Error, "logStatusError", "fmi2Instantiate: this FMU is for co-simulation only");
    return NULL;
  }
  if (!fmuGUID || strcmp(fmuGUID, EF_GUID) != 0) {
    logf_(&tmp, fmi2Error, "logStatusError", "fmi2Instantiate: GUID '%s' does not match this FMU's '%s'",
          fmuGUID ? fmuGUID : "", EF_GUID);
    return NULL;
  }
  Instance *c = (Instance *)functions->allocateMemory(1, sizeof(Instance));
  if (!c) return NULL;
  *c = tmp;
  set_start_values(c);
  if (!c->str[0] || !c->str[1]) {
    logf_(c, fmi2Error, "logStatusError", "fmi2Instantiate: out of memory");
    fmi2FreeInstance(c);
    return NULL;
  }
  c->phase = ST_INSTANTIATED;
  return c;
}

void fmi2FreeInstance(fmi2Component comp) {
  Instance *c = (Instance *)comp;
  if (!c) return;
  engine_free(c);
  for (int i = 0; i < N_STR; ++i)
    if (c->str[i]) c->cb.freeMemory(c->str[i]);
  c->cb.freeMemory(c);
}

fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
  Instance *c = (Instance *)comp;
  (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
  if (!c) return fmi2Error;
  if (c->phase != ST_INSTANTIATED) return FAIL(c, "fmi2SetupExperiment: only after fmi2Instantiate or fmi2Reset");
  c->t = c->t_start = startTime;
  return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component comp) {
  Instance *c = (Instance *)comp;
  if (!c) return fmi2Error;
  if (c->phase != ST_INSTANTIATED) return FAIL(c, "fmi2EnterInitializationMode: only once, after instantiation");
  c->phase = ST_INIT;
  return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component comp) {
  Instance *c = (Instance *)comp;
  if (!c) return fmi2Error;
  if (c->phase != ST_INIT) return FAIL(c, "fmi2ExitInitializationMode: not in initialization mode");
  if (begin_pass(c) != fmi2OK) {
    c->phase = ST_ERROR;
    return fmi2Error;
  }
  c->phase = ST_STEP;
  return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component comp) {
  Instance *c = (Instance *)comp;
  if (!c) return fmi2Error;
  if (c->phase != ST_STEP) return FAIL(c, "fmi2Terminate: only in step mode");
  if (end_pass(c) != fmi2OK) {
    c->phase = ST_ERROR;
    return fmi2Error;
  }
  c->phase = ST_TERMINATED;
  return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component comp) {
  Instance *c = (Instance *)comp;
  if (!c) return fmi2Error;
  engine_free(c);
  set_start_values(c);
  c->phase = ST_INSTANTIATED;
  return fmi2OK;
}

/* ---- values ---- */

fmi2Status fmi2GetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
  Instance *c = (Instance *)comp;
  if (!c) return fmi2Error;
  if (nvr > 0 && (!vr || !value)) return FAIL(c, "fmi2GetReal: null array");
  if (c->phase == ST_ERROR) return FAIL(c, "fmi2GetReal: the instance is in the error state");
  for (size_t i = 0; i < nvr; i++) {
    fmi2ValueReference r = vr[i];
    if (r < EF_VR_POSE) {
      value[i] = c->u[r - EF_VR_U];
    } else if (r < EF_VR_X) {
      value[i] = c->pose[r - EF_VR_POSE];
    } else if (r < EF_VR_END) {
      if (c->phase == ST_INSTANTIATED || c->phase == ST_INIT || !c->allocated)
        return FAIL(c, "fmi2GetReal: states and outputs only after fmi2ExitInitializationMode (the vehicle is set "
                    "down on the field there)");
      if (r < EF_VR_Y) {
        value[i] = c->E.wv[r - EF_VR_X];
      } else {
        outputs(c);
        value[i] = c->y[r - EF_VR_Y];
      }
    } else {
      return FAIL(c, "fmi2GetReal: unknown value reference %u (this FMU's reals are 0 ... %d)", (unsigned)r,
                  EF_VR_END - 1);
    }
  }
  return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
  Instance *c = (Instance *)comp;
  if (!c) return fmi2Error;
  if (nvr > 0 && (!vr || !value)) return FAIL(c, "fmi2SetReal: null array");
  if (c->phase == ST_ERROR || c->phase == ST_TERMINATED)
    return FAIL(c, "fmi2SetReal: not after an error or fmi2Terminate");
  for (size_t i = 0; i < nvr; i++) {
    fmi2ValueReference r = vr[i];
    if (r < EF_VR_POSE) {
      c->u[r - EF_VR_U] = value[i];
      c->y_valid = 0;
    } else if (r < EF_VR_X) {
      if (c->phase == ST_STEP)
        return FAIL(c, "fmi2SetReal: the start pose (value reference %u) is fixed after initialization", (unsigned)r);
      c->pose[r - EF_VR_POSE] = value[i];
    } else if (r < EF_VR_END) {
      return FAIL(c, "fmi2SetReal: value reference %u is an output (states and outputs cannot be set)", (unsigned)r);
    } else {
      return FAIL(c, "fmi2SetReal: unknown value reference %u (this FMU's reals are 0 ... %d)", (unsigned)r,
                  EF_VR_END - 1);
    }
  }
  return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
  Instance *c = (Instance *)comp;
  if (!c) return fmi2Error;
  if (nvr > 0 && (!vr || !value)) return FAIL(c, "fmi2GetString: null array");
  for (size_t i = 0; i < nvr; i++) {
    if (vr[i] < EF_VR_STR || vr[i] >= EF_VR_STR + N_STR)
      return FAIL(c, "fmi2GetString: unknown value reference %u (this FMU's strings are %d, %d)", (unsigned)vr[i],
                  EF_VR_STR, EF_VR_STR + 1);
    value[i] = c->str[vr[i] - EF_VR_STR];
  }
  return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
  Instance *c = (Instance *)comp;
  if (!c) return fmi2Error;
  if (nvr > 0 && (!vr || !value)) return FAIL(c, "fmi2SetString: null array");
  if (c->phase != ST_INSTANTIATED && c->phase != ST_INIT)
    return FAIL(c, "fmi2SetString: field_file and field_file_out are fixed after initialization");
  for (size_t i = 0; i < nvr; i++) {
    if (vr[i] < EF_VR_STR || vr[i] >= EF_VR_STR + N_STR)
      return FAIL(c, "fmi2SetString: unknown value reference %u (this FMU's strings are %d, %d)", (unsigned)vr[i],
                  EF_VR_STR, EF_VR_STR + 1);
    if (set_string(c, (int)(vr[i] - EF_VR_STR), value[i]) != fmi2OK) return fmi2Error;
  }
  return fmi2OK;
}

/* This FMU has no Integer or Boolean variables: an empty call is fmi2OK, any reference an error. */
#define NO_VARIABLES(fn, type, constness)                                                              \
  fmi2Status fn(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, constness type value[]) { \
    Instance *c = (Instance *)comp;                                                                    \
    (void)vr; (void)value;                                                                             \
    if (!c) return fmi2Error;                                                                          \
    if (nvr == 0) return fmi2OK;                                                                       \
    return FAIL(c, #fn ": this FMU has no variables of this type (value reference %u)", (unsigned)vr[0]); \
  }
NO_VARIABLES(fmi2GetInteger, fmi2Integer, )
NO_VARIABLES(fmi2GetBoolean, fmi2Boolean, )
NO_VARIABLES(fmi2SetInteger, fmi2Integer, const)
NO_VARIABLES(fmi2SetBoolean, fmi2Boolean, const)

/* ---- FMU state and derivatives: not provided (canGetAndSetFMUstate, providesDirectionalDerivative false) ---- */

fmi2Status fmi2GetFMUstate(fmi2Component comp, fmi2FMUstate *s) {
  (void)s;
  return FAIL((Instance *)comp, "fmi2GetFMUstate: not supported (canGetAndSetFMUstate=\"false\")");
}
fmi2Status fmi2SetFMUstate(fmi2Component comp, fmi2FMUstate s) {
  (void)s;
  return FAIL((Instance *)comp, "fmi2SetFMUstate: not supported (canGetAndSetFMUstate=\"false\")");
}
fmi2Status fmi2FreeFMUstate(fmi2Component comp, fmi2FMUstate *s) {
  (void)s;
  return FAIL((Instance *)comp, "fmi2FreeFMUstate: not supported (canGetAndSetFMUstate=\"false\")");
}
fmi2Status fmi2SerializedFMUstateSize(fmi2Component comp, fmi2FMUstate s, size_t *size) {
  (void)s; (void)size;
  return FAIL((Instance *)comp, "fmi2SerializedFMUstateSize: not supported (canSerializeFMUstate=\"false\")");
}
fmi2Status fmi2SerializeFMUstate(fmi2Component comp, fmi2FMUstate s, fmi2Byte b[], size_t size) {
  (void)s; (void)b; (void)size;
  return FAIL((Instance *)comp, "fmi2SerializeFMUstate: not supported (canSerializeFMUstate=\"false\")");
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component comp, const fmi2Byte b[], size_t size, fmi2FMUstate *s) {
  (void)s; (void)b; (void)size;
  return FAIL((Instance *)comp, "fmi2DeSerializeFMUstate: not supported (canSerializeFMUstate=\"false\")");
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component comp, const fmi2ValueReference vu[], size_t nu,
                                        const fmi2ValueReference vk[], size_t nk, const fmi2Real dvk[],
                                        fmi2Real dvu[]) {
  (void)vu; (void)nu; (void)vk; (void)nk; (void)dvk; (void)dvu;
  return FAIL((Instance *)comp, "fmi2GetDirectionalDerivative: not supported (providesDirectionalDerivative=\"false\")");
}

/* ---- co-simulation ---- */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
  (void)vr; (void)nvr; (void)order; (void)value;
  return FAIL((Instance *)comp, "fmi2SetRealInputDerivatives: not supported (canInterpolateInputs=\"false\")");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
  (void)vr; (void)nvr; (void)order; (void)value;
  return FAIL((Instance *)comp, "fmi2GetRealOutputDerivatives: not supported (maxOutputDerivativeOrder=\"0\")");
}

fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
  Instance *c = (Instance *)comp;
  (void)noSetFMUStatePriorToCurrentPoint;
  if (!c) return fmi2Error;
  if (c->phase != ST_STEP) return FAIL(c, "fmi2DoStep: only after fmi2ExitInitializationMode");
  double h = communicationStepSize;
  if (fabs(currentCommunicationPoint - c->t) > 1e-9 * fmax(1.0, fabs(c->t)))
    return FAIL(c, "fmi2DoStep: currentCommunicationPoint = %.17g is not this FMU's time %.17g",
                currentCommunicationPoint, c->t);
  if (!(h > 0.0) || !isfinite(h))
    return FAIL(c, "fmi2DoStep: communicationStepSize = %.17g s must be a positive time", h);
  double ratio = h / EF_MACRO_STEP_S;
  long long n = (long long)floor(ratio + 0.5);
  int shorter = 0; /* a shorter last step to the communication point */
  if (n < 1 || fabs(ratio - (double)n) > 1e-9 * ratio) {
    n = (long long)floor(ratio);
    shorter = 1;
  }
  /* in chunks of CHUNK macro steps; each step ends on the grid: (k + 1) dt from its origin, the start
     (the Python output grid: simulation/loop.py OutputGrid) */
  enum { CHUNK = 32 };
  double T[CHUNK], U[2 * CHUNK], To[CHUNK], X[NV * CHUNK], Y[EF_NY_OUT * CHUNK];
  int rc = 0;
  for (long long j0 = 0; j0 < n && rc == 0; j0 += CHUNK) {
    long long m = n - j0 < CHUNK ? n - j0 : CHUNK, done = 0;
    for (long long j = 0; j < m; ++j) {
      T[j] = c->t_grid + (double)(c->k + j + 1) * EF_MACRO_STEP_S;
      U[2 * j] = c->u[0];
      U[2 * j + 1] = c->u[1];
    }
    rc = eng_run(&c->E, m, c->t, T, U, c->dist, 1, To, X, Y, &done);
    c->k += done;
    if (done) c->t = T[done - 1];
  }
  if (rc == 0 && shorter && currentCommunicationPoint + h > c->t) {
    /* the rest, shorter than a macro step: its end is the communication point and the grid's new origin */
    long long done = 0;
    T[0] = currentCommunicationPoint + h;
    U[0] = c->u[0];
    U[1] = c->u[1];
    rc = eng_run(&c->E, 1, c->t, T, U, c->dist, 1, To, X, Y, &done);
    if (done) {
      c->t = c->t_grid = T[0];
      c->k = 0;
    }
  }
  c->y_valid = 0;
  if (rc < 0) return engine_error(c, "fmi2DoStep");
  return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component comp) {
  return FAIL((Instance *)comp, "fmi2CancelStep: fmi2DoStep is synchronous (it never returns fmi2Pending)");
}

fmi2Status fmi2GetStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Status *value) {
  (void)s; (void)value;
  return FAIL((Instance *)comp, "fmi2GetStatus: no asynchronous step (fmi2DoStep never returns fmi2Pending)");
}

fmi2Status fmi2GetRealStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Real *value) {
  Instance *c = (Instance *)comp;
  if (!c) return fmi2Error;
  if (s != fmi2LastSuccessfulTime) return FAIL(c, "fmi2GetRealStatus: only fmi2LastSuccessfulTime");
  *value = c->t;
  return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Integer *value) {
  (void)s; (void)value;
  return FAIL((Instance *)comp, "fmi2GetIntegerStatus: no integer status");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Boolean *value) {
  Instance *c = (Instance *)comp;
  if (!c) return fmi2Error;
  if (s != fmi2Terminated) return FAIL(c, "fmi2GetBooleanStatus: only fmi2Terminated");
  *value = fmi2False; /* the slave never asks to end the simulation */
  return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component comp, const fmi2StatusKind s, fmi2String *value) {
  (void)s; (void)value;
  return FAIL((Instance *)comp, "fmi2GetStringStatus: no string status");
}
