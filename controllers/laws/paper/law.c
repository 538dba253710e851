/* controllers/laws/paper/law.c: the paper's law in C (law="paper"), joined between
 * controller.h and controller.c (see controller.h for what a law file defines). It is the C twin of the Python
 * law, in the same order of kernel calls:
 *
 *   law_disturbance_moved, law_restart
 *                   PaperLaw.disturbance_moved (the reference again under the disturbances
 *                   now held, the plan moved alike) and restart (nothing)
 *   law_step        controllers/laws/paper/law.py PaperLaw.step and _update_reference: the
 *                   set-point rate limit (setpoint_rate), the offset-free shift by d_hat
 *                   (offset_free), the reference (x_bar, u_bar, alpha) of each new set-point,
 *                   the rejection of one outside the theory (the last admissible one kept)
 *   reference       controllers/certification/certificates.py Certificate.reference: the
 *                   hypotheses at y_bar (Assumption 1, alpha of eq:def-alpha > 0,
 *                   eq:condition-recursive-feasibility; nu < 1 and nu_o < 1 are the
 *                   design's), then the model equilibrium with output y_bar (the kernel's
 *                   PFX(equilibrium), which the Python law calls too)
 *   first_admissible PaperLaw._first_admissible and closest_admissible (the uncertified
 *                   mode's first set-point outside the theory)
 *   govern          (controllers/laws/paper/governor.c) PaperLaw._govern with controllers/ocp/
 *                   governor.py ReferenceGovernor (CT_GOVERNOR): the admissible reference
 *                   governor after the first set-point
 *   make_step       controllers/laws/paper/mpc.py RobustMPC.make_step: eq:mpc with the
 *                   candidate of the proof of th:feasibility-stability as fallback (the
 *                   governor's feasible candidate when it moved), and the suboptimal iterate
 *                   no costlier than it
 *   solve           controllers/ocp/fhocp.py FHOCP.solve_request with the paper's reference
 *                   (controllers/laws/paper/reference.py FixedSetpoint: write, through
 *                   controllers/ocp/fhocp_layout.py FHOCPLayout.write; check_answer and
 *                   fhocp_result.judge; the warm start)
 *   evaluate        FixedSetpoint.evaluate (a given plan's answer check)
 *
 * so that the same measurements give the same inputs (tests/cosim/adapters/
 * test_controller_export.py).
 *
 * Where the Python component raises (a certified design whose first set-point is outside
 * the theory), the C step takes the closest admissible set-point as the uncertified law
 * does and raises CTL_WARN_SETPOINT_REJECTED; with no admissible set-point at all it holds
 * the inputs and raises CTL_WARN_NO_ADMISSIBLE_SETPOINT.
 */
#if HAS_ASS
#error "controllers/laws/paper/law.c runs on the paper's FHOCP kernel (HAS_ASS 0)"
#endif
#if !defined(CT_OFFSET_FREE) || !defined(CT_RATE_TUNABLE)
#error "the paper's law needs CT_OFFSET_FREE and CT_RATE_TUNABLE (controller_source.py)"
#endif

/* How far inside the admissible box the closest admissible set-point is put
 * (controllers/laws/paper/law.py INSIDE) and the change of the FHOCP's set-point that counts as one (_update_reference). */
#define PAPER_INSIDE 1e-3
#define PAPER_SAME_TOL (CT_OFFSET_FREE ? 1e-3 : 1e-12)

/* the tunable parameters (law_parameter), in this order: the disturbance filter's gain
 * (option offset_filter, in (0, 1]; with offset_free only), the diagonal of R (option R: NU
 * entries, R kept positive definite), the input-rate weights S (option du_weight: NU
 * entries >= 0, with HAS_DU) and the set-point rate (option setpoint_rate, > 0, in each
 * output's units per sample; when the design has one: CT_RATE_TUNABLE). The weights are the
 * kernel instance's (gk_mem.rw, dw); Q and s are not tunable (s is the certificate's,
 * eq:definition_s, from Q); the theorem holds for any R > 0, and S and the rate are outside
 * the paper's law. */
enum {
  LAW_P_OFFSET_FILTER = 0, LAW_P_R = CT_OFFSET_FREE, LAW_P_DU = LAW_P_R + NU,
  LAW_P_RATE = LAW_P_DU + HAS_DU * NU, LAW_N_PARAMETERS = LAW_P_RATE + CT_RATE_TUNABLE
};

