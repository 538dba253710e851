/* controllers/laws/tracking/law.c: the robust MPC's tracking law in C (the default law),
 * joined between controller.h and controller.c (see controller.h for what a law file defines). It is the C
 * twin of the Python law, line for line and in the same order of kernel calls:
 *
 *   law_disturbance_moved, law_restart
 *                   TrackingLaw.disturbance_moved (the steady state kept at its output under
 *                   the disturbances now held, the plan moved alike) and restart
 *   law_step        controllers/laws/tracking/law.py TrackingLaw.step: its first steady state (the
 *                   equilibrium of the estimate's output), the output-disturbance estimate
 *                   d_hat (DisturbanceFilter), the uncertified mode's shift of the output rows
 *                   by L d_hat, the target r = y_ref - d_hat
 *   make_step       controllers/laws/tracking/mpc.py TrackingMPC.make_step (the candidate, the
 *                   fallback, the next guess)
 *   solve           controllers/laws/tracking/reference.py ArtificialSteadyState.request, and
 *                   controllers/ocp/fhocp.py FHOCP.solve_request: the i = 0 row,
 *                   write_request (ArtificialSteadyState.write), the kernel SQP,
 *                   check_answer (ArtificialSteadyState._check_compiled and
 *                   fhocp_result.judge, the warm start)
 *   check           ArtificialSteadyState.evaluate (the candidate's answer check)
 *
 * so that the same measurements give the same inputs, to the bit
 * (tests/cosim/adapters/test_controller_export.py, tests/fmus/test_controller_fmu.py).
 */
#if !HAS_ASS
#error "controllers/laws/tracking/law.c runs on a tracking FHOCP's kernel (HAS_ASS)"
#endif

/* the tunable parameters (law_parameter), in this order: the disturbance filter's gain
 * (option offset_filter, in (0, 1]), the diagonal of R (option R: NU entries, R kept positive
 * definite), the input-rate weights S (option du_weight: NU entries >= 0, with HAS_DU) and
 * the offset weights T (option offset_weight: NY entries > 0). The weights are the kernel
 * instance's (gk_mem.rw, dw, tw); Q and s are not tunable: s is the certificate's
 * (eq:definition_s, from Q), and the tracking law's hypotheses (H3) hold for any R > 0,
 * S >= 0, T > 0. controller_source.py parameters() names them, in this order. */
enum {
  LAW_P_OFFSET_FILTER = 0, LAW_P_R = 1, LAW_P_DU = LAW_P_R + NU,
  LAW_P_T = LAW_P_DU + HAS_DU * NU, LAW_N_PARAMETERS = LAW_P_T + NY
};

typedef struct law_state {
  gk_ws *ws;
  /* the FHOCP's inputs already applied and the operator's terms (controller.h; given with
   * every step) */
  const ctl_prefix *prefix;
  const ctl_ops *ops;
  /* the output-disturbance estimate d_hat (DisturbanceFilter) and its gain (a parameter) */
  double dhat[NY], beta;
  /* the tracking MPC: artificial steady state, plan, last input, next initial guess;
   * whether the last step's candidate was feasible (StepRecord.candidate_feasible) */
  int started, has_plan, has_uprev, has_guess, cand_feasible;
  double us[NU], xs[NX], plan[NH * NU], uprev[NU], g_u[NH * NU], g_us[NU], g_xs[NX];
  /* the FHOCP's warm start (its last multipliers) */
  int has_warm;
  double warm_lx[NW], warm_lg[NG];
  /* the solver's buffers */
  double p[NP], lbx[NW], ubx[NW], lbg[NG], ubg[NG], w[NW], lx[NW], lg[NG], g[NG], f;
  /* the tightened bounds (NH x NL), then Y_s's right-hand side (YS_RHS) */
  double bnd[(NH + 1) * NL], shift[NL], cand[NH * NU];
  ctl_result res, chk;
  gk_sqp_opts opts;
  gk_sqp_info info;
  ctl_last last;   /* what the last step gave */
} law_state;
#define YS_RHS(st) ((st)->bnd + NH * NL)

