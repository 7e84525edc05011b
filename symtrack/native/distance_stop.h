/* The distance stop of the compiled runs (run.stop_after_distance_m, counted from the time of
 * run.stop_distance_event): the terrain engine's eng_run (grid_engine.c: the engine library, the grid
 * standalone program, the engine FMU) and the homogeneous standalone program
 * (symtrack/codegen/standalone_main.c) include this one copy. The Python time loop
 * (symtrack/simulation/loop.py) applies the same rule to the plants it steps itself (CVODES, IDAS, the
 * Rosenbrock steppers), which run without a C compiler.
 *
 * A step from t to *t_next of length *h that moved the centre of gravity from xy0 to xy1, counting when
 * it ends after from_t: when the distance so far *dist plus this step's reaches target, the step is
 * shortened by three secant refinements of its length (*h *= (target - *dist) / d_step, the step taken
 * again over *h by retake(ctx, *h), which leaves its end position in xy1), *t_next becomes t + *h;
 * *dist grows by the step's distance. Returns 1 when the stop was reached in this step, 0 when not, or retake's nonzero
 * result (an error) as -1. target < 0: no stop. */
#ifndef SYMTRACK_DISTANCE_STOP_H
#define SYMTRACK_DISTANCE_STOP_H
#include <math.h>

typedef int (*distance_retake_fn)(void *ctx, double h);

static int distance_stop(double *dist, double target, double from_t, double t, double *t_next, double *h,
                         const double *xy0, const double *xy1, distance_retake_fn retake, void *ctx) {
  if (!(target >= 0.0) || !(*t_next > from_t + 1e-12)) return 0;
  double d_step = hypot(xy1[0] - xy0[0], xy1[1] - xy0[1]);
  int done = 0;
  if (*dist + d_step >= target) {
    for (int it = 0; it < 3; ++it) {
      if (d_step <= 0) break;
      *h *= (target - *dist) / d_step;
      if (retake(ctx, *h)) return -1;
      d_step = hypot(xy1[0] - xy0[0], xy1[1] - xy0[1]);
    }
    *t_next = t + *h;
    done = 1;
  }
  *dist += d_step;
  return done;
}

#endif
