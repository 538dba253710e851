/* controller.c: the whole step of the robust MPC's tracking law in C, on the compiled kernel.
 *
 * Joined after the kernel (gru_fhocp.h, memory.c ... sqp.c) and the declarations of the
 * controller's constants (controllers/kernel/controller_source.py: CT_*), for an exported
 * controller (the controller FMU, fmus/controller/); the numbers of both are loaded at run
 * time (loader.c, PFX(load_data)), so that one binary serves every design of its
 * dimensions. It is the C twin of the Python
 * controller step, line for line and in the same order of kernel calls:
 *
 *   ctl_step        cosim_adapters/robust_mpc.py RobustMPCController.step: the scalings, the
 *                   observer's first estimate, the law (cosim_adapters/tracking.py
 *                   TrackingLaw.step: its first steady state, d_hat, the target), then the
 *                   observer's update (controllers/observer.py GRUObserver.make_step:
 *                   eq:observer, eq:eo-evolution)
 *   make_step       controllers/ocp/tracking_mpc.py TrackingMPC.make_step (the candidate, the
 *                   fallback, the next guess)
 *   solve           controllers/ocp/reference_tracking.py ArtificialSteadyState.request, and
 *                   controllers/ocp/fhocp.py FHOCP.solve_request: the i = 0 row,
 *                   write_request (ArtificialSteadyState.write), the kernel SQP,
 *                   check_answer (ArtificialSteadyState._check_compiled and
 *                   fhocp_result.judge, the warm start)
 *   check           ArtificialSteadyState.evaluate (the candidate's answer check)
 *
 * so that the same measurements give the same inputs, to the bit
 * (tests/cosim_adapters/test_controller_export.py, tests/fmus/test_controller_fmu.py).
 * The tightened bounds (eq:optimization-constraint) are h - a_i e_o - b_i - w_L - L b_o,
 * evaluated in numpy's order. The observer's first estimate is the model equilibrium whose
 * output is closest to the first measured output (paper section V; the kernel's
 * PFX(equilibrium), which the Python law calls too); a first output the inputs' box does not
 * reach sets CTL_WARN_UNREACHABLE_START.
 *
 * One controller instance (ctl_state) holds everything a step reads and writes, the kernel's
 * solver instance included: instances are independent, and nothing is allocated after
 * ctl_new. Normalised units inside, the problem's units at ctl_step.
 */
#if !HAS_ASS
#error "the exported controller runs the tracking law (a kernel with HAS_ASS)"
#endif
#ifndef CT_NPARAM
#error "the controller's constants (controller_source.py) must precede controller.c"
#endif

/* the step's status codes: controllers/ocp/solve_status.py status_code */
enum ctl_status {
  CTL_OPTIMAL = 0, CTL_INFEASIBLE_X0 = 1, CTL_INFEASIBLE = 2, CTL_LIMIT = 3,
  CTL_RESIDUAL_CHECK_FAILED = 4, CTL_OTHER = 5
};
/* the tunable parameters (ctl_set_parameter), in this order: the disturbance filter's gain
 * (option offset_filter, in (0, 1]), the diagonal of R (option R: NU entries, R kept positive
 * definite), the input-rate weights S (option du_weight: NU entries >= 0, with HAS_DU) and
 * the offset weights T (option offset_weight: NY entries > 0). The weights are the kernel
 * instance's (gk_mem.rw, dw, tw); Q and s are not tunable: s is the certificate's
 * (eq:definition_s, from Q), and the tracking law's hypotheses (H3) hold for any R > 0,
 * S >= 0, T > 0. */
enum {
  CTL_P_OFFSET_FILTER = 0, CTL_P_R = 1, CTL_P_DU = CTL_P_R + NU,
  CTL_P_T = CTL_P_DU + HAS_DU * NU, CTL_N_PARAMETERS = CTL_P_T + NY
};
/* controller_source.py PARAMETERS names them, in this order */
typedef char ctl_parameters_agree[CT_NPARAM == CTL_N_PARAMETERS ? 1 : -1];
/* warnings a step may raise (ctl_state.warnings, a bit mask cleared by ctl_take_warnings) */
enum { CTL_WARN_NONFINITE_INPUT = 1, CTL_WARN_UNREACHABLE_START = 2 };

