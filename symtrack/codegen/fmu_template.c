/* symtrack FMU: an FMI 2.0 Co-Simulation slave of the vehicle on the homogeneous terrain.
 *
 * Written by `symtrack export fmu` (symtrack/codegen/fmu.py) from this template; see docs/codegen.md,
 * section "The FMU". It drives the generated fixed-step Rosenbrock integrator
 * (<prefix>_rosenbrock.c, as `symtrack simulate ... --integrator rosenbrock` and the standalone program
 * do) with the numbers of fmu_model.h (value references, start values, the fixed step), and computes the
 * start state as the Python run does: the terrain cells in static equilibrium at the start pose (Newton
 * on the generated residual and Jacobian of <prefix>_fmu_init.c, from the soil law's static sinkage),
 * then the algebraic accelerations consistent with it (<prefix>_accel, then <prefix>_consistent_z).
 *
 * The FMI 2.0 headers (fmi2Functions.h, fmi2FunctionTypes.h, fmi2TypesPlatform.h) are the Modelica
 * Association's, 2-clause BSD licence, as shipped by fmpy. Links libc and libm only.
 *
 * Semantics:
 * - any communication step h > 0: a whole number n >= 1 of fixed steps (FMU_FIXED_STEP_S, relative
 *   tolerance 1e-9) advances n equal Rosenbrock steps of h / n with the inputs held, as the Python time
 *   loop advances an output interval; any other h advances floor(h / FMU_FIXED_STEP_S) fixed steps and
 *   then one shorter Rosenbrock step to the communication point (a master's last step to its stop
 *   time, a variable-step master's steps); h <= 0 is fmi2Error;
 * - every step is error-controlled as the Python run's (FMU_TOLERANCE, the scenario's
 *   run.fixed_step_tolerance): halved while its error estimate exceeds the tolerance, down to 1/256 of
 *   its length; a step still above it is kept, reported once and the fmi2DoStep returns fmi2Warning;
 * - the parameters (vehicle, soil, start pose) have variability "fixed": settable until
 *   fmi2ExitInitializationMode, which computes the start state from them;
 * - outputs are computed on demand from the state and the current inputs (the model's outputs depend on
 *   the torque commands directly); after fmi2DoStep and before new inputs are set they are the values at
 *   the end of the step, as the Python run records them;
 * - a non-finite state after a step is fmi2Error (the instance then accepts only free/reset).
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmu_model.h"

typedef enum { ST_INSTANTIATED, ST_INIT, ST_STEP, ST_TERMINATED, ST_ERROR } Phase;

typedef struct {
  fmi2CallbackFunctions cb;
  char name[128];
  int logging;
  Phase phase;
  double t;
  double u[FMU_NU], p[FMU_NP], pose[3];
  double x[FMU_NX], z[FMU_NZ], y[FMU_NY];
  int y_valid, x_valid;
  double error_max; /* the largest error estimate of a step kept, as a fraction of the tolerance */
  long n_halved;    /* the steps the error control halved */
  int warned;       /* a step above its tolerance at the smallest length was reported */
  const casadi_real **arg;
  casadi_real **res;
  casadi_int *iw;
  casadi_real *w;
  int mem[FMU_NF];
} Instance;

static void logf_(Instance *c, fmi2Status status, const char *category, const char *fmt, ...) {
  char buf[512];
  va_list ap;
  if (!c || !c->cb.logger) return;
  if (!c->logging && status == fmi2OK) return;
  va_start(ap, fmt);
  vsnprintf(buf, sizeof buf, fmt, ap);
  va_end(ap);
  c->cb.logger(c->cb.componentEnvironment, c->name, status, category, "%s", buf);
}

#define FAIL(c, ...) (logf_((c), fmi2Error, "logStatusError", __VA_ARGS__), fmi2Error)

static int call(Instance *c, int f) {
  return fmu_functions[f].eval(c->arg, c->res, c->iw, c->w, c->mem[f]);
}

static void set_start_values(Instance *c) {
  memcpy(c->u, fmu_u_start, sizeof c->u);
  memcpy(c->p, fmu_p_start, sizeof c->p);
  memcpy(c->pose, fmu_pose_start, sizeof c->pose);
  memset(c->x, 0, sizeof c->x);
  memset(c->z, 0, sizeof c->z);
  c->t = 0.0;
  c->y_valid = c->x_valid = 0;
  c->error_max = 0.0;
  c->n_halved = 0;
  c->warned = 0;
}

