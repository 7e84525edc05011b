/* symtrack standalone: the validation scenario on the homogeneous terrain in plain C.
 *
 * Links only the generated sources (generated/homogeneous_rosenbrock.c) and libc/libm:
 *   make standalone        (or: cc -O2 -Igenerated -Isymtrack/native symtrack/codegen/standalone_main.c
 *                                 generated/homogeneous_rosenbrock.c -lm -o build/symtrack_standalone)
 *   build/symtrack_standalone [repeats]
 *
 * It runs the same time loop as symtrack.simulation.loop.run with the fixed-step integrator
 * (symtrack.integrators.fixed_step.FixedStepper): output steps of SYM_OUTPUT_DT_S split at the torque
 * changes, each advanced in ceil(length / SYM_FIXED_STEP_S) equal Rosenbrock steps (each
 * error-controlled: halved while its estimate exceeds SYM_FIXED_STEP_TOLERANCE), and the
 * run stopped SYM_STOP_DISTANCE_M after the event by shortening the last output step (three
 * secant refinements). It prints the figures of symtrack.simulation.result.summarise as JSON on stdout.
 * The scenario's numbers (parameters, static initial state, torque schedule) come from
 * generated/homogeneous_validation.h, written by python -m codegen.
 * With repeats > 1 the run is repeated and the fastest wall time is reported.
 */
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "distance_stop.h" /* the distance stop (symtrack/native/distance_stop.h, the engine's too) */
#include "homogeneous_rosenbrock.h"
#include "homogeneous_validation.h"

/* each step error-controlled as the Python run's (symtrack/integrators/fixed_step.py: halved while its
   estimate exceeds the tolerance, down to 1/256 of its length) */
#define F(name) homogeneous_rosenbrock_controlled_step##name

static const casadi_real **g_arg;
static casadi_real **g_res;
static casadi_int *g_iw;
static casadi_real *g_w;
static int g_mem;
static long g_nsteps, g_halved;
static double g_error_max;

/* Advance (x, z) over length_s with ceil(length_s / SYM_FIXED_STEP_S - 1e-9) equal steps. */
static int advance(const double *x0, const double *z0, const double *u, double length_s, double *x, double *z) {
  static const double ctl[2] = {SYM_FIXED_STEP_TOLERANCE, SYM_FIXED_STEP_CONTROL ? 1.0 : INFINITY};
  long n = (long)ceil(length_s / SYM_FIXED_STEP_S - 1e-9);
  double xt[SYM_NX], zt[SYM_NZ], r, nh;
  if (n < 1) n = 1;
  double h = length_s / (double)n;
  memcpy(x, x0, SYM_NX * sizeof *x);
  memcpy(z, z0, SYM_NZ * sizeof *z);
  for (long k = 0; k < n; k++) {
    g_arg[0] = x; g_arg[1] = z; g_arg[2] = u; g_arg[3] = sym_p; g_arg[4] = &h; g_arg[5] = ctl;
    g_res[0] = xt; g_res[1] = zt; g_res[2] = &r; g_res[3] = &nh;
    if (F()(g_arg, g_res, g_iw, g_w, g_mem) || !isfinite(r)) return 1;
    if (r > g_error_max) g_error_max = r;
    g_halved += (long)nh;
    g_nsteps += 1 + 2 * (long)nh;
    memcpy(x, xt, sizeof xt);
    memcpy(z, zt, sizeof zt);
  }
  return 0;
}

/* an output step from (x, z) taken again over h by the distance stop: its end into (xn, zn), its position
   into xy; nonzero when a step failed */
typedef struct {
  const double *x, *z, *u;
  double *xn, *zn;
  double xy[2];
} retake_t;

static int retake(void *ctx, double h) {
  retake_t *r = (retake_t *)ctx;
  if (advance(r->x, r->z, r->u, h, r->xn, r->zn)) return 1;
  r->xy[0] = r->xn[SYM_I_X_M];
  r->xy[1] = r->xn[SYM_I_Y_M];
  return 0;
}

static void torque_at(double t, double *u) {
  int cur = 0;
  for (int i = 0; i < SYM_N_TORQUE; i++)
    if (sym_torque_t_s[i] <= t + 1e-12) cur = i;
  u[0] = sym_torque_left_N_m[cur];
  u[1] = sym_torque_right_N_m[cur];
}

typedef struct {
  double distance_m, distance_after_m, lateral_signed_m, yaw_deg, sink_sprocket_max_m, sink_idler_max_m;
  double shear_driven_max_m, shear_idle_min_m, speed_final_m_s, sim_time_s;
  int stopped_by_distance, has_idle;
} Summary;