/* one solve or one answer check (controllers/ocp/fhocp_result.py FHOCPResult) */
typedef struct ctl_result {
  double u[NH * NU], us[NU], xs[NX], x[(NH + 1) * NX];
  double cost, cv, tv, defect;
  int success, feasible, status, iterations;
} ctl_result;

typedef struct ctl_state {
  gk_ws *ws;
  /* the observer (eq:observer) and its error bound (eq:eo-evolution) */
  int has_xhat;
  double xhat[NX], e_o;
  /* the output-disturbance estimate d_hat (DisturbanceFilter) */
  double dhat[NY];
  /* the disturbance filter's gain (CTL_P_OFFSET_FILTER; the weights are ws's) */
  double beta;
  /* the tracking MPC: artificial steady state, plan, last input, next initial guess */
  int started, has_plan, has_uprev, has_guess;
  double us[NU], xs[NX], plan[NH * NU], uprev[NU], g_u[NH * NU], g_us[NU], g_xs[NX];
  /* the FHOCP's warm start (its last multipliers) */
  int has_warm;
  double warm_lx[NW], warm_lg[NG];
  /* the solver's buffers */
  double p[NP], lbx[NW], ubx[NW], lbg[NG], ubg[NG], w[NW], lx[NW], lg[NG], g[NG], f;
  double bnd[NH * NL], ys_rhs[NL], shift[NL], cand[NH * NU];
  ctl_result res, chk;
  gk_sqp_opts opts;
  gk_sqp_info info;
  /* what the last step gave */
  double u_phys[NU], y_pred[NY];
  int status, fallback, iterations, warnings;
} ctl_state;

static int all_finite(const double *a, int n) {
  for (int k = 0; k < n; k++)
    if (!isfinite(a[k])) return 0;
  return 1;
}

static void tighten(ctl_state *st, double e_o) {
  for (int i = 0; i < NH; i++)
    for (int j = 0; j < NL; j++) {
      double v = CT_H[j] - CT_A[i * NL + j] * e_o;
      v = v - CT_B[i * NL + j];
      v = v - CT_WL[j];
      v = v - CT_LBO[j];
      st->bnd[i * NL + j] = CT_CERTIFIED ? v : v - st->shift[j];
    }
  for (int j = 0; j < NL; j++)
    st->ys_rhs[j] = CT_CERTIFIED ? CT_YS_BASE[j] : CT_YS_BASE[j] - st->shift[j];
}

/* the answer check of (w, p) into r (ArtificialSteadyState._check_compiled): the kernel's plain
 * rollout, x_s(u_s) from p's x_s0 with its fixed point verified, cost and residuals (output
 * rows, input box, terminal set, Y_s) */
static void assess(ctl_state *st, const double *w, const double *p, ctl_result *r) {
  gk_assessment out;
  PFX(assess_w)(st->ws, w, p, st->bnd, CT_ALPHA_C, r->u, r->x, &out, r->xs);
  for (int j = 0; j < NU; j++) r->us[j] = gk_clip1(w[NUU + j]);
  r->cost = out.cost;
  r->defect = out.defect;
  if (!(out.steady_residual <= CT_XS_CHECK_TOL)) {
    for (int k = 0; k < NX; k++) r->xs[k] = NAN;
    r->cv = r->tv = INFINITY;
    return;
  }
  r->cv = fmax(fmax(0.0, out.violation_first), fmax(out.violation_rows, out.u_max - 1.0));
  r->tv = fmax(0.0, out.terminal_distance - CT_ALPHA_C);
  for (int j = 0; j < NL; j++) {
    double s = 0.0;
    for (int k = 0; k < NX; k++) s += LUO[j * NX + k] * r->xs[k];
    r->cv = fmax(r->cv, s - st->ys_rhs[j]);
  }
}