/* Solve the small dense system A d = b (column-major A, n <= FMU_NCELL) by LU with partial pivoting. */
static int dense_solve(int n, double *A, double *b) {
  for (int k = 0; k < n; k++) {
    int piv = k;
    for (int i = k + 1; i < n; i++)
      if (fabs(A[i + k * n]) > fabs(A[piv + k * n])) piv = i;
    if (A[piv + k * n] == 0.0) return 1;
    if (piv != k) {
      for (int j = 0; j < n; j++) {
        double s = A[k + j * n]; A[k + j * n] = A[piv + j * n]; A[piv + j * n] = s;
      }
      double s = b[k]; b[k] = b[piv]; b[piv] = s;
    }
    for (int i = k + 1; i < n; i++) {
      double l = A[i + k * n] / A[k + k * n];
      for (int j = k; j < n; j++) A[i + j * n] -= l * A[k + j * n];
      b[i] -= l * b[k];
    }
  }
  for (int k = n - 1; k >= 0; k--) {
    for (int j = k + 1; j < n; j++) b[k] -= A[k + j * n] * b[j];
    b[k] /= A[k + k * n];
  }
  return 0;
}

/* The start state: the pose, the cells in static equilibrium (symtrack.model.static.static_state: Newton
 * with abstol 1e-12 on the residual, at most 200 iterations, from the soil law's static sinkage), the
 * consistent algebraic state (accel, then consistent_z, as FixedStepper.consistent_z). */
static fmi2Status initial_state(Instance *c) {
  double zc[FMU_NCELL], F[FMU_NCELL], J[FMU_NCELL * FMU_NCELL], zg[FMU_NZ];
  c->arg[0] = c->p;
  c->res[0] = zc;
  if (call(c, F_STATIC_GUESS)) return FAIL(c, "the static sinkage guess failed");
  int ok = 0;
  for (int it = 0; it < 200; it++) {
    c->arg[0] = zc; c->arg[1] = c->pose; c->arg[2] = c->p;
    c->res[0] = F; c->res[1] = J;
    if (call(c, F_STATIC_NEWTON)) return FAIL(c, "the static residual failed");
    double norm = 0.0;
    for (int i = 0; i < FMU_NCELL; i++) norm = fmax(norm, fabs(F[i]));
    if (!(norm == norm)) break;
    if (norm <= 1e-12) { ok = 1; break; }
    if (dense_solve(FMU_NCELL, J, F)) break;
    double step = 0.0;
    for (int i = 0; i < FMU_NCELL; i++) { zc[i] -= F[i]; step = fmax(step, fabs(F[i])); }
    if (step <= 1e-12) { ok = 1; break; }
  }
  if (!ok) return FAIL(c, "no static equilibrium of the terrain cells at the start pose (Newton did not converge "
                          "in 200 iterations): check the vehicle and soil parameters");
  memset(c->x, 0, sizeof c->x);
  for (int i = 0; i < 3; i++) c->x[fmu_pose_index[i]] = c->pose[i];
  for (int i = 0; i < FMU_NCELL; i++) c->x[fmu_cell_index[i]] = zc[i];
  c->arg[0] = c->x; c->arg[1] = c->u; c->arg[2] = c->p;
  c->res[0] = zg;
  if (call(c, F_ACCEL)) return FAIL(c, "the start accelerations failed");
  c->arg[0] = c->x; c->arg[1] = zg; c->arg[2] = c->u; c->arg[3] = c->p;
  c->res[0] = c->z;
  if (call(c, F_CONSISTENT_Z)) return FAIL(c, "the consistent algebraic state failed");
  c->x_valid = 1;
  c->y_valid = 0;
  return fmi2OK;
}

static fmi2Status ensure_state(Instance *c) {
  if (c->x_valid) return fmi2OK;
  return initial_state(c);
}