typedef struct law_state {
  gk_ws *ws;
  /* the FHOCP's inputs already applied and the operator's terms (controller.h; given with
   * every step) */
  const ctl_prefix *prefix;
  const ctl_ops *ops;
  /* the set-point handling: the requested set-point, the FHOCP's, the offset estimate d_hat
   * and its gain (a parameter) */
  int has_ref, has_model, has_reference;
  double y_ref[NY], y_model[NY], dhat[NY], beta;
  double rate;   /* the set-point rate (< 0: none), a parameter when the design has one */
  /* the reference (x_bar, u_bar, alpha) of the FHOCP's set-point */
  double x_bar[NX], u_bar[NU], alpha;
  /* the robust MPC: the plan, the last input (u_{-1} of the input-rate term); whether the
   * last fallback's candidate was feasible (controller.c reads it with disturbances) */
  int has_plan, has_uprev, cand_feasible;
  /* the measured disturbances' last move left the set-point unreachable: the last
   * reference kept, said at the next step */
  int moved_refused;
  double plan[NH * NU], uprev[NU], cand[NH * NU];
  /* the reference governor (CT_GOVERNOR): lambda_max, whether its last step moved, the last
   * request refused as unreachable, and the candidate it found feasible this step (the
   * solve's initial guess and the fallback) */
  double lam_max;
  int moved, has_unreachable, has_gcand;
  double unreachable[NY], gcand[NH * NU], gx[(NH + 1) * NX];
  /* (more outputs than inputs) the equilibrium of the last request the governor moves
   * towards along the surface of equilibrium outputs: the request, whether it has one */
  int has_target, target_ok;
  double target_r[NY], target_x[NX], target_u[NU];
  /* the FHOCP's warm start (its last answer and multipliers) */
  int has_warm;
  double warm_w[NW], warm_lx[NW], warm_lg[NG];
  /* the solver's buffers */
  double p[NP], lbx[NW], ubx[NW], lbg[NG], ubg[NG], w[NW], lx[NW], lg[NG], g[NG], f;
  double bnd[NH * NL];
  ctl_result res, chk;
  gk_sqp_opts opts;
  gk_sqp_info info;
  ctl_last last;   /* what the last step gave */
} law_state;

/* ---------------------------------------------------------------- the reference */
/* Certificate.ok at y (normalised), alpha (eq:def-alpha) into *alpha: the margins
 * h - e_tilde a_N - b_N - w_L - L y of Assumption 1, in numpy's order */
static int admissible(const double *y, double *alpha) {
  double a = INFINITY;
  int ok = CT_CERT_DESIGN_OK;
  for (int j = 0; j < NL; j++) {
    double ly = 0.0;
    for (int c = 0; c < NY; c++) ly += -CT_CERT_L[j * NY + c] * y[c];
    const double m = (((ly + CT_CERT_H[j]) - CT_CERT_EAN[j]) - CT_CERT_BN[j]) - CT_CERT_WL[j];
    if (!(m > 0.0)) ok = 0;
    if (CT_CERT_CS[j] > 0.0) a = fmin(a, m / CT_CERT_CS[j]);
  }
  *alpha = a;
  return ok && a > 0.0 && CT_CERT_RF_LHS <= a * CT_CERT_RF_ONE_MINUS_RHO;
}

/* Certificate.reference: (x_bar, u_bar, alpha) of the set-point y into x, u, *alpha; 0, or 1
 * when y fails a hypothesis or is not reachable with |u|inf <= 1 */
static int reference_of(law_state *st, const double *y, double *x, double *u, double *alpha) {
  if (!admissible(y, alpha)) return 1;
  return PFX(equilibrium)(st->ws, y, x, u) != 0;
}

/* the same into st (the FHOCP's reference); nothing written when it fails */
static int reference(law_state *st, const double *y) {
  double alpha, x[NX], u[NU];
  if (reference_of(st, y, x, u, &alpha) != 0) return 1;
  memcpy(st->x_bar, x, sizeof x);
  memcpy(st->u_bar, u, sizeof u);
  st->alpha = alpha;
  st->has_reference = 1;
  return 0;
}

/* closest_admissible: y moved into the admissible box, PAPER_INSIDE within it; 1 when the box
 * is empty for some output */
