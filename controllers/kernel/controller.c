/* controller.c: the whole step of the robust MPC in C, on the compiled kernel.
 *
 * Joined after the kernel (gru_fhocp.h, memory.c ... sqp.c), the declarations of the
 * controller's constants (controllers/kernel/controller_source.py: CT_*), controller.h and
 * the law's C files (of controllers/laws/<name>/: tracking/law.c, the default law, or
 * paper/law.c and paper/governor.c, the paper's), for an exported controller (the controller
 * FMU, fmus/controller/); the numbers are loaded at run time (loader.c, PFX(load_data)), so
 * that one binary serves every design of its dimensions and law. It is the C twin of the
 * Python controller's step (controllers/mpc.py RobustMPC.step), in the same order: the scalings,
 * the observer's first estimate, the law's step, then the observer's update
 * (controllers/observer.py GRUObserver.make_step: eq:observer, eq:eo-evolution), so that the
 * same measurements give the same inputs (tests/cosim/adapters/test_controller_export.py,
 * tests/fmus/test_controller_fmu.py). The observer's first estimate is the model equilibrium
 * whose output is closest to the first measured output (paper section V; the kernel's
 * PFX(equilibrium), which the Python component calls too); a first output the inputs' box
 * does not reach sets CTL_WARN_UNREACHABLE_START.
 *
 * One controller instance (ctl_state) holds everything a step reads and writes, the kernel's
 * solver instance included: instances are independent, and nothing is allocated after
 * ctl_new. Normalised units inside, the problem's units at ctl_step.
 *
 * Measured disturbances (CT_NQD of them) and dead time (CT_U_DELAYS samples on the inputs,
 * CT_DEAD the shortest; each disturbance its CT_LAGS): as controllers/held_inputs.py
 * HeldInputs (measure, hold, ahead, model_input, applied, prefix). The disturbances the FHOCP
 * holds are a shift of the biases (controllers/disturbances.py BiasShift: W_d d, CT_WD), the
 * kernel's per-thread shift (rollout.c gk_db), given at every step before the kernel's calls;
 * x_hat is predicted over the shortest dead time with the inputs applied before the FHOCP
 * starts; an input whose dead time is longer has its first FHOCP inputs fixed to those it
 * applied (ctl_prefix); the observer advances with the model input as the model sees it
 * (u_{k-K_j}, d_{k-L}).
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
#if CT_NQD
  /* the measured disturbances (normalised, oldest first), the ones in the biases now and
   * their shift W_d d, the ones the FHOCP held last */
  int has_d, has_shift, has_d_law;
  double d_past[(CT_LAG_MAX + 1) * CT_NQD], d_shift[CT_NQD], db[3 * NX], d_law[CT_NQD];
#endif
#if CT_U_DEPTH
  /* the last CT_U_DEPTH inputs applied (normalised, oldest first) */
  int has_u_past;
  double u_past[CT_U_DEPTH * NU];
#endif
  /* the FHOCP's inputs already applied (controller.h) */
  ctl_prefix prefix;
  /* the operator's settings and this step's terms (operator.c); what the law computed */
  ctl_operator op;
  double computed[NU];
} ctl_state;

#if CT_NQD
static int same_d(const double *a, const double *b) {
  for (int j = 0; j < CT_NQD; j++)
    if (!(a[j] == b[j])) return 0;
  return 1;
}

/* Hold the disturbances d (normalised) in the biases (HeldInputs.hold: BiasShift.set,
 * FHOCP.shift_biases): the shift W_d d, summed from j = 0 on as numpy does it there, the
 * cached rollout forgotten when it changed, the thread's shift given every time; law: the
 * value the FHOCP holds, whose moves move the law's steady state. */
