/* symtrack: the closed loop of an MPC scenario in plain C (symtrack codegen mpc NAME --out DIR).
 *
 * The controller is the real-time iteration of symtrack.control.rti / PathTrackingMPC (one
 * Gauss-Newton SQP step per sample, preparation / feedback split, step halving on the collocation
 * residual, the shifted previous plan when a sample fails), every numerical step of it a CasADi
 * Function generated into mpc_rti.c (the dense QP solved by CasADi's qrqp, generated too). The
 * plant is the compiled homogeneous Rosenbrock integrator (homogeneous_rosenbrock.c) driven as
 * symtrack.integrators.fixed_step.FixedStepper.step drives it in the Python closed loop. Every
 * number (parameters, reference path, horizon, weights, bounds, initial state, cold start) comes
 * from mpc_scenario.h, written by the codegen command; nothing is read at run time.
 *
 *   ./mpc_closed_loop [CSV]     writes CSV (default: closed_loop.csv beside the program) and a
 *                               JSON summary on stdout
 *
 * What it does not have: the NLP fallback of the Python controller (IPOPT). A sample whose QP fails
 * or whose step is rejected applies the next command of the previous plan (the Python controller's
 * last resort) and is counted in "failed_solves".
 */
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "homogeneous_rosenbrock.h"
#include "mpc_rti.h"
#include "mpc_scenario.h"

typedef int (*cfun)(const casadi_real **, casadi_real **, casadi_int *, casadi_real *, int);
typedef int (*wfun)(casadi_int *, casadi_int *, casadi_int *, casadi_int *);

static const casadi_real **g_arg;
static casadi_real **g_res;
static casadi_int *g_iw;
static casadi_real *g_w;

static int call(cfun f, int n_in, const double **in, int n_out, double **out) {
  for (int i = 0; i < n_in; i++) g_arg[i] = in[i];
  for (int i = 0; i < n_out; i++) g_res[i] = out[i];
  return f(g_arg, g_res, g_iw, g_w, 0);
}

static int alloc_work(void) {
  wfun works[] = {mpc_rti_prepare_work, mpc_rti_feedback_work, mpc_rti_point_work, mpc_rti_defect_work,
                  mpc_rti_shift_guess_work, mpc_rti_shift_plan_work, mpc_plant_accel_work,
                  homogeneous_consistent_z_work, homogeneous_rosenbrock_controlled_chunk16_work};
  casadi_int na = 0, nr = 0, ni = 0, nw = 0;
  for (size_t k = 0; k < sizeof works / sizeof works[0]; k++) {
    casadi_int a, r, i, w;
    works[k](&a, &r, &i, &w);
    if (a > na) na = a;
    if (r > nr) nr = r;
    if (i > ni) ni = i;
    if (w > nw) nw = w;
  }
  g_arg = malloc((size_t)(na + 1) * sizeof *g_arg);
  g_res = malloc((size_t)(nr + 1) * sizeof *g_res);
  g_iw = malloc((size_t)(ni + 1) * sizeof *g_iw);
  g_w = malloc((size_t)(nw + 1) * sizeof *g_w);
  return !(g_arg && g_res && g_iw && g_w);
}

/* ------------------------------------------------------------------ reference path (path.py) */
static int searchsorted_left(double v) { /* first i with s[i] >= v */
  int lo = 0, hi = PATH_N;
  while (lo < hi) {
    int mid = (lo + hi) / 2;
    if (path_s[mid] < v) lo = mid + 1; else hi = mid;
  }
  return lo;
}

static int searchsorted_right(double v) { /* first i with s[i] > v */
  int lo = 0, hi = PATH_N;
  while (lo < hi) {
    int mid = (lo + hi) / 2;
    if (path_s[mid] <= v) lo = mid + 1; else hi = mid;
  }
  return lo;
}

