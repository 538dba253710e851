/* controller.c: the whole step of the robust MPC in C, on the compiled kernel.
 *
 * Joined after the kernel (gru_fhocp.h, memory.c ... sqp.c), the declarations of the
 * controller's constants (controllers/kernel/controller_source.py: CT_*), controller.h and
 * the law's files (law_tracking.c, the default law, or law_paper.c and law_paper_governor.c,
 * the paper's), for an exported controller (the controller FMU, fmus/controller/); the
 * numbers are loaded at run time (loader.c, PFX(load_data)), so that one binary serves every
 * design of its dimensions and law. It is the C twin of the Python component's step
 * (cosim_adapters/robust_mpc.py RobustMPCController.step), in the same order: the scalings,
 * the observer's first estimate, the law's step, then the observer's update
 * (controllers/observer.py GRUObserver.make_step: eq:observer, eq:eo-evolution), so that the
 * same measurements give the same inputs (tests/cosim_adapters/test_controller_export.py,
 * tests/fmus/test_controller_fmu.py). The observer's first estimate is the model equilibrium
 * whose output is closest to the first measured output (paper section V; the kernel's
 * PFX(equilibrium), which the Python component calls too); a first output the inputs' box
 * does not reach sets CTL_WARN_UNREACHABLE_START.
 *
 * One controller instance (ctl_state) holds everything a step reads and writes, the kernel's
 * solver instance included: instances are independent, and nothing is allocated after
 * ctl_new. Normalised units inside, the problem's units at ctl_step.
 */
/* controller_source.py parameters() names the law's tunable parameters, in its order */
typedef char ctl_parameters_agree[CT_NPARAM == LAW_N_PARAMETERS ? 1 : -1];

typedef struct ctl_state {
  gk_ws *ws;
  /* the observer (eq:observer) and its error bound (eq:eo-evolution) */
  int has_xhat;
  double xhat[NX], e_o;
  /* the law */
  law_state law;
  /* what the last step gave */
  double u_phys[NU], y_pred[NY], y_target[NY];
  int warnings;
} ctl_state;

/* ---------------------------------------------------------------- the instance */
EXPORT void PFX(ctl_reset)(ctl_state *st) {
  gk_ws *ws = st->ws;
  memset(st, 0, sizeof *st);
  st->ws = ws;
  PFX(invalidate)(ws);
  ws_default_weights(ws);
  st->e_o = CT_E_O0;
  law_reset(&st->law, ws);
  for (int j = 0; j < NU; j++) st->u_phys[j] = 0.5 * (CT_U_LO[j] + CT_U_HI[j]);
  for (int a = 0; a < NY; a++) st->y_pred[a] = st->y_target[a] = NAN;
}

/* A new controller instance (NULL when out of memory, or before PFX(load_data) gave the
 * numbers): every allocation it will ever make. */
EXPORT ctl_state *PFX(ctl_new)(void) {
  ctl_state *st = (ctl_state *)calloc(1, sizeof(ctl_state));
  if (!st) return 0;
  st->ws = PFX(ws_new)();
  if (!st->ws) {
    free(st);
    return 0;
  }
  PFX(ctl_reset)(st);
  return st;
}

EXPORT void PFX(ctl_free)(ctl_state *st) {
  if (!st) return;
  PFX(ws_free)(st->ws);
  free(st);
}

/* One control step (RobustMPCController.step) at the measured outputs y and set-points ref
 * (the problem's units): writes u_phys (the inputs to apply, in their boxes), status,
 * fallback, iterations, y_pred (the model's output at the next sample under the applied
 * plan) and y_target (the steady output the FHOCP steers the model to); advances the
 * observer. A non-finite y or ref changes nothing (the last inputs are held) and sets
 * CTL_WARN_NONFINITE_INPUT; returns 1 then, else 0. */