/* p = (x_hat, x_s0, r[, u_prev]) */
static void parameters(double *p, const double *xhat, const double *xs0, const double *rt,
                       const double *up) {
  memcpy(p, xhat, NX * sizeof(double));
  memcpy(p + NX, xs0, NX * sizeof(double));
  memcpy(p + 2 * NX, rt, NY * sizeof(double));
#if HAS_DU
  memcpy(p + 2 * NX + NY, up, NU * sizeof(double));
#else
  (void)up;
#endif
}

/* ArtificialSteadyState.evaluate: (u, u_s) evaluated apart from the solver into r, by the answer check
 * of the w they make (u in the control horizon's form) */
static void check(ctl_state *st, const double *xhat, const double *u_in, const double *us_in,
                  const double *rt, const double *xs0, const double *up, int status,
                  ctl_result *r) {
  double w[NW] = {0.0}, p[NP];
  for (int c = 0; c < NUU; c++) w[c] = gk_clip1(u_in[c]);
  for (int j = 0; j < NU; j++) w[NUU + j] = gk_clip1(us_in[j]);
  parameters(p, xhat, xs0, rt, up);
  assess(st, w, p, r);
  r->defect = 0.0;
  r->status = status;
  r->success = r->feasible = 0;
  r->iterations = 0;
}

/* the status of a failed kernel SQP, as status_code names the solver's own status */
static int sqp_status_code(int sqp) {
  if (sqp == GK_SQP_MAXIMUM_ITERATIONS_EXCEEDED || sqp == GK_SQP_USER_REQUESTED_STOP)
    return CTL_LIMIT;
  return CTL_OTHER;
}

/* the solver's buffers for the target rt (ArtificialSteadyState.write) */
static void write_request(ctl_state *st, const double *xhat, const double *rt,
                          const double *u_init, const double *us_init, const double *xs0,
                          const double *up, const double *us_centre) {
  double *p = st->p;
  parameters(p, xhat, xs0, rt, up);
  for (int c = 0; c < NW; c++) {
    st->lbx[c] = c == IT ? 0.0 : -1.0;
    st->ubx[c] = c == IT ? CT_ALPHA_C : 1.0;
  }
  if (CT_US_RATE > 0.0)
    for (int j = 0; j < NU; j++) {
      st->lbx[NUU + j] = fmax(us_centre[j] - CT_US_RATE, -1.0);
      st->ubx[NUU + j] = fmin(us_centre[j] + CT_US_RATE, 1.0);
    }
  /* the constraint rows: output rows i >= 1 (paired), the terminal rows, Y_s */
  const int r0 = (NH - 1) * NQ;
  for (int c = 0; c < NG; c++) {
    st->lbg[c] = -INFINITY;
    st->ubg[c] = INFINITY;
  }
  for (int i = 1; i < NH; i++)
    for (int r = 0; r < NQ; r++) {
      const int pos = (i - 1) * NQ + r;
      st->ubg[pos] = st->bnd[i * NL + CT_PAIR_UP[r]];
      if (CT_PAIR_LO[r] >= 0) st->lbg[pos] = -st->bnd[i * NL + CT_PAIR_LO[r]];
    }
  for (int k = 0; k < NX; k++) {
    st->ubg[r0 + k] = 0.0;
    st->lbg[r0 + NX + k] = 0.0;
  }
  for (int r = 0; r < NQ; r++) {
    st->ubg[r0 + 2 * NX + r] = st->ys_rhs[CT_PAIR_UP[r]];
    if (CT_PAIR_LO[r] >= 0) st->lbg[r0 + 2 * NX + r] = -st->ys_rhs[CT_PAIR_LO[r]];
  }
  /* the initial guess: the candidate, t its terminal gap, the multipliers shifted */
  memcpy(st->w, u_init, NUU * sizeof(double));
  for (int j = 0; j < NU; j++)
    st->w[NUU + j] = fmin(fmax(us_init[j], st->lbx[NUU + j]), st->ubx[NUU + j]);
  const double gap = PFX(terminal_gap)(st->ws, st->w, p);
  st->w[IT] = fmin(fmax(gap, 1e-6), CT_ALPHA_C);
  for (int c = 0; c < NW; c++) st->lx[c] = st->has_warm ? st->warm_lx[CT_PERM_X[c]] : 0.0;
  for (int c = 0; c < NG; c++) st->lg[c] = st->has_warm ? st->warm_lg[CT_PERM_G[c]] : 0.0;
}