static double project(double x, double y, double s_hint, int with_hint) {
  int lo = 0, hi = PATH_N;
  if (with_hint) {
    lo = searchsorted_left(s_hint + PATH_WINDOW_LO_M);
    hi = searchsorted_left(s_hint + PATH_WINDOW_HI_M) + 1;
    if (lo < 0) lo = 0;
    if (hi > PATH_N) hi = PATH_N;
  }
  int i = lo;
  double best_d = INFINITY;
  for (int j = lo; j < hi; j++) {
    double d = (path_x[j] - x) * (path_x[j] - x) + (path_y[j] - y) * (path_y[j] - y);
    if (d < best_d) { best_d = d; i = j; }
  }
  double best_s = path_s[i];
  for (int j = i - 1; j <= i; j++) {
    if (j < 0 || j >= PATH_N - 1) continue;
    double ex = path_x[j + 1] - path_x[j], ey = path_y[j + 1] - path_y[j];
    double L2 = ex * ex + ey * ey;
    if (L2 <= 0) continue;
    double t = ((x - path_x[j]) * ex + (y - path_y[j]) * ey) / L2;
    t = fmin(1.0, fmax(0.0, t));
    double px = path_x[j] + t * ex, py = path_y[j] + t * ey;
    double dd = (px - x) * (px - x) + (py - y) * (py - y);
    if (dd < best_d) { best_d = dd; best_s = path_s[j] + t * sqrt(L2); }
  }
  return best_s;
}

typedef struct { double x, y, yaw, kappa, speed; } PathPoint;

static PathPoint path_at(double s) {
  s = fmin(fmax(s, 0.0), path_s[PATH_N - 1]);
  int i = searchsorted_right(s) - 1;
  if (i > PATH_N - 2) i = PATH_N - 2;
  double t = (s - path_s[i]) / fmax(path_s[i + 1] - path_s[i], 1e-12);
  PathPoint p;
  p.x = path_x[i] + t * (path_x[i + 1] - path_x[i]);
  p.y = path_y[i] + t * (path_y[i + 1] - path_y[i]);
  p.yaw = path_psi[i] + t * (path_psi[i + 1] - path_psi[i]);
  p.kappa = path_kappa[i];
  p.speed = path_speed[i];
  return p;
}

static double lateral_error(double x, double y, double s) {
  PathPoint r = path_at(s);
  return -(x - r.x) * sin(r.yaw) + (y - r.y) * cos(r.yaw);
}

/* ref[k * 5 + j]: stage k, [x, y, yaw, speed, curvature] (column k of the 5 x (N+1) input) */
static void reference(double s0, double yaw_now, double *ref) {
  double s = s0, shift = 0.0;
  for (int k = 0; k <= MPC_N; k++) {
    PathPoint r = path_at(s);
    if (k == 0) shift = MPC_TWO_PI * nearbyint((yaw_now - r.yaw) / MPC_TWO_PI); /* Python round: half to even */
    double *o = ref + 5 * k;
    o[0] = r.x; o[1] = r.y; o[2] = r.yaw + shift; o[3] = r.speed; o[4] = r.kappa;
    s += r.speed * MPC_DT_S;
  }
}

/* ------------------------------------------------------------------ the plant (FixedStepper.step) */
static double pl_x[PLANT_NX], pl_z[PLANT_NZ], pl_u_last[PLANT_NU];
static int pl_started = 0;

static int plant_step(const double *u) {
  double zg[PLANT_NZ];
  if (!pl_started || u[0] != pl_u_last[0] || u[1] != pl_u_last[1]) {
    /* a new start or a new command: re-solve z for (x, u, p) */
    if (!pl_started) {
      double *o[] = {zg};
      const double *in[] = {pl_x, u, plant_p};
      if (call(mpc_plant_accel, 3, in, 1, o)) return 1;
    } else {
      memcpy(zg, pl_z, sizeof zg);
    }
    const double *in[] = {pl_x, zg, u, plant_p};
    double *o[] = {pl_z};
    if (call(homogeneous_consistent_z, 4, in, 1, o)) return 1;
    pl_started = 1;
  }
  long n = (long)ceil(MPC_DT_S / PLANT_FIXED_STEP_S - 1e-9);
  if (n < 1) n = 1;
  double h = MPC_DT_S / (double)n;
  static double U[PLANT_NU * PLANT_CHUNK], H[PLANT_CHUNK], X[PLANT_NX * PLANT_CHUNK], Z[PLANT_NZ * PLANT_CHUNK];
  /* the steps' error control: tolerance, largest error ratio kept (symtrack/integrators/fixed_step.py) */
  static const double ctl[2] = {PLANT_FIXED_STEP_TOLERANCE, 1.0};
  while (n > 0) {
    long k = n < PLANT_CHUNK ? n : PLANT_CHUNK;
    for (long j = 0; j < PLANT_CHUNK; j++) {
      for (int i = 0; i < PLANT_NU; i++) U[j * PLANT_NU + i] = j < k ? u[i] : 0.0;
      H[j] = j < k ? h : 0.0;
    }
    const double *in[] = {pl_x, pl_z, U, H, plant_p, ctl};
    double *o[] = {X, Z, NULL, NULL, NULL}; /* the outputs, error ratios and halvings: not used here */
    if (call(homogeneous_rosenbrock_controlled_chunk16, 6, in, 5, o)) return 1;
    memcpy(pl_x, X + (k - 1) * PLANT_NX, sizeof pl_x);
    memcpy(pl_z, Z + (k - 1) * PLANT_NZ, sizeof pl_z);
    n -= k;
  }
  memcpy(pl_u_last, u, sizeof pl_u_last);
  for (int i = 0; i < PLANT_NX; i++)
    if (!isfinite(pl_x[i])) return 2;
  return 0;
}