static int closest_admissible(const double *y, double *out) {
  for (int a = 0; a < NY; a++) {
    const double lo = CT_BOX_LO[a], hi = CT_BOX_HI[a];
    if (!(lo + 2 * PAPER_INSIDE <= hi)) return 1;
    out[a] = fmin(fmax(y[a], lo + PAPER_INSIDE), hi - PAPER_INSIDE);
  }
  return 0;
}

/* PaperLaw._first_admissible: the reference of the admissible set-point closest to target,
 * else to the output of the equilibrium closest to the measured y, into st and y_bar; 1 when
 * neither has one */
static int first_admissible(law_state *st, const double *target, const double *y,
                            double *y_bar) {
  double x_eq[NX], u_eq[NU], starts[2][NY], inside[NY];
  PFX(equilibrium)(st->ws, y, x_eq, u_eq);
  memcpy(starts[0], target, sizeof starts[0]);
  PFX(output)(x_eq, starts[1]);
  for (int s = 0; s < 2; s++) {
    if (closest_admissible(starts[s], inside) != 0) continue;
    if (reference(st, inside) == 0) {
      memcpy(y_bar, inside, sizeof inside);
      return 0;
    }
  }
  return 1;
}

/* the reference governor (controllers/laws/paper/governor.c, joined after this file) */
static void govern(law_state *st, const double *xhat, const double *target, int changed,
                   int *warnings);

/* PaperLaw._update_reference: the FHOCP's set-point for the request yr at the measured y
 * (after the first, through the governor when CT_GOVERNOR, its candidates from xstart: x_hat
 * predicted over the inputs' dead time); raises CTL_WARN_SETPOINT_REJECTED
 * once per requested set-point refused. 1 when there is no reference to regulate to (the
 * first set-point and none admissible). */
static int update_reference(law_state *st, const double *xhat, const double *xstart,
                            const double *y, const double *yr, int *warnings) {
  double target[NY], yh[NY];
  st->has_gcand = 0;
  memcpy(target, yr, sizeof target);
  if (st->rate >= 0.0 && st->has_model)
    for (int a = 0; a < NY; a++) {
      const double step = st->rate / fabs(CT_Y_SCALE[a]);
      const double base = st->y_model[a] + (CT_OFFSET_FREE ? st->dhat[a] : 0.0);
      target[a] = base + fmin(fmax(yr[a] - base, -step), step);
    }
  if (CT_OFFSET_FREE) {
    PFX(output)(xhat, yh);
    for (int a = 0; a < NY; a++) {
      st->dhat[a] = st->dhat[a] + st->beta * (((y[a] - yh[a])) - st->dhat[a]);
      target[a] = target[a] - st->dhat[a];
    }
  }
  if (st->has_model) {
    double d = 0.0;
    for (int a = 0; a < NY; a++) d = fmax(d, fabs(target[a] - st->y_model[a]));
    if (d < PAPER_SAME_TOL) return 0;
  }
  int changed = !st->has_ref;
  for (int a = 0; a < NY; a++) changed |= yr[a] != st->y_ref[a];
  memcpy(st->y_ref, yr, sizeof st->y_ref);
  st->has_ref = 1;
  if (CT_GOVERNOR && st->has_model) {
    govern(st, xstart, target, changed, warnings);
    return 0;
  }
  if (reference(st, target) == 0) {
    memcpy(st->y_model, target, sizeof target);
    st->has_model = 1;
    return 0;
  }
  if (changed) *warnings |= CTL_WARN_SETPOINT_REJECTED;
  if (st->has_model) return 0;   /* the last admissible set-point is kept */
  if (first_admissible(st, target, y, st->y_model) == 0) {
    st->has_model = 1;
    return 0;
  }
  *warnings |= CTL_WARN_NO_ADMISSIBLE_SETPOINT;
  return 1;
}

/* ---------------------------------------------------------------- the FHOCP */
/* u_{-1} of the input-rate term: the input applied last, u_bar before the first */
static const double *u_prev(const law_state *st) {
  return st->has_uprev ? st->uprev : st->u_bar;
}

/* FixedSetpoint.evaluate: the plan u (clipped) from x_hat evaluated apart from the solver into
 * r (the kernel's answer check of a given sequence) */