static fmi2Status outputs(Instance *c) {
  if (c->y_valid) return fmi2OK;
  if (ensure_state(c) != fmi2OK) return fmi2Error;
  c->arg[0] = c->x; c->arg[1] = c->u; c->arg[2] = c->p;
  c->res[0] = c->y;
  if (call(c, F_OUTPUTS)) return FAIL(c, "the outputs failed");
  c->y_valid = 1;
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
    for (int k = 0; k < FMU_NLOGCAT; k++)
      if (categories[i] && strcmp(categories[i], fmu_log_categories[k]) == 0) known = 1;
    if (!known) return FAIL(c, "fmi2SetDebugLogging: unknown log category '%s'", categories[i] ? categories[i] : "");
  }
  c->logging = loggingOn ? 1 : 0;
  return fmi2OK;
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
  if (!fmuGUID || strcmp(fmuGUID, FMU_GUID) != 0) {
    logf_(&tmp, fmi2Error, "logStatusError", "fmi2Instantiate: GUID '%s' does not match this FMU's '%s'",
          fmuGUID ? fmuGUID : "", FMU_GUID);
    return NULL;
  }
  casadi_int sz_arg = 0, sz_res = 0, sz_iw = 0, sz_w = 0;
  for (int f = 0; f < FMU_NF; f++) {
    casadi_int a, r, i, w;
    fmu_functions[f].work(&a, &r, &i, &w);
    if (a > sz_arg) sz_arg = a;
    if (r > sz_res) sz_res = r;
    if (i > sz_iw) sz_iw = i;
    if (w > sz_w) sz_w = w;
  }
  Instance *c = (Instance *)functions->allocateMemory(1, sizeof(Instance));
  if (!c) return NULL;
  *c = tmp;
  c->arg = (const casadi_real **)functions->allocateMemory((size_t)sz_arg + 1, sizeof(casadi_real *));
  c->res = (casadi_real **)functions->allocateMemory((size_t)sz_res + 1, sizeof(casadi_real *));
  c->iw = (casadi_int *)functions->allocateMemory((size_t)sz_iw + 1, sizeof(casadi_int));
  c->w = (casadi_real *)functions->allocateMemory((size_t)sz_w + 1, sizeof(casadi_real));
  if (!c->arg || !c->res || !c->iw || !c->w) {
    if (c->arg) functions->freeMemory((void *)c->arg);
    if (c->res) functions->freeMemory(c->res);
    if (c->iw) functions->freeMemory(c->iw);
    if (c->w) functions->freeMemory(c->w);
    functions->freeMemory(c);
    return NULL;
  }
  for (int f = 0; f < FMU_NF; f++) {
    fmu_functions[f].incref();
    c->mem[f] = fmu_functions[f].checkout();
  }
  set_start_values(c);
  c->phase = ST_INSTANTIATED;
  return c;
}

void fmi2FreeInstance(fmi2Component comp) {
  Instance *c = (Instance *)comp;
  if (!c) return;
  for (int f = 0; f < FMU_NF; f++) {
    fmu_functions[f].release(c->mem[f]);
    fmu_functions[f].decref();
  }
  fmi2CallbackFreeMemory fr = c->cb.freeMemory;
  fr((void *)c->arg);
  fr(c->res);
  fr(c->iw);
  fr(c->w);
  fr(c);
}

fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
  Instance *c = (Instance *)comp;
  (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
  if (!c) return fmi2Error;
  if (c->phase != ST_INSTANTIATED) return FAIL(c, "fmi2SetupExperiment: only after fmi2Instantiate or fmi2Reset");
  c->t = startTime;
  return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component comp) {
  Instance *c = (Instance *)comp;
  if (!c) return fmi2Error;
  if (c->phase != ST_INSTANTIATED) return FAIL(c, "fmi2EnterInitializationMode: only once, after instantiation");
  c->phase = ST_INIT;
  c->x_valid = c->y_valid = 0;
  return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component comp) {
  Instance *c = (Instance *)comp;
  if (!c) return fmi2Error;
  if (c->phase != ST_INIT) return FAIL(c, "fmi2ExitInitializationMode: not in initialization mode");
  c->x_valid = 0;
  if (initial_state(c) != fmi2OK) {
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
  c->phase = ST_TERMINATED;
  return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component comp) {
  Instance *c = (Instance *)comp;
  if (!c) return fmi2Error;
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
    if (r < FMU_VR_P) {
      value[i] = c->u[r - FMU_VR_U];
    } else if (r < FMU_VR_POSE) {
      value[i] = c->p[r - FMU_VR_P];
    } else if (r < FMU_VR_X) {
      value[i] = c->pose[r - FMU_VR_POSE];
    } else if (r < FMU_VR_Y) {
      if (c->phase == ST_INSTANTIATED) return FAIL(c, "fmi2GetReal: states only after fmi2EnterInitializationMode");
      if (ensure_state(c) != fmi2OK) return fmi2Error;
      value[i] = c->x[r - FMU_VR_X];
    } else if (r < FMU_VR_END) {
      if (c->phase == ST_INSTANTIATED) return FAIL(c, "fmi2GetReal: outputs only after fmi2EnterInitializationMode");
      if (outputs(c) != fmi2OK) return fmi2Error;
      value[i] = c->y[fmu_y_index[r - FMU_VR_Y]];
    } else {
      return FAIL(c, "fmi2GetReal: unknown value reference %u (this FMU has 0 ... %d)", (unsigned)r, FMU_VR_END - 1);
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
    if (r < FMU_VR_P) {
      c->u[r - FMU_VR_U] = value[i];
      c->y_valid = 0;
    } else if (r < FMU_VR_X) {
      if (c->phase == ST_STEP)
        return FAIL(c, "fmi2SetReal: the parameter with value reference %u is fixed after initialization", (unsigned)r);
      if (r < FMU_VR_POSE) c->p[r - FMU_VR_P] = value[i];
      else c->pose[r - FMU_VR_POSE] = value[i];
      c->x_valid = c->y_valid = 0;
    } else if (r < FMU_VR_END) {
      return FAIL(c, "fmi2SetReal: value reference %u is an output (states and outputs cannot be set)", (unsigned)r);
    } else {
      return FAIL(c, "fmi2SetReal: unknown value reference %u (this FMU has 0 ... %d)", (unsigned)r, FMU_VR_END - 1);
    }
  }
  return fmi2OK;
}

/* This FMU has no Integer, Boolean or String variables: an empty call is fmi2OK, any reference an error. */
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
NO_VARIABLES(fmi2GetString, fmi2String, )
NO_VARIABLES(fmi2SetInteger, fmi2Integer, const)
NO_VARIABLES(fmi2SetBoolean, fmi2Boolean, const)
NO_VARIABLES(fmi2SetString, fmi2String, const)

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
  double ratio = h / FMU_FIXED_STEP_S;
  long n = (long)floor(ratio + 0.5);
  double hs = h / (double)n, last = 0.0; /* n steps of hs, then one of last (0: none) */
  if (n < 1 || fabs(ratio - (double)n) > 1e-9 * ratio) {
    /* not a whole multiple: whole fixed steps, then the shorter rest */
    n = (long)floor(ratio);
    hs = FMU_FIXED_STEP_S;
    last = h - (double)n * FMU_FIXED_STEP_S;
  }
  /* the steps (n of hs, then the shorter one, last, when > 0), each through the generated controlled step
     as the Python run's (symtrack/integrators/fixed_step.py: halved while its estimate exceeds the
     tolerance, down to 1/256; a step still above it is kept and reported once, fmi2Warning) */
  static const double ctl[2] = {FMU_TOLERANCE, FMU_TOLERANCE_ON ? 1.0 : INFINITY};
  fmi2Status status = fmi2OK;
  double xn[FMU_NX], zn[FMU_NZ], r, nh;
  for (long k = 0; k <= n; k++) {
    double hk = k < n ? hs : last, tk = c->t + (double)k * hs;
    if (!(hk > 0.0)) break;
    c->arg[0] = c->x; c->arg[1] = c->z; c->arg[2] = c->u; c->arg[3] = c->p; c->arg[4] = &hk; c->arg[5] = ctl;
    c->res[0] = xn; c->res[1] = zn; c->res[2] = &r; c->res[3] = &nh;
    if (call(c, F_STEP)) {
      c->phase = ST_ERROR;
      return FAIL(c, "fmi2DoStep: the Rosenbrock step failed at t = %.17g s", tk);
    }
    for (int i = 0; i < FMU_NX; i++)
      if (!isfinite(xn[i]) || !isfinite(r)) {
        c->phase = ST_ERROR;
        return FAIL(c, "fmi2DoStep: non-finite state %s at t = %.17g s even in steps of 1/256 of the fixed step "
                    "(the vehicle left the model's domain)", fmu_state_names[i], tk + hk);
      }
    if (r > c->error_max) c->error_max = r;
    c->n_halved += (long)nh;
    if (FMU_TOLERANCE_ON && !(r <= 1.0)) {
      status = fmi2Warning;
      if (!c->warned) {
        logf_(c, fmi2Warning, "logStatusWarning", "fmi2DoStep: the error estimate of the step at t = %.17g s stays "
              "%.3g x its tolerance %g at 1/256 of the fixed step; the step was kept (compare with a variable-step "
              "integrator)", tk, r, FMU_TOLERANCE);
        c->warned = 1;
      }
    }
    memcpy(c->x, xn, sizeof xn);
    memcpy(c->z, zn, sizeof zn);
  }
  c->t = currentCommunicationPoint + h;
  c->y_valid = 0;
  return status;
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