EXPORT int PFX(ctl_step)(ctl_state *st, const double *y_phys, const double *r_phys) {
  double y[NY], yr[NY], yh[NY], u[NU], dz[NX], dr[NX], xn[NX], d[NY];
  if (!all_finite(y_phys, NY) || !all_finite(r_phys, NY)) {
    st->warnings |= CTL_WARN_NONFINITE_INPUT;
    return 1;
  }
  for (int a = 0; a < NY; a++) {
    y[a] = (y_phys[a] - CT_Y_OFFSET[a]) / CT_Y_SCALE[a];
    yr[a] = (r_phys[a] - CT_Y_OFFSET[a]) / CT_Y_SCALE[a];
  }
  if (!st->has_xhat) {
    double u0[NU];
    if (PFX(equilibrium)(st->ws, y, st->xhat, u0) != 0)
      st->warnings |= CTL_WARN_UNREACHABLE_START;
    st->has_xhat = 1;
  }
  for (int j = 0; j < NU; j++) u[j] = (st->u_phys[j] - CT_U_OFFSET[j]) / CT_U_SCALE[j];
  law_step(&st->law, st->xhat, st->e_o, y, yr, u, &st->warnings);   /* u: held unless set */
  /* the observer (GRUObserver.make_step) */
  PFX(output)(st->xhat, yh);
  for (int a = 0; a < NY; a++) d[a] = y[a] - yh[a];
  for (int k = 0; k < NX; k++) {
    double sz = 0.0, sr = 0.0;
    for (int a = 0; a < NY; a++) {
      sz += CT_LZ[k * NY + a] * d[a];
      sr += CT_LR[k * NY + a] * d[a];
    }
    dz[k] = sz;
    dr[k] = sr;
  }
  PFX(gru_step)(st->xhat, u, dz, dr, xn);
  memcpy(st->xhat, xn, sizeof xn);
  st->e_o = CT_RHO_O * st->e_o + CT_W_BAR;
  for (int j = 0; j < NU; j++) {
    const double v = u[j] * CT_U_SCALE[j] + CT_U_OFFSET[j];
    st->u_phys[j] = v < CT_U_LO[j] ? CT_U_LO[j] : (v > CT_U_HI[j] ? CT_U_HI[j] : v);
  }
  for (int a = 0; a < NY; a++) {
    st->y_pred[a] = st->law.last.y_pred[a] * CT_Y_SCALE[a] + CT_Y_OFFSET[a];
    st->y_target[a] = st->law.last.y_target[a] * CT_Y_SCALE[a] + CT_Y_OFFSET[a];
  }
  return 0;
}

/* Tunable parameter i (the law's LAW_P_*): its value, or NaN for an unknown one. */
EXPORT double PFX(ctl_get_parameter)(const ctl_state *st, int i) {
  const double *v = law_parameter((law_state *)&st->law, i);
  return v ? *v : NAN;
}

/* Set tunable parameter i (the law's LAW_P_*) from the next step on: NULL, or why the value
 * is refused (then nothing changes). */
EXPORT const char *PFX(ctl_set_parameter)(ctl_state *st, int i, double value) {
  double *v = law_parameter(&st->law, i);
  if (!v) return "is not a parameter of the controller";
  const char *why = law_refuse(&st->law, i, value);
  if (why) return why;
  *v = value;
  return 0;
}

/* the warnings raised since the last call (CTL_WARN_* bits), cleared */
EXPORT int PFX(ctl_take_warnings)(ctl_state *st) {
  const int w = st->warnings;
  st->warnings = 0;
  return w;
}

/* what the last step gave: the inputs to apply (NU, the problem's units), the status code,
 * whether the candidate was applied, the SQP iterations, the predicted outputs (NY) and the
 * steady outputs the FHOCP steers the model to (NY; NaN before the first step) */
EXPORT void PFX(ctl_outputs)(const ctl_state *st, double *u_phys, int *status, int *fallback,
                             int *iterations, double *y_pred, double *y_target) {
  if (u_phys) memcpy(u_phys, st->u_phys, sizeof st->u_phys);
  if (status) *status = st->law.last.status;
  if (fallback) *fallback = st->law.last.fallback;
  if (iterations) *iterations = st->law.last.iterations;
  if (y_pred) memcpy(y_pred, st->y_pred, sizeof st->y_pred);
  if (y_target) memcpy(y_target, st->y_target, sizeof st->y_target);
}