static double sinkage_mean(const double *x, int end_sprocket) {
  return end_sprocket ? 0.5 * (x[SYM_I_SINKAGE_SPROCKET_LEFT_M] + x[SYM_I_SINKAGE_SPROCKET_RIGHT_M])
                      : 0.5 * (x[SYM_I_SINKAGE_IDLER_LEFT_M] + x[SYM_I_SINKAGE_IDLER_RIGHT_M]);
}

/* Running figures of symtrack.runner.summarise, updated at every output point. */
typedef struct {
  double t_last_torque;
  int driven, idle; /* state indices, or -1 when both sprockets get the same |torque| */
} SummaryRule;

static void observe(Summary *s, const SummaryRule *r, double t, const double *x) {
  double ss = sinkage_mean(x, 1), si = sinkage_mean(x, 0);
  if (ss > s->sink_sprocket_max_m) s->sink_sprocket_max_m = ss;
  if (si > s->sink_idler_max_m) s->sink_idler_max_m = si;
  if (r->driven >= 0) {
    if (t >= r->t_last_torque) {
      if (x[r->driven] > s->shear_driven_max_m) s->shear_driven_max_m = x[r->driven];
      if (x[r->idle] < s->shear_idle_min_m) s->shear_idle_min_m = x[r->idle];
    }
  } else {
    double jm = fmax(x[SYM_I_SHEAR_LEFT_M], x[SYM_I_SHEAR_RIGHT_M]);
    if (jm > s->shear_driven_max_m) s->shear_driven_max_m = jm;
  }
}

static int run(Summary *s) {
  double x[SYM_NX], z[SYM_NZ], xn[SYM_NX], zn[SYM_NZ], u[SYM_NU];
  SummaryRule rule;
  int last = SYM_N_TORQUE - 1;
  rule.t_last_torque = sym_torque_t_s[last];
  if (fabs(sym_torque_left_N_m[last]) != fabs(sym_torque_right_N_m[last])) {
    int right_driven = fabs(sym_torque_right_N_m[last]) > fabs(sym_torque_left_N_m[last]);
    rule.driven = right_driven ? SYM_I_SHEAR_RIGHT_M : SYM_I_SHEAR_LEFT_M;
    rule.idle = right_driven ? SYM_I_SHEAR_LEFT_M : SYM_I_SHEAR_RIGHT_M;
  } else {
    rule.driven = rule.idle = -1;
  }
  memset(s, 0, sizeof *s);
  s->has_idle = rule.driven >= 0;
  s->sink_sprocket_max_m = s->sink_idler_max_m = -INFINITY;
  s->shear_driven_max_m = -INFINITY;
  s->shear_idle_min_m = INFINITY;
  memcpy(x, sym_x0, sizeof x);
  memcpy(z, sym_z0, sizeof z);
  double t = 0.0, dist = 0.0;
  observe(s, &rule, t, x);
  while (t < SYM_DURATION_S - 1e-12) {
    double t_next = fmin(t + SYM_OUTPUT_DT_S, SYM_DURATION_S);
    for (int i = 1; i < SYM_N_TORQUE; i++) {
      double tc = sym_torque_t_s[i];
      if (t + 1e-12 < tc && tc < t_next - 1e-12) t_next = tc;
    }
    torque_at(t, u);
    if (advance(x, z, u, t_next - t, xn, zn)) return 1;
    /* the distance stop (distance_stop.h): the output step taken again over the shortened h */
    double h = t_next - t;
    retake_t rt = {x, z, u, xn, zn, {xn[SYM_I_X_M], xn[SYM_I_Y_M]}};
    const double xy0[2] = {x[SYM_I_X_M], x[SYM_I_Y_M]};
    int done = distance_stop(&dist, SYM_HAS_STOP_DISTANCE ? SYM_STOP_DISTANCE_M : -1.0, SYM_STOP_FROM_T_S, t, &t_next,
                             &h, xy0, rt.xy, retake, &rt);
    if (done < 0) return 1;
    double seg = hypot(xn[SYM_I_X_M] - x[SYM_I_X_M], xn[SYM_I_Y_M] - x[SYM_I_Y_M]);
    s->distance_m += seg;
    if (t_next > SYM_STOP_FROM_T_S + 1e-12) s->distance_after_m += seg;
    t = t_next;
    memcpy(x, xn, sizeof x);
    memcpy(z, zn, sizeof z);
    for (int i = 0; i < SYM_NX; i++)
      if (!isfinite(x[i])) return 2;
    observe(s, &rule, t, x);
    if (done) {
      s->stopped_by_distance = 1;
      break;
    }
  }
  double psi0 = sym_x0[SYM_I_YAW_RAD];
  s->lateral_signed_m = -(x[SYM_I_X_M] - sym_x0[SYM_I_X_M]) * sin(psi0) + (x[SYM_I_Y_M] - sym_x0[SYM_I_Y_M]) * cos(psi0);
  s->yaw_deg = (x[SYM_I_YAW_RAD] - psi0) * (180.0 / 3.14159265358979323846); /* as numpy.degrees */
  s->speed_final_m_s = x[SYM_I_U_M_S];
  s->sim_time_s = t;
  if (SYM_HAS_STOP_DISTANCE && !s->stopped_by_distance) return 3;
  return 0;
}