static void evaluate(law_state *st, const double *xhat, const double *u, int status,
                     ctl_result *r) {
  gk_assessment out;
  for (int c = 0; c < NH * NU; c++) r->u[c] = gk_clip1(u[c]);
  PFX(assess)(st->ws, xhat, r->u, st->x_bar, st->u_bar, u_prev(st), st->bnd, st->alpha, r->x,
              &out);
  r->cost = out.cost;
  set_residuals(r, &out, st->alpha, 0);
  r->defect = 0.0;
  r->status = status;
  r->success = r->feasible = 0;
  r->iterations = 0;
}

/* FixedSetpoint.write through FHOCPLayout.write: p = (x_hat, x_bar, u_bar[, u_{-1}]), the
 * bounds (t <= alpha; the slacks free in the softened phase, soften, else 0), the output and
 * terminal rows, the initial guess (u_init when given: the governor's candidate; else the
 * last answer shifted by one stage with u_bar appended, else u_bar repeated; t its terminal
 * gap; the softened phase's slacks its plan's) and the multipliers shifted by one stage */
static void write_request(law_state *st, const double *xhat, const double *u_init,
                          int soften) {
  double *p = st->p;
  memcpy(p, xhat, NX * sizeof(double));
  memcpy(p + NX, st->x_bar, NX * sizeof(double));
  memcpy(p + 2 * NX, st->u_bar, NU * sizeof(double));
#if HAS_DU
  memcpy(p + 2 * NX + NU, u_prev(st), NU * sizeof(double));
#endif
  variable_bounds(st->lbx, st->ubx, st->alpha, soften);
  for (int c = 0; c < NG; c++) {
    st->lbg[c] = -INFINITY;
    st->ubg[c] = INFINITY;
  }
  output_rows(st->bnd, st->lbg, st->ubg);
  const int r0 = (NH - 1) * NQ;
  for (int k = 0; k < NX; k++) {
    st->ubg[r0 + k] = 0.0;
    st->lbg[r0 + NX + k] = 0.0;
  }
  move_rows(st->lbg, st->ubg);
  for (int c = 0; c < NW; c++) st->w[c] = 0.0;
  if (u_init) {
    memcpy(st->w, u_init, NH * NU * sizeof(double));
  } else if (st->has_warm) {
    memcpy(st->w, st->warm_w + NU, (NH - 1) * NU * sizeof(double));
    memcpy(st->w + (NH - 1) * NU, st->u_bar, NU * sizeof(double));
  } else {
    for (int i = 0; i < NH; i++) memcpy(st->w + i * NU, st->u_bar, NU * sizeof(double));
  }
  for (int c = 0; c < NH * NU; c++) st->w[c] = gk_clip1(st->w[c]);
  ops_bound(st->ops, st->lbx, st->ubx);   /* the operator's bounds (FHOCPLayout.write) */
  ops_clip(st->ops, st->w);
  prefix_impose(st->prefix, st->w);
  prefix_bound(st->prefix, st->lbx, st->ubx);
  const double gap = soften ? PFX(plan_slacks)(st->ws, st->w, p, st->bnd, st->alpha)
                            : PFX(terminal_gap)(st->ws, st->w, p);
  st->w[IT] = fmin(fmax(gap, 1e-6), fmax(st->alpha, 0.0));
  for (int c = 0; c < NW; c++) st->lx[c] = st->has_warm ? st->warm_lx[CT_PERM_X[c]] : 0.0;
  for (int c = 0; c < NG; c++) st->lg[c] = st->has_warm ? st->warm_lg[CT_PERM_G[c]] : 0.0;
}

/* One phase of FHOCP.solve_request (FHOCP._solve_phase) into st->res: the hard problem, or
 * the softened one (soften), the SQP from u_init (NULL: the warm start), the answer check
 * (FixedSetpoint.check_answer, judge) and the warm start (keeps_warm_start); the SQP's
 * status */