static void hold(ctl_state *st, const double *d, int law) {
  if (!st->has_shift || !same_d(d, st->d_shift)) {
    for (int k = 0; k < 3 * NX; k++) {
      double s = 0.0;
      for (int j = 0; j < CT_NQD; j++) s = s + CT_WD[k * CT_NQD + j] * d[j];
      st->db[k] = s;
    }
    memcpy(st->d_shift, d, sizeof st->d_shift);
    st->has_shift = 1;
    PFX(invalidate)(st->ws);
  }
  PFX(set_bias_shift)(st->db);
  if (!law) return;
  if (st->has_d_law && !same_d(d, st->d_law)) law_disturbance_moved(&st->law);
  memcpy(st->d_law, d, sizeof st->d_law);
  st->has_d_law = 1;
}

/* disturbance j as the model sees it i samples on: d_{k+i-L_j} while known, else d_k */
__attribute__((unused)) static double seen(const ctl_state *st, int i, int j) {
  const double *newest = st->d_past + CT_LAG_MAX * CT_NQD;
  return i < CT_LAGS[j] ? newest[(i - CT_LAGS[j]) * CT_NQD + j] : newest[j];
}
#endif

#if CT_U_DEPTH
/* the FHOCP's fixed inputs from the inputs applied (HeldInputs.ahead: InputPrefix.set) */
static void set_prefix(ctl_state *st) {
#if CT_U_LAG_MAX
  for (int i = 0; i < CT_U_LAG_MAX; i++)
    for (int j = 0; j < NU; j++) {
      int row = CT_U_DEPTH - CT_U_LAGS[j] + i;
      if (row > CT_U_DEPTH - 1) row = CT_U_DEPTH - 1;
      st->prefix.known[i * NU + j] = i < CT_U_LAGS[j] ? st->u_past[row * NU + j] : 0.0;
    }
#else
  (void)st;
#endif
}
#endif

#if CT_DEAD
/* x_hat predicted over the inputs' shortest dead time (HeldInputs.ahead) into x: input j at
 * step i as applied CT_U_DELAYS[j] - i samples ago */
static void ahead(ctl_state *st, double *x) {
  double zero[NX] = {0.0}, xn[NX], v[NU];
  memcpy(x, st->xhat, NX * sizeof(double));
  for (int i = 0; i < CT_DEAD; i++) {
#if CT_NQD
    double d[CT_NQD];
    for (int j = 0; j < CT_NQD; j++) d[j] = seen(st, i, j);
    hold(st, d, 0);
#endif
    for (int j = 0; j < NU; j++) v[j] = st->u_past[(CT_U_DEPTH - CT_U_DELAYS[j] + i) * NU + j];
    PFX(gru_step)(x, v, zero, zero, xn);
    memcpy(x, xn, sizeof xn);
  }
#if CT_NQD
  hold(st, st->d_past + CT_LAG_MAX * CT_NQD, 0);   /* the FHOCP's: d_k */
#endif
}
#endif

/* ---------------------------------------------------------------- the instance */
EXPORT void PFX(ctl_reset)(ctl_state *st) {
  gk_ws *ws = st->ws;
  memset(st, 0, sizeof *st);
  st->ws = ws;
  PFX(invalidate)(ws);
  ws_default_weights(ws);
  st->e_o = CT_E_O0;
  law_reset(&st->law, ws);
  op_reset(&st->op);
  for (int j = 0; j < NU; j++)
    st->u_phys[j] = st->computed[j] = 0.5 * (CT_U_LO[j] + CT_U_HI[j]);
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
#if HAS_SHIFT
  {   /* the thread's bias shift exists from now on: a step on this thread never allocates */
    const double zero[3 * NX] = {0.0};
    PFX(set_bias_shift)(zero);
  }
#endif
  return st;
}

EXPORT void PFX(ctl_free)(ctl_state *st) {
  if (!st) return;
  PFX(ws_free)(st->ws);
  free(st);
}

/* One control step (RobustMPCController.step) at the measured outputs y, set-points ref and
 * measured disturbances d (the problem's units; d unused, and may be NULL, without
 * disturbances): writes u_phys (the inputs to apply, in their boxes), status,
 * fallback, iterations, y_pred (the model's output at the next sample under the applied
 * plan) and y_target (the steady output the FHOCP steers the model to); advances the
 * observer. A non-finite y, ref or d changes nothing (the last inputs are held) and sets
 * CTL_WARN_NONFINITE_INPUT; returns 1 then, else 0. */