int main(int argc, char **argv) {
  /* one optional argument, the number of repeats: --help prints the usage, anything else is refused */
  if (argc > 2 || (argc == 2 && (argv[1][0] < '0' || argv[1][0] > '9'))) {
    int help = argc == 2 && (!strcmp(argv[1], "-h") || !strcmp(argv[1], "--help"));
    if (!help) fprintf(stderr, "standalone: not a number of repeats: %s\n", argv[argc - 1]);
    fprintf(help ? stdout : stderr,
            "usage: %s [REPEATS]\n  Runs the validation scenario REPEATS times (default 1) and prints a JSON line\n"
            "  of its figures and the wall time.\n  -h, --help  print this and exit\n", argv[0]);
    return help ? 0 : 2;
  }
  int repeats = argc > 1 ? atoi(argv[1]) : 1;
  if (repeats < 1) repeats = 1;
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  F(_incref)();
  F(_work)(&sz_arg, &sz_res, &sz_iw, &sz_w);
  g_arg = malloc((size_t)(sz_arg + 1) * sizeof *g_arg);
  g_res = malloc((size_t)(sz_res + 1) * sizeof *g_res);
  g_iw = malloc((size_t)(sz_iw + 1) * sizeof *g_iw);
  g_w = malloc((size_t)(sz_w + 1) * sizeof *g_w);
  if (!g_arg || !g_res || !g_iw || !g_w) return 4;
  g_mem = F(_checkout)();
  Summary s;
  double best = INFINITY;
  for (int r = 0; r < repeats; r++) {
    struct timespec t0, t1;
    g_nsteps = g_halved = 0;
    g_error_max = 0.0;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    int flag = run(&s);
    clock_gettime(CLOCK_MONOTONIC, &t1);
    if (flag) {
      fprintf(stderr, "symtrack_standalone: the run failed (code %d)\n", flag);
      return 1;
    }
    double wall = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
    if (wall < best) best = wall;
  }
  F(_release)(g_mem);
  F(_decref)();
  printf("{\n");
  printf("  \"scenario\": \"%s\",\n", SYM_SCENARIO);
  printf("  \"integrator\": \"rosenbrock\",\n");
  printf("  \"stopped_by\": \"%s\",\n", s.stopped_by_distance ? "distance" : "duration");
  printf("  \"distance_m\": %.17g,\n", s.distance_m);
  if (SYM_HAS_STOP_DISTANCE && strlen(SYM_STOP_EVENT) > 0)
    printf("  \"distance_after_%s_m\": %.17g,\n", SYM_STOP_EVENT, s.distance_after_m);
  printf("  \"lateral_deviation_m\": %.17g,\n", fabs(s.lateral_signed_m));
  printf("  \"lateral_deviation_signed_m\": %.17g,\n", s.lateral_signed_m);
  printf("  \"yaw_final_deg\": %.17g,\n", s.yaw_deg);
  printf("  \"sinkage_sprocket_mm\": %.17g,\n", 1e3 * s.sink_sprocket_max_m);
  printf("  \"sinkage_idler_mm\": %.17g,\n", 1e3 * s.sink_idler_max_m);
  printf("  \"shear_driven_max_m\": %.17g,\n", s.shear_driven_max_m);
  if (s.has_idle)
    printf("  \"shear_idle_min_m\": %.17g,\n", s.shear_idle_min_m);
  else
    printf("  \"shear_idle_min_m\": null,\n");
  printf("  \"speed_final_m_s\": %.17g,\n", s.speed_final_m_s);
  printf("  \"nose_up\": %s,\n", s.sink_sprocket_max_m > s.sink_idler_max_m ? "true" : "false");
  printf("  \"sim_time_s\": %.17g,\n", s.sim_time_s);
  printf("  \"wall_time_s\": %.9g,\n", best);
  printf("  \"real_time_factor\": %.9g,\n", best > 0 ? s.sim_time_s / best : 0.0);
  printf("  \"fixed_step_error_max\": %.17g,\n", g_error_max);
  printf("  \"fixed_step_steps_halved\": %ld,\n", g_halved);
  printf("  \"steps\": %ld,\n", g_nsteps);
  printf("  \"repeats\": %d\n", repeats);
  printf("}\n");
  return 0;
}
