/* The grid validation as a standalone program: the terrain engine (symtrack/native/grid_engine.c)
 * on the million-cell field of the built-in validation_grid scenario, linking only libc and libm.
 * The numbers come from generated/grid_validation.h, the engine's equations from
 * generated/engine_gen.inc (python -m codegen; symtrack/codegen/grid_standalone.py says what each is).
 *
 * It does what TerrainEngine.begin_pass and the time loop do with the EnginePlant: the vehicle set
 * down at rest, the cells under it at their static sinkage (eng_assign, eng_static), the settling
 * with zero torque, then the scenario's output steps in one eng_run with the distance stop. Every
 * step's time, vehicle state and outputs go to the CSV file named by argv[1] (default
 * grid_validation.csv); a JSON line with the run's figures goes to stdout.
 *
 *   make grid-standalone        # builds build/symtrack_grid_standalone and runs it
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "grid_engine.c"
#include "grid_validation.h"

static void *zalloc(size_t n, size_t size) {
  void *p = calloc(n ? n : 1, size);
  if (!p) {
    fprintf(stderr, "grid_standalone: out of memory\n");
    exit(2);
  }
  return p;
}

static const char *errname(long long code) {
  switch (code) {
    case ERR_FIELD: return "the vehicle left the terrain field";
    case ERR_COLLISION: return "channel collision";
    case ERR_UNCOVERED: return "a loaded cell without a channel";
    case ERR_NONFINITE: return "the vehicle step returned a non-finite state";
    case ERR_NEWTON: return "a cell's implicit stage did not converge";
    default: return "engine error";
  }
}

int main(int argc, char **argv) {
  /* an option is never taken for the CSV's name: --help prints the usage, another option is refused */
  if (argc > 2 || (argc == 2 && argv[1][0] == '-')) {
    int help = argc == 2 && (!strcmp(argv[1], "-h") || !strcmp(argv[1], "--help"));
    if (!help) fprintf(stderr, "grid_standalone: unknown option or extra argument: %s\n", argv[argc - 1]);
    fprintf(help ? stdout : stderr,
            "usage: %s [CSV]\n  Runs the grid validation on the terrain engine and writes CSV (default\n"
            "  grid_validation.csv) and a JSON line of its figures on stdout.\n  -h, --help  print this and exit\n",
            argv[0]);
    return help ? 0 : 2;
  }
  const char *csv = argc > 1 ? argv[1] : "grid_validation.csv";
  eng_t E;
  memset(&E, 0, sizeof E);
  long long n = GV_NX * GV_NY, nch = GV_M * GV_M;
  E.nx = GV_NX; E.ny = GV_NY; E.M = GV_M; E.n_ch = nch;
  E.x0 = GV_X0; E.y0 = GV_Y0; E.dx = GV_DX;
  E.z = zalloc(n, sizeof(double)); E.zdot = zalloc(n, sizeof(double));
  E.zmax = zalloc(n, sizeof(double)); E.pmax = zalloc(n, sizeof(double));
  E.phase = zalloc(n, 1); E.touched = zalloc(n, 1); E.zoff = zalloc(n, sizeof(double));
  E.cycles = zalloc(n, sizeof(unsigned short)); E.soil_index = zalloc(n, 1);
  E.ch_cell = zalloc(nch, sizeof(long long)); E.ch_foot = zalloc(nch, sizeof(long long));
  E.ch_new_stamp = zalloc(nch, sizeof(long long)); E.ch_new_cell = zalloc(nch, sizeof(long long));
  for (long long c = 0; c < nch; ++c) E.ch_cell[c] = E.ch_new_cell[c] = -1;
  double **chd[] = {&E.ch_z, &E.ch_v, &E.ch_zmax, &E.ch_pmax, &E.ch_p, &E.ch_cx, &E.ch_cy, &E.ch_dp, &E.ch_vr,
                    &E.ch_zoff, &E.ch_delta, &E.ch_dc};
  for (size_t i = 0; i < sizeof chd / sizeof chd[0]; ++i) *chd[i] = zalloc(nch, sizeof(double));
  E.ch_g = zalloc(NGEO * nch, sizeof(double)); E.ch_pw = zalloc(2 * nch, sizeof(double));
  E.ch_new = zalloc(nch, 1); E.ch_counted = zalloc(nch, 1); E.ch_soil = zalloc(nch, 1);
  E.act = zalloc(nch, sizeof(long long)); E.new_list = zalloc(4 * nch + 16, sizeof(long long));
  E.pv = zalloc(GV_N_PV, sizeof(double));
  memcpy(E.pv, gv_pv, sizeof gv_pv);
  E.geo = (double *)gv_geo;
  E.wv = zalloc(NW, sizeof(double)); E.a = zalloc(NA, sizeof(double));
  E.work = zalloc(GV_WORK, sizeof(double));
  E.agrid = zalloc(NA * (GV_EXIT_SUBSTEPS + 1), sizeof(double));
  E.agrid_entry = zalloc(NA * (GV_ENTRY_SUBSTEPS + 1), sizeof(double));
  E.n_pv = GV_N_PV; E.ny_out = GV_NY_OUT; E.cell_substeps = GV_CELL_SUBSTEPS; E.entry_substeps = GV_ENTRY_SUBSTEPS;
  E.exit_substeps = GV_EXIT_SUBSTEPS;
  E.steady_euler = GV_STEADY_EULER;
  E.power_mode = GV_POWER_MODE; E.pad = GV_PAD; E.release_rate = GV_RELEASE_RATE; E.areal_mass = GV_AREAL_MASS;
  E.damping = GV_DAMPING; E.gamma = GV_GAMMA; E.entry_fraction = GV_ENTRY_FRACTION; E.ring_tol = GV_RING_TOL;
  E.vehicle_rtol = GV_VEHICLE_RTOL; E.vehicle_atol = GV_VEHICLE_ATOL; E.vehicle_max_halvings = GV_VEHICLE_MAX_HALVINGS;
  E.soil_veh = gv_soil_veh; E.soil_law = gv_soil_law; E.n_sums = GV_N_SUMS;
  /* TerrainEngine.begin_pass: set down at rest, the cells at their static sinkage, the settling */
  E.wv[ENG_W_X] = GV_START_X; E.wv[ENG_W_Y] = GV_START_Y; E.wv[ENG_W_YAW] = GV_START_YAW;
  WORK = E.work;
  {
    const double *arg[2] = {E.wv, E.pv};
    double *res[1] = {E.a};
    eng_vehicle_a(arg, res, 0, WORK, 0);
  }
  if (eng_assign(&E, 0.0)) goto fail;
  eng_static(&E);
  long long nset = GV_SETTLE_STEPS, done = 0;
  double dist_settle[3] = {0.0, -1.0, 0.0};
  if (nset > 0) {
    double *Ts = zalloc(nset, sizeof(double)), *Us = zalloc(2 * nset, sizeof(double));
    double *To = zalloc(nset, sizeof(double)), *Xs = zalloc(NV * nset, sizeof(double));
    double *Ys = zalloc(GV_NY_OUT * nset, sizeof(double));
    for (long long k = 0; k < nset; ++k) Ts[k] = GV_SETTLE_STEP_S * (double)(k + 1);
    if (eng_run(&E, nset, 0.0, Ts, Us, dist_settle, 0, To, Xs, Ys, &done) < 0) goto fail;
    free(Ts); free(Us); free(To); free(Xs); free(Ys);
  }
  if (eng_assign(&E, 0.0)) goto fail;
  /* the time loop (EnginePlant): the output steps, the distance counted from the stop event */
  double dist[3] = {0.0, GV_STOP_DISTANCE_M, GV_STOP_FROM_T_S};
  double *To = zalloc(GV_N_STEPS, sizeof(double)), *X = zalloc(NV * GV_N_STEPS, sizeof(double));
  double *Y = zalloc(GV_NY_OUT * GV_N_STEPS, sizeof(double));
  struct timespec w0, w1;
  clock_gettime(CLOCK_MONOTONIC, &w0);
  int rc = eng_run(&E, GV_N_STEPS, 0.0, gv_T, gv_U, dist, 1, To, X, Y, &done);
  clock_gettime(CLOCK_MONOTONIC, &w1);
  if (rc < 0) goto fail;
  double wall = (double)(w1.tv_sec - w0.tv_sec) + 1e-9 * (double)(w1.tv_nsec - w0.tv_nsec);
  FILE *f = fopen(csv, "w");
  if (!f) {
    fprintf(stderr, "grid_standalone: cannot write %s\n", csv);
    return 2;
  }
  fprintf(f, "t_s");
  for (int i = 0; i < NV; ++i) fprintf(f, ",x%d", i);
  for (long long i = 0; i < GV_NY_OUT; ++i) fprintf(f, ",%s", gv_output_names[i]);
  fprintf(f, "\n");
  for (long long k = 0; k < done; ++k) {
    fprintf(f, "%.17g", To[k]);
    for (int i = 0; i < NV; ++i) fprintf(f, ",%.17g", X[NV * k + i]);
    for (long long i = 0; i < GV_NY_OUT; ++i) fprintf(f, ",%.17g", Y[GV_NY_OUT * k + i]);
    fprintf(f, "\n");
  }
  fclose(f);
  const double *xe = X + NV * (done - 1);
  printf("{\"scenario\": \"%s\", \"steps\": %lld, \"stopped_by_distance\": %s, \"sim_time_s\": %.17g, "
         "\"wall_time_s\": %.6g, \"real_time_factor\": %.6g, \"x_m\": %.17g, \"y_m\": %.17g, \"yaw_rad\": %.17g, "
         "\"peak_active_cells\": %lld}\n",
         GV_SCENARIO, done, rc == 1 ? "true" : "false", To[done - 1], wall, To[done - 1] / wall, xe[0], xe[1], xe[2],
         E.peak_active);
  return 0;
fail:
  fprintf(stderr, "grid_standalone: %s (code %lld, cells %lld %lld)\n", errname(E.err_code), E.err_code, E.err_a,
          E.err_b);
  return 1;
}