/* ------------------------------------------------------------------ the RTI (PathTrackingMPC) */
static double c_w[MPC_NW];                  /* the last accepted plan (scaled), shifted after failures */
static double plan_u[MPC_N][MPC_NU];        /* its commands [N m] */
static int plan_age = 0;
/* the prepared linearisation */
static double l_w[MPC_NW], l_M[MPC_NK * MPC_NCOL * MPC_N], l_Phi[MPC_NXA * MPC_NXA * (MPC_N + 1)];
static double l_Gam[MPC_NXA * MPC_NZU * (MPC_N + 1)], l_xi[MPC_NXA * (MPC_N + 1)], l_xc[MPC_NCELL + 1];

static void accept(const double *w) {
  memcpy(c_w, w, sizeof c_w);
  for (int k = 0; k < MPC_N; k++)
    for (int i = 0; i < MPC_NU; i++) plan_u[k][i] = w[k * MPC_BLOCK + MPC_NXA + i] * MPC_TORQUE_SCALE_N_M;
  plan_age = 0;
}

/* linearise at the plan shifted one sample ahead (shift = 1: the next sample's guess), or at the plan itself
 * (shift = 0: the cold start, whose first feedback comes on the measurement it was solved for; as
 * PathTrackingMPC._prepare_rti) */
static int prepare_next(const double *xc, int shift) {
  double *o1[] = {l_w};
  const double *in1[] = {c_w};
  if (shift && plan_age == 0) {
    if (call(mpc_rti_shift_guess, 1, in1, 1, o1)) return 1;
  } else {
    memcpy(l_w, c_w, sizeof l_w);
  }
  memcpy(l_xc, xc, sizeof(double) * MPC_NCELL);
  const double *in[] = {l_w, mpc_p, l_xc};
  double *o[] = {l_M, l_Phi, l_Gam, l_xi};
  return call(mpc_rti_prepare, 3, in, 4, o);
}

static int all_finite(const double *v, int n) {
  for (int i = 0; i < n; i++)
    if (!isfinite(v[i])) return 0;
  return 1;
}

static double defect_of(const double *w) {
  double d = NAN;
  const double *in[] = {w, mpc_p, l_xc};
  double *o[] = {&d};
  if (call(mpc_rti_defect, 3, in, 1, o)) return NAN;
  return d;
}

static int point_at(const double *x0s, const double *dxa, const double *GdU, const double *dU, double alpha, double *w) {
  const double *in[] = {l_w, l_M, x0s, dxa, GdU, dU, &alpha};
  double *o[] = {w};
  return call(mpc_rti_point, 7, in, 1, o);
}

/* RTI.feedback: 0 = accepted (w_out), else failed; a rejected step is followed by up to
   `relin` Gauss-Newton iterations linearised at its shortest step (RTI.feedback's relinearisations) */