/* the answer check of the solver's w (ArtificialSteadyState._check_compiled) and its judgement
 * (fhocp_result.judge) into st->res */
static void check_answer(ctl_state *st, int sqp_status) {
  ctl_result *r = &st->res;
  assess(st, st->w, st->p, r);
  const int ok = sqp_status == GK_SQP_SOLVE_SUCCEEDED;
  r->iterations = st->info.iterations + st->info.discarded_iterations;
  r->feasible = all_finite(st->w, NW) && r->cv <= CT_FEAS_TOL && r->tv <= CT_FEAS_TOL &&
                r->defect <= CT_DEFECT_TOL;
  r->success = ok && r->feasible;
  r->status = r->success ? CTL_OPTIMAL
              : ok       ? CTL_RESIDUAL_CHECK_FAILED
                         : sqp_status_code(sqp_status);
  /* the warm start (fhocp_result.keeps_warm_start) */
  if (r->success || (all_finite(st->w, NW) && all_finite(st->lg, NG) && all_finite(st->lx, NW))) {
    memcpy(st->warm_lx, st->lx, sizeof st->warm_lx);
    memcpy(st->warm_lg, st->lg, sizeof st->warm_lg);
    st->has_warm = 1;
  }
}

/* one solve for the target rt from the guess (ArtificialSteadyState.request, FHOCP.
 * solve_request) against the bounds tighten() wrote: the i = 0 row first, then the SQP and
 * its answer check, into st->res */
static void solve(ctl_state *st, const double *xhat, const double *rt, const double *g_u,
                  const double *g_us, const double *xs0, const double *up,
                  const double *us_centre) {
  double u_init[NH * NU], us_init[NU];
  for (int c = 0; c < NH * NU; c++) u_init[c] = gk_clip1(g_u[c]);
  for (int j = 0; j < NU; j++) us_init[j] = gk_clip1(g_us[j]);
  double x0v = -INFINITY;
  for (int j = 0; j < NL; j++) {
    double s = 0.0;
    for (int k = 0; k < NX; k++) s += LUO[j * NX + k] * xhat[k];
    x0v = fmax(x0v, s - st->bnd[j]);
  }
  if (x0v > CT_FEAS_TOL) {
    check(st, xhat, u_init, us_init, rt, xs0, up, CTL_INFEASIBLE_X0, &st->res);
    return;
  }
  write_request(st, xhat, rt, u_init, us_init, xs0, up, us_centre);
  const int status = PFX(sqp)(st->ws, st->p, st->lbx, st->ubx, st->lbg, st->ubg, st->w, st->lx,
                              st->lg, st->g, &st->f, &st->opts, &st->info);
  check_answer(st, status);
}