static int solve_phase(law_state *st, const double *xhat, const double *u_init, int soften) {
  PFX(set_soft)(st->ws, soften);
  write_request(st, xhat, u_init, soften);
  const int status = PFX(sqp)(st->ws, st->p, st->lbx, st->ubx, st->lbg, st->ubg, st->w, st->lx,
                              st->lg, st->g, &st->f, &st->opts, &st->info);
  ctl_result *r = &st->res;
  gk_assessment out;
  PFX(assess_w)(st->ws, st->w, st->p, st->bnd, st->alpha, r->u, r->x, &out, 0);
  r->cost = out.cost;
  r->defect = out.defect;
  set_residuals(r, &out, st->alpha, soften);
  judge(r, st->w, status, &st->info);
  if (r->success || (all_finite(st->w, NW) && all_finite(st->lg, NG) && all_finite(st->lx, NW))) {
    memcpy(st->warm_w, st->w, sizeof st->warm_w);
    memcpy(st->warm_lx, st->lx, sizeof st->warm_lx);
    memcpy(st->warm_lg, st->lg, sizeof st->warm_lg);
    st->has_warm = 1;
  }
  return status;
}

/* FHOCP.solve_request with the paper's reference, into st->res: the i = 0 row first (a
 * violated one: u_bar repeated, evaluated, status infeasible_x0; with SOFT the softened phase
 * at once), then the hard phase, and with SOFT the softened one when the hard one had no
 * answer (soften_after), from the same guess and warm start */
static void solve(law_state *st, const double *xhat, const double *u_init) {
  if (x0_violation(xhat, st->bnd) > CT_FEAS_TOL) {
    if (SOFT) {
      solve_phase(st, xhat, u_init, 1);
      return;
    }
    double ubar_seq[NH * NU];
    for (int i = 0; i < NH; i++) memcpy(ubar_seq + i * NU, st->u_bar, NU * sizeof(double));
    evaluate(st, xhat, ubar_seq, CTL_INFEASIBLE_X0, &st->res);
    return;
  }
#if SOFT
  double w0[NW], lx0[NW], lg0[NG];   /* the warm start, for the softened phase */
  const int had_warm = st->has_warm;
  memcpy(w0, st->warm_w, sizeof w0);
  memcpy(lx0, st->warm_lx, sizeof lx0);
  memcpy(lg0, st->warm_lg, sizeof lg0);
#endif
  const int status = solve_phase(st, xhat, u_init, 0);
#if SOFT
  if (st->res.success || !soften_after(status)) return;
  st->has_warm = had_warm;
  memcpy(st->warm_w, w0, sizeof w0);
  memcpy(st->warm_lx, lx0, sizeof lx0);
  memcpy(st->warm_lg, lg0, sizeof lg0);
  solve_phase(st, xhat, u_init, 1);
#else
  (void)status;
#endif
}

/* RobustMPC.make_step: u_k = k^MPC(x_hat, e_o) (eq:mpc), the candidate of the proof (the
 * plan shifted with u_bar appended, u_bar repeated at first; the governor's feasible
 * candidate when it moved the set-point, which the solve starts from) applied when the solve
 * fails, unless the solver's iterate is feasible and no costlier (suboptimal MPC) */
static void make_step(law_state *st, const double *xhat, double *u) {
  double *cand = st->cand;
  if (st->has_gcand)
    memcpy(cand, st->gcand, sizeof st->cand);
  else
    shifted_candidate(cand, st->plan, st->has_plan, st->u_bar);
  prefix_impose(st->prefix, cand);   /* the inputs already applied, as they were */
  solve(st, xhat, st->has_gcand ? st->gcand : 0);
  ctl_result *res = &st->res;
  int use = res->success, fallback = 0;
  const ctl_result *applied = res;
  st->cand_feasible = 1;
  if (!use) {
    evaluate(st, xhat, cand, CTL_OTHER, &st->chk);
    use = take_iterate(res, &st->chk, &st->cand_feasible, &fallback);
    if (!use) applied = &st->chk;
  }
  keep_plan(st->plan, st->prefix, use ? res->u : cand, !use, u);
  st->has_plan = 1;
  step_done(st->uprev, &st->has_uprev, u, &st->last, res, applied, fallback);
}

/* ---------------------------------------------------------------- the law's interface */
static void law_reset(law_state *st, gk_ws *ws) {
  memset(st, 0, sizeof *st);
  st->ws = ws;
  st->opts = sqp_options();
  st->alpha = NAN;
  last_reset(&st->last);
  st->beta = CT_BETA;
  st->rate = CT_SETPOINT_RATE;
  st->lam_max = 1.0;
}

/* PaperLaw.disturbance_moved: the reference of the FHOCP's set-point again under the
 * disturbances now held in the biases (the kernel's equilibrium with the thread's shift), the
 * plan moved by the same input change; the request refused as unreachable and the governor's
 * kept equilibrium forgotten; an unreachable set-point gives way to the closest reachable
 * output (the last reference kept when that one fails the checks too) */