static int feedback(const double *x0s, const double *ref, double *w_out, double *alpha_out, int relin) {
  static double dU[MPC_NZU], dxa[MPC_NXA * (MPC_N + 1)], GdU[MPC_NXA * (MPC_N + 1)], wb[MPC_NW];
  const double *in[] = {l_w, l_Phi, l_Gam, l_xi, x0s, ref};
  double *o[] = {dU, dxa, GdU};
  if (call(mpc_rti_feedback, 6, in, 3, o)) return 1; /* the QP failed */
  if (!all_finite(dU, MPC_NZU)) return 1;
  double alpha = 1.0, d = NAN, shortest = pow(0.5, MPC_HALVINGS);
  for (int it = 0; it <= MPC_HALVINGS; it++) {
    if (point_at(x0s, dxa, GdU, dU, alpha, w_out) || !all_finite(w_out, MPC_NW)) return 2;
    d = defect_of(w_out);
    if (d <= MPC_MAX_DEFECT) break;
    if (alpha <= shortest) break;
    alpha *= 0.5;
  }
  if (!(d <= MPC_MAX_DEFECT)) {
    if (point_at(x0s, dxa, GdU, dU, 0.0, wb)) return 2;
    double d0 = defect_of(wb);
    if (d > 2.0 * d0 + MPC_MAX_DEFECT || d0 > 10.0 * MPC_MAX_DEFECT || isnan(d)) {
      if (relin <= 0 || isnan(d)) return 3;
      /* re-linearise at the shortest step (w_out) and take one more step from there */
      memcpy(l_w, w_out, sizeof l_w);
      const double *inp[] = {l_w, mpc_p, l_xc};
      double *op[] = {l_M, l_Phi, l_Gam, l_xi};
      if (call(mpc_rti_prepare, 3, inp, 4, op)) return 3;
      return feedback(x0s, ref, w_out, alpha_out, relin - 1);
    }
  }
  *alpha_out = alpha;
  return 0;
}