/* ---------------------------------------------------------------- the law */
/* TrackingMPC.make_step: u_k for the target rt, with the candidate as fallback */
static void make_step(ctl_state *st, const double *xhat, const double *rt, double *u) {
  double *cand = st->cand;
  if (st->has_plan) {
    memcpy(cand, st->plan + NU, (NH - 1) * NU * sizeof(double));
    memcpy(cand + (NH - 1) * NU, st->us, NU * sizeof(double));
  } else {
    for (int i = 0; i < NH; i++) memcpy(cand + i * NU, st->us, NU * sizeof(double));
  }
  double up[NU], us0[NU], xs0[NX];
  memcpy(up, st->has_uprev ? st->uprev : st->us, sizeof up);
  memcpy(us0, st->us, sizeof us0);
  memcpy(xs0, st->xs, sizeof xs0);
  if (st->has_guess)
    solve(st, xhat, rt, st->g_u, st->g_us, st->g_xs, up, us0);
  else
    solve(st, xhat, rt, cand, us0, xs0, up, us0);
  ctl_result *res = &st->res;
  int use = res->success, fallback = 0;
  const ctl_result *applied = res;
  if (!use) {
    check(st, xhat, cand, us0, rt, xs0, up, CTL_OTHER, &st->chk);
    const int feasible = st->chk.cv <= CT_FEAS_TOL && st->chk.tv <= CT_FEAS_TOL;
    use = res->feasible && (!feasible || res->cost <= st->chk.cost);
    fallback = !use;
    if (!use) applied = &st->chk;
  }
  if (use) {
    memcpy(st->plan, res->u, sizeof st->plan);
    memcpy(st->us, res->us, sizeof st->us);
    memcpy(st->xs, res->xs, sizeof st->xs);
    memcpy(u, res->u, NU * sizeof(double));
  } else {
    memcpy(st->plan, cand, sizeof st->plan);
    for (int j = 0; j < NU; j++) u[j] = gk_clip1(cand[j]);
  }
  st->has_plan = 1;
  st->has_guess = all_finite(res->xs, NX);
  if (st->has_guess) {
    memcpy(st->g_u, res->u + NU, (NH - 1) * NU * sizeof(double));
    memcpy(st->g_u + (NH - 1) * NU, res->us, NU * sizeof(double));
    memcpy(st->g_us, res->us, sizeof st->g_us);
    memcpy(st->g_xs, res->xs, sizeof st->g_xs);
  }
  memcpy(st->uprev, u, sizeof st->uprev);
  st->has_uprev = 1;
  st->status = res->status;
  st->fallback = fallback;
  st->iterations = res->iterations;
  PFX(output)(applied->x + NX, st->y_pred);
}