__attribute__((unused)) static void law_disturbance_moved(law_state *st) {
  double x[NX], u[NU], alpha;
  st->has_unreachable = 0;
  st->has_target = 0;
  if (!st->has_model || !st->has_reference) return;
  if (reference_of(st, st->y_model, x, u, &alpha) != 0) {
    double xe[NX], ue[NU], ye[NY];
    st->moved_refused = 1;
    PFX(equilibrium)(st->ws, st->y_model, xe, ue);
    PFX(output)(xe, ye);
    if (reference_of(st, ye, x, u, &alpha) != 0) return;
    memcpy(st->y_model, ye, sizeof ye);
  }
  if (st->has_plan)
    for (int i = 0; i < NH; i++)
      for (int j = 0; j < NU; j++)
        st->plan[i * NU + j] = gk_clip1(st->plan[i * NU + j] + (u[j] - st->u_bar[j]));
  memcpy(st->x_bar, x, sizeof x);
  memcpy(st->u_bar, u, sizeof u);
  st->alpha = alpha;
}

/* PaperLaw.restart: nothing (the next solve starts from the shifted plan) */
__attribute__((unused)) static void law_restart(law_state *st) { (void)st; }

/* PaperLaw.applied: the inputs the plant got (normalised), u_{-1} of the next step */
static void law_applied(law_state *st, const double *u) {
  memcpy(st->uprev, u, sizeof st->uprev);
  st->has_uprev = 1;
}

/* the paper's law takes no operator limits on its outputs (mpc_operating.py): no room */
static int law_room(const law_state *st, double *slack) {
  (void)st; (void)slack;
  return 0;
}

/* PaperLaw.step: u (normalised) at x_hat, e_o for the measured y and the set-point yr, the
 * FHOCP from xstart (x_hat, or x_hat predicted over the inputs' shortest dead time) with the
 * inputs already applied in prefix and the operator's terms ops; with no admissible set-point
 * to start from, u is left as it came (controller.c: the inputs held, the box's middle
 * before any) */
static void law_step(law_state *st, const double *xhat, const double *xstart,
                     const ctl_prefix *prefix, const ctl_ops *ops, double e_o, const double *y,
                     const double *yr, double *u, int *warnings) {
  st->prefix = prefix;
  st->ops = ops;
  operator_bounds(ops, e_o, st->bnd);   /* (the governor's feasibility test reads them) */
  if (st->moved_refused) {
    *warnings |= CTL_WARN_SETPOINT_REJECTED;
    st->moved_refused = 0;
  }
  if (update_reference(st, xhat, xstart, y, yr, warnings) != 0) {   /* u as it came: held */
    st->last.status = CTL_OTHER;
    st->last.fallback = 1;
    st->last.iterations = 0;
    return;
  }
  make_step(st, xstart, u);
  memcpy(st->last.y_target, st->y_model, sizeof st->last.y_target);
}

/* where tunable parameter i (LAW_P_*) lives, NULL for an unknown one */
static double *law_parameter(law_state *st, int i) {
  gk_mem *m = &st->ws->mem;
  if (CT_OFFSET_FREE && i == LAW_P_OFFSET_FILTER) return &st->beta;
  if (i >= LAW_P_R && i < LAW_P_DU) return m->rw + (i - LAW_P_R) * (NU + 1);
#if HAS_DU
  if (i >= LAW_P_DU && i < LAW_P_RATE) return m->dw + (i - LAW_P_DU);
#endif
  if (CT_RATE_TUNABLE && i == LAW_P_RATE) return &st->rate;
  return 0;
}

/* why the value of tunable parameter i (a known one) is refused; NULL: accepted */
static const char *law_refuse(const law_state *st, int i, double value) {
  if (CT_OFFSET_FREE && i == LAW_P_OFFSET_FILTER)
    return value > 0.0 && value <= 1.0 ? 0 : "must be in (0, 1]";
  if (i < LAW_P_DU) return refuse_r(st->ws, i - LAW_P_R, value);
  if (i < LAW_P_RATE) return value >= 0.0 && isfinite(value) ? 0 : "must be a finite weight >= 0";
  return value > 0.0 && isfinite(value) ? 0 : "must be a finite rate > 0";
}