static double now_s(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static int cmp_double(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

static double percentile(const double *v, int n, double q) { /* numpy's default (linear) */
  if (n == 0) return NAN;
  double *s = malloc((size_t)n * sizeof *s);
  memcpy(s, v, (size_t)n * sizeof *s);
  qsort(s, (size_t)n, sizeof *s, cmp_double);
  double pos = q / 100.0 * (double)(n - 1);
  int lo = (int)floor(pos);
  int hi = lo + 1 < n ? lo + 1 : n - 1;
  double r = s[lo] + (pos - lo) * (s[hi] - s[lo]);
  free(s);
  return r;
}

static const char USAGE[] =
    "usage: %s [CSV]\n"
    "  Runs the MPC closed loop of the scenario it was generated from (symtrack codegen mpc NAME)\n"
    "  and writes CSV (default: closed_loop.csv beside the program) and a JSON summary on stdout.\n"
    "  -h, --help  print this and exit\n";

int main(int argc, char **argv) {
  char csv_path[4096];
  /* an option is never taken for the CSV's name: --help prints the usage, another option is refused */
  if (argc > 2 || (argc == 2 && argv[1][0] == '-')) {
    int help = argc == 2 && (!strcmp(argv[1], "-h") || !strcmp(argv[1], "--help"));
    if (!help) fprintf(stderr, "mpc_closed_loop: unknown option or extra argument: %s\n", argv[argc - 1]);
    fprintf(help ? stdout : stderr, USAGE, argv[0]);
    return help ? 0 : 2;
  }
  if (argc > 1) {
    snprintf(csv_path, sizeof csv_path, "%s", argv[1]);
  } else { /* beside the program */
    const char *slash = strrchr(argv[0], '/');
    int n = slash ? (int)(slash - argv[0]) + 1 : 0;
    snprintf(csv_path, sizeof csv_path, "%.*sclosed_loop.csv", n, argv[0]);
  }
  if (alloc_work()) return 4;
  FILE *csv = fopen(csv_path, "w");
  if (!csv) {
    fprintf(stderr, "mpc_closed_loop: cannot write %s\n", csv_path);
    return 5;
  }
  fprintf(csv, "%s\n", MPC_CSV_HEADER);
  static double x0s[MPC_NXA], ref[5 * (MPC_N + 1)], wopt[MPC_NW], xc[MPC_NCELL + 1];
  static double solve_us[MPC_MAX_SAMPLES], prep_us[MPC_MAX_SAMPLES];
  double u_prev[MPC_NU], u[MPC_NU];
  memcpy(pl_x, plant_x0, sizeof pl_x);
  memcpy(u_prev, plant_u0, sizeof u_prev);
  for (int i = 0; i < MPC_NCELL; i++) xc[i] = pl_x[mpc_cell_index[i]];
  /* the cold start (solved by the codegen command, as the Python loop solves it before it engages) */
  accept(mpc_w_cold);
  if (prepare_next(xc, 0)) {
    fprintf(stderr, "mpc_closed_loop: the first preparation failed\n");
    return 1;
  }
  double t = 0.0, s_hint = project(pl_x[PLANT_I_X_M], pl_x[PLANT_I_Y_M], 0.0, 0);
  int k = 0, failed = 0, halved = 0, completed = 0;
  double wall0 = now_s();
  for (;;) {
    double x = pl_x[PLANT_I_X_M], y = pl_x[PLANT_I_Y_M], yaw = pl_x[PLANT_I_YAW_RAD];
    s_hint = project(x, y, s_hint, 1);
    double e_lat = lateral_error(x, y, s_hint);
    if (s_hint >= PATH_LENGTH_M || t >= MPC_DURATION_S - 1e-9 || k >= MPC_MAX_SAMPLES) {
      completed = s_hint >= PATH_LENGTH_M;
      /* the final state: no solve (solve_time_us 0), the last command repeated */
      fprintf(csv, "%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n", t, x, y, yaw, u_prev[0], u_prev[1], e_lat, 0.0);
      break;
    }
    reference(s_hint, yaw, ref);
    for (int i = 0; i < MPC_NXA; i++)
      x0s[i] = (i < MPC_NXP ? pl_x[mpc_pred_index[i]] : u_prev[i - MPC_NXP]) / mpc_sx[i];
    for (int i = 0; i < MPC_NCELL; i++) xc[i] = pl_x[mpc_cell_index[i]];
    double alpha = 1.0;
    double t0 = now_s();
    int flag = feedback(x0s, ref, wopt, &alpha, MPC_RELINEARISATIONS);
    double t1 = now_s();
    if (flag == 0) {
      accept(wopt);
      if (alpha < 1.0) halved++;
      memcpy(u, plan_u[0], sizeof u);
    } else {
      failed++;
      plan_age++;
      memcpy(u, plan_u[plan_age < MPC_N - 1 ? plan_age : MPC_N - 1], sizeof u);
      static double ws[MPC_NW];
      const double *in[] = {c_w};
      double *o[] = {ws};
      if (call(mpc_rti_shift_plan, 1, in, 1, o)) return 1;
      memcpy(c_w, ws, sizeof c_w);
    }
    /* the preparation of the next sample: shift, linearise, condense (no measurement) */
    if (prepare_next(xc, 1)) {
      fprintf(stderr, "mpc_closed_loop: preparation failed at t = %g s\n", t);
      return 1;
    }
    double t2 = now_s();
    solve_us[k] = 1e6 * (t1 - t0);
    prep_us[k] = 1e6 * (t2 - t1);
    fprintf(csv, "%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n", t, x, y, yaw, u[0], u[1], e_lat, solve_us[k]);
    int pf = plant_step(u);
    if (pf) {
      fprintf(stderr, "mpc_closed_loop: the plant step failed (code %d) at t = %g s\n", pf, t);
      fclose(csv);
      return 1;
    }
    memcpy(u_prev, u, sizeof u);
    t += MPC_DT_S;
    k++;
  }
  double wall = now_s() - wall0;
  if (fclose(csv) != 0) {
    fprintf(stderr, "mpc_closed_loop: writing %s failed\n", csv_path);
    return 5;
  }
  double smax = 0.0;
  for (int i = 0; i < k; i++) smax = fmax(smax, solve_us[i]);
  printf("{\n  \"scenario\": \"%s\",\n  \"solver\": \"rti (qrqp, generated C)\",\n", MPC_SCENARIO);
  printf("  \"samples\": %d,\n  \"failed_solves\": %d,\n  \"halved_steps\": %d,\n", k, failed, halved);
  printf("  \"path_completed\": %s,\n", completed ? "true" : "false");
  printf("  \"final_x_m\": %.17g,\n  \"final_y_m\": %.17g,\n  \"final_yaw_rad\": %.17g,\n", pl_x[PLANT_I_X_M],
         pl_x[PLANT_I_Y_M], pl_x[PLANT_I_YAW_RAD]);
  printf("  \"sim_time_s\": %.17g,\n", t);
  printf("  \"solve_time_median_us\": %.6g,\n  \"solve_time_p95_us\": %.6g,\n  \"solve_time_max_us\": %.6g,\n",
         percentile(solve_us, k, 50.0), percentile(solve_us, k, 95.0), smax);
  printf("  \"preparation_time_median_us\": %.6g,\n  \"preparation_time_max_us\": %.6g,\n",
         percentile(prep_us, k, 50.0), percentile(prep_us, k, 100.0));
  printf("  \"wall_time_s\": %.6g,\n  \"csv\": \"%s\"\n}\n", wall, csv_path);
  return 0;
}