/* the tightened bounds (controller.h), in the uncertified mode around y + d_hat, and Y_s's
 * right-hand side */
static void tighten(law_state *st, double e_o) {
  operator_bounds(st->ops, e_o, st->bnd);
  if (!CT_CERTIFIED)
    for (int i = 0; i < NH; i++)
      for (int j = 0; j < NL; j++) st->bnd[i * NL + j] -= st->shift[j];
  for (int j = 0; j < NL; j++) {   /* narrowed by the operator's limits (ys_rhs) */
    const double base = st->ops->active ? CT_YS_BASE[j] - st->ops->dh[j] : CT_YS_BASE[j];
    YS_RHS(st)[j] = CT_CERTIFIED ? base : base - st->shift[j];
  }
}

/* the answer check of (w, p) into r (ArtificialSteadyState._check_compiled): the kernel's plain
 * rollout, x_s(u_s) from p's x_s0 with its fixed point verified, cost and residuals (output
 * rows, input box, terminal set, Y_s) */
static void assess(law_state *st, const double *w, const double *p, ctl_result *r,
                   int soften) {
  gk_assessment out;
  PFX(assess_w)(st->ws, w, p, st->bnd, CT_ALPHA_C, r->u, r->x, &out, r->xs);
  for (int j = 0; j < NU; j++) r->us[j] = gk_clip1(w[NUU + j]);
  r->cost = out.cost;
  r->defect = out.defect;
  if (!(out.steady_residual <= CT_XS_CHECK_TOL)) {
    for (int k = 0; k < NX; k++) r->xs[k] = NAN;
    r->cv = r->tv = INFINITY;
    r->softened = 0.0;
    return;
  }
  set_residuals(r, &out, CT_ALPHA_C, soften);
  double excess = -INFINITY;
  for (int j = 0; j < NL; j++) {
    double s = 0.0;
    for (int k = 0; k < NX; k++) s += LUO[j * NX + k] * r->xs[k];
    excess = fmax(excess, s - YS_RHS(st)[j]);
  }
  extra_row(r, excess, soften);
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
static void check(law_state *st, const double *xhat, const double *u_in, const double *us_in,
                  const double *rt, const double *xs0, const double *up, int status,
                  ctl_result *r) {
  double w[NW] = {0.0}, p[NP];
  for (int c = 0; c < NUU; c++) w[c] = gk_clip1(u_in[c]);
  for (int j = 0; j < NU; j++) w[NUU + j] = gk_clip1(us_in[j]);
  parameters(p, xhat, xs0, rt, up);
  assess(st, w, p, r, 0);
  r->defect = 0.0;
  r->status = status;
  r->success = r->feasible = 0;
  r->iterations = 0;
}

/* the solver's buffers for the target rt (ArtificialSteadyState.write) */
static void write_request(law_state *st, const double *xhat, const double *rt,
                          const double *u_init, const double *us_init, const double *xs0,
                          const double *up, const double *us_centre, int soften) {
  double *p = st->p;
  parameters(p, xhat, xs0, rt, up);
  variable_bounds(st->lbx, st->ubx, CT_ALPHA_C, soften);
  const ctl_ops *ops = st->ops;
  if (CT_US_RATE > 0.0)
    for (int j = 0; j < NU; j++) {
      const double c = ops->active ? fmin(fmax(us_centre[j], ops->lo[j]), ops->hi[j])
                                   : us_centre[j];
      st->lbx[NUU + j] = fmax(c - CT_US_RATE, -1.0);
      st->ubx[NUU + j] = fmin(c + CT_US_RATE, 1.0);
    }
  ops_bound(ops, st->lbx, st->ubx);
  prefix_bound(st->prefix, st->lbx, st->ubx);
  /* the constraint rows: output rows i >= 1 (paired), the terminal rows, Y_s */
  const int r0 = (NH - 1) * NQ;
  for (int c = 0; c < NG; c++) {
    st->lbg[c] = -INFINITY;
    st->ubg[c] = INFINITY;
  }
  output_rows(st->bnd, st->lbg, st->ubg);
  for (int k = 0; k < NX; k++) {
    st->ubg[r0 + k] = 0.0;
    st->lbg[r0 + NX + k] = 0.0;
  }
  for (int r = 0; r < NQ; r++) {
    st->ubg[r0 + 2 * NX + r] = YS_RHS(st)[CT_PAIR_UP[r]];
    if (CT_PAIR_LO[r] >= 0) st->lbg[r0 + 2 * NX + r] = -YS_RHS(st)[CT_PAIR_LO[r]];
  }
  move_rows(st->lbg, st->ubg);
  /* the initial guess: the candidate, t its terminal gap, the multipliers shifted */
  memcpy(st->w, u_init, NUU * sizeof(double));
  if (ops->active) {   /* inside the operator's bounds, the inputs already applied kept */
    ops_clip(ops, st->w);
    prefix_impose(st->prefix, st->w);
  }
  for (int j = 0; j < NU; j++)
    st->w[NUU + j] = fmin(fmax(us_init[j], st->lbx[NUU + j]), st->ubx[NUU + j]);
  for (int c = IT + 1; c < NW; c++) st->w[c] = 0.0;   /* the slacks (SOFT) */
  const double gap = soften ? PFX(plan_slacks)(st->ws, st->w, p, st->bnd, CT_ALPHA_C)
                            : PFX(terminal_gap)(st->ws, st->w, p);
  st->w[IT] = fmin(fmax(gap, 1e-6), CT_ALPHA_C);
  for (int c = 0; c < NW; c++) st->lx[c] = st->has_warm ? st->warm_lx[CT_PERM_X[c]] : 0.0;
  for (int c = 0; c < NG; c++) st->lg[c] = st->has_warm ? st->warm_lg[CT_PERM_G[c]] : 0.0;
}

/* the answer check of the solver's w (ArtificialSteadyState._check_compiled) and its judgement
 * (fhocp_result.judge) into st->res */
static void check_answer(law_state *st, int sqp_status, int soften) {
  ctl_result *r = &st->res;
  assess(st, st->w, st->p, r, soften);
  judge(r, st->w, sqp_status, &st->info);
  /* the warm start (fhocp_result.keeps_warm_start) */
  if (r->success || (all_finite(st->w, NW) && all_finite(st->lg, NG) && all_finite(st->lx, NW))) {
    memcpy(st->warm_lx, st->lx, sizeof st->warm_lx);
    memcpy(st->warm_lg, st->lg, sizeof st->warm_lg);
    st->has_warm = 1;
  }
}

/* one solve for the target rt from the guess (ArtificialSteadyState.request, FHOCP.
 * solve_request) against the bounds tighten() wrote, into st->res: the i = 0 row first (a
 * violated one: the candidate evaluated, status infeasible_x0; with SOFT the softened phase
 * at once), then the hard phase's SQP and its answer check, and with SOFT the softened
 * phase's when the hard one had no answer (soften_after), from the same guess and warm
 * start */
static void solve(law_state *st, const double *xhat, const double *rt, const double *g_u,
                  const double *g_us, const double *xs0, const double *up,
                  const double *us_centre) {
  double u_init[NH * NU], us_init[NU];
  for (int c = 0; c < NH * NU; c++) u_init[c] = gk_clip1(g_u[c]);
  prefix_impose(st->prefix, u_init);
  for (int j = 0; j < NU; j++) us_init[j] = gk_clip1(g_us[j]);
  const int outside = x0_violation(xhat, st->bnd) > CT_FEAS_TOL;
  if (outside && !SOFT) {
    check(st, xhat, u_init, us_init, rt, xs0, up, CTL_INFEASIBLE_X0, &st->res);
    return;
  }
#if SOFT
  double lx0[NW], lg0[NG];   /* the warm start, for the softened phase */
  const int had_warm = st->has_warm;
  memcpy(lx0, st->warm_lx, sizeof lx0);
  memcpy(lg0, st->warm_lg, sizeof lg0);
#endif
  for (int soften = outside; soften <= SOFT; soften++) {
    PFX(set_soft)(st->ws, soften);
    write_request(st, xhat, rt, u_init, us_init, xs0, up, us_centre, soften);
    const int status = PFX(sqp)(st->ws, st->p, st->lbx, st->ubx, st->lbg, st->ubg, st->w,
                                st->lx, st->lg, st->g, &st->f, &st->opts, &st->info);
    check_answer(st, status, soften);
    if (soften || st->res.success || !soften_after(status)) return;
#if SOFT
    st->has_warm = had_warm;   /* the softened phase starts where the hard one did */
    memcpy(st->warm_lx, lx0, sizeof lx0);
    memcpy(st->warm_lg, lg0, sizeof lg0);
#endif
  }
}

/* ---------------------------------------------------------------- the law */
/* TrackingMPC.make_step: u_k for the target rt, with the candidate as fallback */
static void make_step(law_state *st, const double *xhat, const double *rt, double *u) {
  double *cand = st->cand;
  shifted_candidate(cand, st->plan, st->has_plan, st->us);
  prefix_impose(st->prefix, cand);   /* the inputs already applied, as they were */
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
  st->cand_feasible = 1;
  if (!use) {
    check(st, xhat, cand, us0, rt, xs0, up, CTL_OTHER, &st->chk);
    use = take_iterate(res, &st->chk, &st->cand_feasible, &fallback);
    if (!use) applied = &st->chk;
  }
  if (use) {
    memcpy(st->us, res->us, sizeof st->us);
    memcpy(st->xs, res->xs, sizeof st->xs);
  }
  keep_plan(st->plan, st->prefix, use ? res->u : cand, !use, u);
  st->has_plan = 1;
  st->has_guess = all_finite(res->xs, NX);
  if (st->has_guess) {
    memcpy(st->g_u, res->u + NU, (NH - 1) * NU * sizeof(double));
    memcpy(st->g_u + (NH - 1) * NU, res->us, NU * sizeof(double));
    memcpy(st->g_us, res->us, sizeof st->g_us);
    memcpy(st->g_xs, res->xs, sizeof st->g_xs);
  }
  step_done(st->uprev, &st->has_uprev, u, &st->last, res, applied, fallback);
}

/* ---------------------------------------------------------------- the law's interface */
static void law_reset(law_state *st, gk_ws *ws) {
  memset(st, 0, sizeof *st);
  st->opts = sqp_options();
  st->ws = ws;
  st->beta = CT_BETA;
  last_reset(&st->last);
}

/* TrackingLaw.disturbance_moved: the steady state's output kept under the disturbances now in
 * the biases, its input the equilibrium's, the plan moved by the same input change */
__attribute__((unused)) static void law_disturbance_moved(law_state *st) {
  double ys[NY], xs[NX], us[NU];
  if (!st->started) return;
  PFX(output)(st->xs, ys);
  PFX(equilibrium)(st->ws, ys, xs, us);
  for (int j = 0; j < NU; j++) us[j] = gk_clip1(us[j]);
  if (st->has_plan)
    for (int i = 0; i < NH; i++)
      for (int j = 0; j < NU; j++) {
        const double du = us[j] - st->us[j];
        st->plan[i * NU + j] = gk_clip1(st->plan[i * NU + j] + du);
      }
  memcpy(st->us, us, sizeof us);
  memcpy(st->xs, xs, sizeof xs);
  st->has_guess = 0;
}

/* TrackingLaw.restart: the steady state starts again at the next step */
__attribute__((unused)) static void law_restart(law_state *st) { st->started = 0; }

/* TrackingLaw.applied: the inputs the plant got (normalised), u_{-1} of the next step */
static void law_applied(law_state *st, const double *u) {
  memcpy(st->uprev, u, sizeof st->uprev);
  st->has_uprev = 1;
}

/* Operating.room: the last plan's slack in each row, its stages i = 1 .. N-1 at its bounds
 * and its steady state in Y_s (L (U_o x + b_o) against bnd + L b_o), into slack (NL, >= 0);
 * 0 after a fallback (no plan to keep feasible) */
static int law_room(const law_state *st, double *slack) {
  double y[NY];
  if (st->last.fallback || !st->has_plan) return 0;
  for (int r = 0; r < NL; r++) slack[r] = INFINITY;
  for (int i = 1; i < NH; i++) {
    PFX(output)(st->res.x + i * NX, y);
    for (int r = 0; r < NL; r++) {
      double ly = 0.0;
      for (int a = 0; a < NY; a++) ly += y[a] * CT_L[r * NY + a];
      slack[r] = fmin(slack[r], (st->bnd[i * NL + r] + CT_LBO[r]) - ly);
    }
  }
  PFX(output)(st->xs, y);
  for (int r = 0; r < NL; r++) {
    double ly = 0.0;
    for (int a = 0; a < NY; a++) ly += y[a] * CT_L[r * NY + a];
    slack[r] = fmax(fmin(slack[r], (YS_RHS(st)[r] + CT_LBO[r]) - ly), 0.0);
  }
  return 1;
}

/* TrackingLaw.step: u (normalised) at x_hat, e_o for the measured y and the set-point yr, the
 * FHOCP from xstart (x_hat, or x_hat predicted over the inputs' shortest dead time) with the
 * inputs already applied in prefix and the operator's terms ops */
static void law_step(law_state *st, const double *xhat, const double *xstart,
                     const ctl_prefix *prefix, const ctl_ops *ops, double e_o, const double *y,
                     const double *yr, double *u, int *warnings) {
  double yh[NY], rt[NY];
  (void)warnings;
  st->prefix = prefix;
  st->ops = ops;
  if (!st->started) {
    double x_s[NX], u_s[NU];
    PFX(output)(xhat, yh);
    PFX(equilibrium)(st->ws, yh, x_s, u_s);
    for (int j = 0; j < NU; j++) st->us[j] = gk_clip1(u_s[j]);
    memcpy(st->xs, x_s, sizeof x_s);
    st->has_plan = st->has_guess = 0;
    st->started = 1;
  }
  PFX(output)(xhat, yh);
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
  make_step(st, xstart, rt, u);
  PFX(output)(st->xs, st->last.y_target);   /* the steady output y_s */
}

/* where tunable parameter i (LAW_P_*) lives, NULL for an unknown one */
static double *law_parameter(law_state *st, int i) {
  gk_mem *m = &st->ws->mem;
  if (i == LAW_P_OFFSET_FILTER) return &st->beta;
  if (i >= LAW_P_R && i < LAW_P_DU) return m->rw + (i - LAW_P_R) * (NU + 1);
#if HAS_DU
  if (i >= LAW_P_DU && i < LAW_P_T) return m->dw + (i - LAW_P_DU);
#endif
  if (i >= LAW_P_T && i < LAW_N_PARAMETERS) return m->tw + (i - LAW_P_T);
  return 0;
}

/* why the value of tunable parameter i (a known one) is refused; NULL: accepted */
static const char *law_refuse(const law_state *st, int i, double value) {
  if (i == LAW_P_OFFSET_FILTER) return value > 0.0 && value <= 1.0 ? 0 : "must be in (0, 1]";
  if (i < LAW_P_DU) return refuse_r(st->ws, i - LAW_P_R, value);
  if (i < LAW_P_T) return value >= 0.0 && isfinite(value) ? 0 : "must be a finite weight >= 0";
  return value > 0.0 && isfinite(value) ? 0 : "must be a finite weight > 0";
}