/* Operating.before: the limits ramped (the law's room), the set-points r (problem units, in
 * place) inside the active output limits, the FHOCP's terms; the plant at rest first (the
 * equilibrium input of the first output estimate) when no input was applied yet */
static void operate_before(ctl_state *st, double *r) {
  ctl_operator *o = &st->op;
  if (!op_engaged(o)) {
    o->ops.active = 0;
    return;
  }
  if (!o->has_last && !o->has_start) {
    double yh[NY], xs0[NX], u0[NU];
    PFX(output)(st->xhat, yh);
    PFX(equilibrium)(st->ws, yh, xs0, u0);
    for (int j = 0; j < NU; j++) {
      const double v = gk_clip1(u0[j]) * CT_U_SCALE[j] + CT_U_OFFSET[j];
      o->start[j] = fmin(fmax(v, CT_U_LO[j]), CT_U_HI[j]);
    }
    o->has_start = 1;
  }
  double slack[NL];
  const int have = law_room(&st->law, slack);
  op_ramp(o, have || o->mode != 1.0 ? slack : 0);
  op_setpoint(o, r);
  op_terms(o);
}

EXPORT int PFX(ctl_step)(ctl_state *st, const double *y_phys, const double *r_phys,
                         const double *d_phys) {
  double y[NY], yr[NY], yh[NY], u[NU], dz[NX], dr[NX], xn[NX], d[NY], r_op[NY];
  const double *xstart = st->xhat;
  (void)d_phys;
  if (!all_finite(y_phys, NY) || !all_finite(r_phys, NY)
#if CT_NQD
      || !d_phys || !all_finite(d_phys, CT_NQD)
#endif
  ) {
    st->warnings |= CTL_WARN_NONFINITE_INPUT;
    return 1;
  }
  for (int a = 0; a < NY; a++) {
    y[a] = (y_phys[a] - CT_Y_OFFSET[a]) / CT_Y_SCALE[a];
    yr[a] = (r_phys[a] - CT_Y_OFFSET[a]) / CT_Y_SCALE[a];
  }
#if CT_NQD
  /* the disturbances, each held inside its box (HeldInputs.measure) */
  double dk[CT_NQD];
  for (int j = 0; j < CT_NQD; j++) {
    const double v = (d_phys[j] - CT_D_OFFSET[j]) / CT_D_SCALE[j];
    dk[j] = v < -1.0 ? -1.0 : (v > 1.0 ? 1.0 : v);
  }
  if (!st->has_d)
    for (int r = 0; r <= CT_LAG_MAX; r++) memcpy(st->d_past + r * CT_NQD, dk, sizeof dk);
  else {
    memmove(st->d_past, st->d_past + CT_NQD, CT_LAG_MAX * CT_NQD * sizeof(double));
    memcpy(st->d_past + CT_LAG_MAX * CT_NQD, dk, sizeof dk);
  }
  st->has_d = 1;
  hold(st, dk, 1);
#endif
  if (!st->has_xhat) {
    double u0[NU];
    if (PFX(equilibrium)(st->ws, y, st->xhat, u0) != 0)
      st->warnings |= CTL_WARN_UNREACHABLE_START;
    st->has_xhat = 1;
  }
  const int engaged = op_engaged(&st->op);
  if (engaged || st->op.ops.active) {   /* the operator's settings (operate_before) */
    memcpy(r_op, r_phys, sizeof r_op);
    operate_before(st, r_op);
    for (int a = 0; a < NY; a++) yr[a] = (r_op[a] - CT_Y_OFFSET[a]) / CT_Y_SCALE[a];
  }
#if CT_U_DEPTH
  if (!st->has_u_past) {   /* at rest before the run: the input that holds y_hat */
    double xs0[NX], u0[NU];
    PFX(output)(st->xhat, yh);
    PFX(equilibrium)(st->ws, yh, xs0, u0);
    for (int i = 0; i < CT_U_DEPTH; i++)
      for (int j = 0; j < NU; j++) st->u_past[i * NU + j] = gk_clip1(u0[j]);
    st->has_u_past = 1;
  }
  set_prefix(st);
#endif
#if CT_DEAD
  double xa[NX];
  ahead(st, xa);
  xstart = xa;
#endif
  for (int j = 0; j < NU; j++) u[j] = (st->u_phys[j] - CT_U_OFFSET[j]) / CT_U_SCALE[j];
  /* u: held unless set */
  law_step(&st->law, st->xhat, xstart, &st->prefix, &st->op.ops, st->e_o, y, yr, u,
           &st->warnings);
  /* what the law computed, and what the plant gets (Operating.after) */
  for (int j = 0; j < NU; j++) {
    const double v = u[j] * CT_U_SCALE[j] + CT_U_OFFSET[j];
    st->computed[j] = v < CT_U_LO[j] ? CT_U_LO[j] : (v > CT_U_HI[j] ? CT_U_HI[j] : v);
  }
  if (engaged) {
    double applied[NU];
    op_applied(&st->op, st->computed, applied);
    for (int j = 0; j < NU; j++) u[j] = (applied[j] - CT_U_OFFSET[j]) / CT_U_SCALE[j];
    law_applied(&st->law, u);
  } else {
    memcpy(st->op.last, st->computed, sizeof st->op.last);
    st->op.has_last = 1;
  }
#if CT_NQD
  /* a disturbance that moved the steady states beyond the plan: start again */
  if (st->law.last.fallback && !st->law.cand_feasible) law_restart(&st->law);
#endif
  /* the model input as the model sees it (HeldInputs.model_input) */
  double um[NU];
  memcpy(um, u, sizeof um);
#if CT_U_DEPTH
  for (int j = 0; j < NU; j++)
    if (CT_U_DELAYS[j] > 0) um[j] = st->u_past[(CT_U_DEPTH - CT_U_DELAYS[j]) * NU + j];
#endif
#if CT_NQD
  int lagged = 0;
  for (int j = 0; j < CT_NQD; j++) lagged |= CT_LAGS[j] != 0;
  if (lagged) {
    double dm[CT_NQD];
    for (int j = 0; j < CT_NQD; j++)
      dm[j] = st->d_past[(CT_LAG_MAX - CT_LAGS[j]) * CT_NQD + j];
    hold(st, dm, 0);
  }
#endif
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
  PFX(gru_step)(st->xhat, um, dz, dr, xn);
  memcpy(st->xhat, xn, sizeof xn);
  st->e_o = CT_RHO_O * st->e_o + CT_W_BAR;
#if CT_U_DEPTH
  memmove(st->u_past, st->u_past + NU, (CT_U_DEPTH - 1) * NU * sizeof(double));
  memcpy(st->u_past + (CT_U_DEPTH - 1) * NU, u, NU * sizeof(double));
#endif
  memcpy(st->u_phys, engaged ? st->op.last : st->computed, sizeof st->u_phys);
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

/* Operator setting i (operator.c: op.mode, op.service.*, op.manual.*, op.min.*, op.max.*)
 * from the next step on: NULL, or why the value is refused (then nothing changes). */
EXPORT const char *PFX(ctl_set_operator)(ctl_state *st, int i, double value) {
  const char *why = op_refuse(&st->op, i, value);
  if (why) return why;
  op_set(&st->op, i, value);
  return 0;
}

/* Operator setting i's value now (an operator limit: its target); NaN for an unknown one */
EXPORT double PFX(ctl_get_operator)(const ctl_state *st, int i) {
  return op_value(&st->op, i);
}

/* what the law computed at the last step (NU, the problem's units; in manual: in shadow) */
EXPORT void PFX(ctl_computed)(const ctl_state *st, double *u_phys) {
  memcpy(u_phys, st->computed, sizeof st->computed);
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