/* ---------------------------------------------------------------- the instance */
EXPORT void PFX(ctl_reset)(ctl_state *st) {
  gk_ws *ws = st->ws;
  memset(st, 0, sizeof *st);
  st->ws = ws;
  PFX(invalidate)(ws);
  st->e_o = CT_E_O0;
  st->opts = (gk_sqp_opts){.tol_pr = CT_SQP_TOL_PR, .tol_du = CT_SQP_TOL_DU,
                           .max_iter = CT_SQP_MAX_ITER, .max_iter_ls = CT_SQP_MAX_ITER_LS,
                           .min_step_size = CT_SQP_MIN_STEP, .c1 = CT_SQP_C1,
                           .beta = CT_SQP_BETA, .time_budget = INFINITY,
                           .tol_du_relative = CT_SQP_TOL_DU_RELATIVE,
                           .reuse_step = CT_SQP_REUSE_STEP};
  for (int j = 0; j < NU; j++) st->u_phys[j] = 0.5 * (CT_U_LO[j] + CT_U_HI[j]);
  for (int a = 0; a < NY; a++) st->y_pred[a] = NAN;
  st->status = CTL_OTHER;
  st->beta = CT_BETA;
  ws_default_weights(ws);
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
 * fallback, iterations and y_pred (the model's output at the next sample under the applied
 * plan); advances the observer. A non-finite y or ref changes nothing (the last inputs are
 * held) and sets CTL_WARN_NONFINITE_INPUT; returns 1 then, else 0. */
EXPORT int PFX(ctl_step)(ctl_state *st, const double *y_phys, const double *r_phys) {
  double y[NY], yr[NY], yh[NY], rt[NY], u[NU], dz[NX], dr[NX], xn[NX], d[NY];
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
  const double e_o = st->e_o;
  /* the law (TrackingLaw.step) */
  if (!st->started) {
    double x_s[NX], u_s[NU];
    PFX(output)(st->xhat, yh);
    PFX(equilibrium)(st->ws, yh, x_s, u_s);
    for (int j = 0; j < NU; j++) st->us[j] = gk_clip1(u_s[j]);
    memcpy(st->xs, x_s, sizeof x_s);
    st->has_plan = st->has_guess = 0;
    st->started = 1;
  }
  PFX(output)(st->xhat, yh);
  const double beta = st->beta;
  for (int a = 0; a < NY; a++) st->dhat[a] = st->dhat[a] + beta * ((y[a] - yh[a]) - st->dhat[a]);
  if (!CT_CERTIFIED)   /* the measured tightening is around y + d_hat */
    for (int j = 0; j < NL; j++) {
      double s = 0.0;
      for (int a = 0; a < NY; a++) s += CT_L[j * NY + a] * st->dhat[a];
      st->shift[j] = s;
    }
  tighten(st, e_o);
  for (int a = 0; a < NY; a++) rt[a] = yr[a] - st->dhat[a];
  make_step(st, st->xhat, rt, u);
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
  for (int a = 0; a < NY; a++) st->y_pred[a] = st->y_pred[a] * CT_Y_SCALE[a] + CT_Y_OFFSET[a];
  return 0;
}

/* where tunable parameter i (CTL_P_*) lives, NULL for an unknown one */
static double *parameter(ctl_state *st, int i) {
  gk_mem *m = &st->ws->mem;
  if (i == CTL_P_OFFSET_FILTER) return &st->beta;
  if (i >= CTL_P_R && i < CTL_P_DU) return m->rw + (i - CTL_P_R) * (NU + 1);
#if HAS_DU
  if (i >= CTL_P_DU && i < CTL_P_T) return m->dw + (i - CTL_P_DU);
#endif
  if (i >= CTL_P_T && i < CTL_N_PARAMETERS) return m->tw + (i - CTL_P_T);
  return 0;
}

/* a (NU x NU) is positive definite: its Cholesky factorisation exists */
static int positive_definite(const double *a) {
  double l[NU * NU];
  for (int j = 0; j < NU; j++)
    for (int k = 0; k <= j; k++) {
      double s = a[j * NU + k];
      for (int c = 0; c < k; c++) s -= l[j * NU + c] * l[k * NU + c];
      if (j == k) {
        if (!(s > 0.0)) return 0;
        l[j * NU + j] = sqrt(s);
      } else {
        l[j * NU + k] = s / l[k * NU + k];
      }
    }
  return 1;
}

/* Tunable parameter i (CTL_P_*): its value, or NaN for an unknown one. */
EXPORT double PFX(ctl_get_parameter)(const ctl_state *st, int i) {
  const double *v = parameter((ctl_state *)st, i);
  return v ? *v : NAN;
}

/* Set tunable parameter i (CTL_P_*) from the next step on: NULL, or why the value is refused
 * (then nothing changes). */
EXPORT const char *PFX(ctl_set_parameter)(ctl_state *st, int i, double value) {
  double *v = parameter(st, i);
  if (!v) return "is not a parameter of the controller";
  if (i == CTL_P_OFFSET_FILTER) {
    if (!(value > 0.0 && value <= 1.0)) return "must be in (0, 1]";
  } else if (i < CTL_P_DU) {
    double r[NU * NU];
    memcpy(r, st->ws->mem.rw, sizeof r);
    r[(i - CTL_P_R) * (NU + 1)] = value;
    if (!(isfinite(value) && positive_definite(r)))
      return "must keep R positive definite (a finite diagonal weight > 0)";
  } else if (i < CTL_P_T) {
    if (!(value >= 0.0 && isfinite(value))) return "must be a finite weight >= 0";
  } else if (!(value > 0.0 && isfinite(value))) {
    return "must be a finite weight > 0";
  }
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
 * whether the candidate was applied, the SQP iterations, the predicted outputs (NY) */
EXPORT void PFX(ctl_outputs)(const ctl_state *st, double *u_phys, int *status, int *fallback,
                             int *iterations, double *y_pred) {
  if (u_phys) memcpy(u_phys, st->u_phys, sizeof st->u_phys);
  if (status) *status = st->status;
  if (fallback) *fallback = st->fallback;
  if (iterations) *iterations = st->iterations;
  if (y_pred) memcpy(y_pred, st->y_pred, sizeof st->y_pred);
}
