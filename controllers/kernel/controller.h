/* controller.h: what the exported controller's two parts share (controllers/kernel/
 * controller_source.py joins the kernel, the controller's constants, this file, the law's
 * C files -- of controllers/laws/<name>/: tracking/law.c, or paper/law.c and
 * paper/governor.c -- and controller.c into one translation unit).
 *
 * A law file defines, for controller.c:
 *
 *   law_state           everything the law keeps between steps (its FHOCP's buffers, warm
 *                       start, plan, set-point handling), the kernel's solver instance ws
 *                       included; with `last` (ctl_last), what its last step gave
 *   LAW_N_PARAMETERS    how many tunable parameters it has (CT_NPARAM must agree)
 *   law_reset(ls, ws)   a new run
 *   law_step(ls, xhat, xstart, prefix, e_o, y, yr, u, warnings)
 *                       u_k (normalised) for the estimate x_hat (the FHOCP from xstart: x_hat
 *                       predicted over the inputs' shortest dead time; its inputs already
 *                       applied in prefix, ctl_prefix), the bound e_o, the measured output y
 *                       and the set-point yr (normalised), raising CTL_WARN_* bits; u comes
 *                       holding the inputs applied last (left so: they are held)
 *   law_disturbance_moved(ls), law_restart(ls), ls->cand_feasible
 *                       with measured disturbances (CT_NQD > 0)
 *   law_parameter(ls, i), law_refuse(ls, i, value)
 *                       where tunable parameter i lives (NULL: none), why a value is refused
 *                       (NULL: accepted)
 *
 * The helpers below are marked unused: a law uses those it needs (a law without an FHOCP
 * solve, tests/controllers/laws/steady/law.c, uses none of them).
 */
#ifndef CT_NPARAM
#error "the controller's constants (controller_source.py) must precede controller.h"
#endif

/* a helper a law may use (unused ones are no warning) */
#define CTL_HELPER __attribute__((unused)) static

/* the step's status codes: controllers/ocp/solve_status.py status_code */
enum ctl_status {
  CTL_OPTIMAL = 0, CTL_INFEASIBLE_X0 = 1, CTL_INFEASIBLE = 2, CTL_LIMIT = 3,
  CTL_RESIDUAL_CHECK_FAILED = 4, CTL_OTHER = 5
};
/* warnings a step may raise (a bit mask cleared by ctl_take_warnings; fmus/controller/model.c
 * logs them): a non-finite measurement or set-point; a first measured output no input in
 * the box reaches; (the paper's law) a set-point outside the theory refused, the last
 * admissible one kept; no admissible set-point at all to start from */
enum {
  CTL_WARN_NONFINITE_INPUT = 1, CTL_WARN_UNREACHABLE_START = 2,
  CTL_WARN_SETPOINT_REJECTED = 4, CTL_WARN_NO_ADMISSIBLE_SETPOINT = 8
};

/* one solve or one answer check (controllers/ocp/fhocp_result.py FHOCPResult); us and xs:
 * the artificial steady state (the tracking law) */
typedef struct ctl_result {
  double u[NH * NU], us[NU], xs[NX], x[(NH + 1) * NX];
  double cost, cv, tv, defect, softened;   /* softened: FHOCPResult.softened (SOFT) */
  int success, feasible, status, iterations;
} ctl_result;

/* what a law's last step gave (controller.c reports it): the solve's status, whether the
 * candidate was applied, the SQP iterations, the model's output at the next sample under the
 * applied plan and the steady output the FHOCP steered the model to (the paper's law: its
 * set-point, the governed one; the tracking law: the artificial steady state's output y_s;
 * the Python law's diagnostics y_model_<output>), normalised */
typedef struct ctl_last {
  double y_pred[NY], y_target[NY];
  int status, fallback, iterations;
} ctl_last;

/* The FHOCP's inputs already applied (controllers/dead_time.py InputPrefix): with inputs whose
 * dead time exceeds the shortest (CT_U_LAG_MAX > 0), stage i of input j is fixed for
 * i < CT_U_LAGS[j] to known[i NU + j], the input applied CT_U_LAGS[j] - i samples ago, and
 * the input applied now is stage CT_U_LAGS[j]; without, nothing is fixed and it is stage 0.
 * controller.c sets it each step, the laws read it (prefix_impose, prefix_bound,
 * prefix_applied). */
typedef struct ctl_prefix {
#if CT_U_LAG_MAX
  double known[CT_U_LAG_MAX * NU];
#else
  char none;
#endif
} ctl_prefix;

/* InputPrefix.impose: the plan u (NH x NU) with its fixed stages set */
CTL_HELPER void prefix_impose(const ctl_prefix *pf, double *u) {
#if CT_U_LAG_MAX
  for (int i = 0; i < CT_U_LAG_MAX; i++)
    for (int j = 0; j < NU; j++)
      if (i < CT_U_LAGS[j]) u[i * NU + j] = pf->known[i * NU + j];
#else
  (void)pf; (void)u;
#endif
}

/* InputPrefix.bound: the fixed stages in the solver's bounds (u_i's entries of w: i NU + j) */
CTL_HELPER void prefix_bound(const ctl_prefix *pf, double *lbx, double *ubx) {
#if CT_U_LAG_MAX
  for (int i = 0; i < CT_U_LAG_MAX; i++)
    for (int j = 0; j < NU; j++)
      if (i < CT_U_LAGS[j]) lbx[i * NU + j] = ubx[i * NU + j] = pf->known[i * NU + j];
#else
  (void)pf; (void)lbx; (void)ubx;
#endif
}

/* InputPrefix.applied: the inputs applied now from the plan (NH x NU) into u */
CTL_HELPER void prefix_applied(const ctl_prefix *pf, const double *plan, double *u) {
  (void)pf;
  for (int j = 0; j < NU; j++) {
#if CT_U_LAG_MAX
    u[j] = plan[CT_U_LAGS[j] * NU + j];
#else
    u[j] = plan[j];
#endif
  }
}

/* before any step */
CTL_HELPER void last_reset(ctl_last *l) {
  for (int a = 0; a < NY; a++) l->y_pred[a] = l->y_target[a] = NAN;
  l->status = CTL_OTHER;
  l->fallback = l->iterations = 0;
}

/* the step whose solve gave res and whose applied plan is applied's (res or the candidate's
 * check) */
CTL_HELPER void last_record(ctl_last *l, const ctl_result *res, const ctl_result *applied,
                        int fallback) {
  l->status = res->status;
  l->fallback = fallback;
  l->iterations = res->iterations;
  PFX(output)(applied->x + NX, l->y_pred);
}

CTL_HELPER int all_finite(const double *a, int n) {
  for (int k = 0; k < n; k++)
    if (!isfinite(a[k])) return 0;
  return 1;
}

/* the status of a failed kernel SQP, as status_code names the solver's own status */
CTL_HELPER int sqp_status_code(int sqp) {
  if (sqp == GK_SQP_MAXIMUM_ITERATIONS_EXCEEDED || sqp == GK_SQP_USER_REQUESTED_STOP)
    return CTL_LIMIT;
  return CTL_OTHER;
}

/* the kernel SQP's options of the design (controllers/kernel/kernel_abi.py SqpOptions) */
CTL_HELPER gk_sqp_opts sqp_options(void) {
  return (gk_sqp_opts){.tol_pr = CT_SQP_TOL_PR, .tol_du = CT_SQP_TOL_DU,
                       .max_iter = CT_SQP_MAX_ITER, .max_iter_ls = CT_SQP_MAX_ITER_LS,
                       .min_step_size = CT_SQP_MIN_STEP, .c1 = CT_SQP_C1,
                       .beta = CT_SQP_BETA, .time_budget = INFINITY,
                       .tol_du_relative = CT_SQP_TOL_DU_RELATIVE,
                       .reuse_step = CT_SQP_REUSE_STEP};
}

/* the tightened output bounds h - a_i e_o - b_i - w_L - L b_o (eq:optimization-constraint;
 * controllers/ocp/fhocp.py FHOCP.tightened_bounds, in numpy's order) into bnd (NH x NL) */
CTL_HELPER void tightened_bounds(double e_o, double *bnd) {
  for (int i = 0; i < NH; i++)
    for (int j = 0; j < NL; j++) {
      double v = CT_H[j] - CT_A[i * NL + j] * e_o;
      v = v - CT_B[i * NL + j];
      v = v - CT_WL[j];
      bnd[i * NL + j] = v - CT_LBO[j];
    }
}

/* the i = 0 row's violation at x_hat (FHOCP.check_x0): it involves x_hat only */
CTL_HELPER double x0_violation(const double *xhat, const double *bnd) {
  double v = -INFINITY;
  for (int j = 0; j < NL; j++) {
    double s = 0.0;
    for (int k = 0; k < NX; k++) s += LUO[j * NX + k] * xhat[k];
    v = fmax(v, s - bnd[j]);
  }
  return v;
}

/* the row-paired output rows i >= 1 of the single-shooting FHOCP's g (controllers/ocp/
 * fhocp_layout.py FHOCPLayout: D U_o x_i, upper and lower L rows per reduced row) into
 * lbg, ubg (the first (NH - 1) NQ entries) */
CTL_HELPER void output_rows(const double *bnd, double *lbg, double *ubg) {
  for (int i = 1; i < NH; i++)
    for (int r = 0; r < NQ; r++) {
      const int pos = (i - 1) * NQ + r;
      ubg[pos] = bnd[i * NL + CT_PAIR_UP[r]];
      if (CT_PAIR_LO[r] >= 0) lbg[pos] = -bnd[i * NL + CT_PAIR_LO[r]];
    }
}

/* the output rows', input box's and terminal set's violations of an assessment with the
 * terminal radius alpha into r (controllers/ocp/fhocp_result.py set_residuals); soften: the
 * softened phase's answer, whose rows' excess is a price, not a failure (route_softened) */
CTL_HELPER void set_residuals(ctl_result *r, const gk_assessment *out, double alpha,
                              int soften) {
  r->cv = fmax(fmax(0.0, out->violation_first), fmax(out->violation_rows, out->u_max - 1.0));
  r->tv = fmax(0.0, out->terminal_distance - alpha);
  r->softened = 0.0;
  if (soften) {
    r->softened = fmax(r->cv, r->tv);
    r->cv = fmax(0.0, out->u_max - 1.0);
    r->tv = 0.0;
  }
}

/* a row the law adds beyond the output rows and the terminal set (the tracking law's Y_s)
 * exceeded by excess: a violation, or for the softened phase's answer part of its excess */
CTL_HELPER void extra_row(ctl_result *r, double excess, int soften) {
  if (soften) r->softened = fmax(r->softened, excess);
  else r->cv = fmax(r->cv, excess);
}

/* the variable bounds of the single-shooting FHOCP: the inputs' box, 0 <= t <= alpha, the
 * slacks (SOFT) 0 <= eps, free in the softened phase (soften), fixed at 0 in the hard one */
CTL_HELPER void variable_bounds(double *lbx, double *ubx, double alpha, int soften) {
  for (int c = 0; c < NW; c++) {
    lbx[c] = c < IT ? -1.0 : 0.0;
    ubx[c] = c < IT ? 1.0 : (c == IT ? alpha : (soften ? INFINITY : 0.0));
  }
}

/* a softened FHOCP solves its softened phase after the hard one ended so (controllers/ocp/
 * solve_status.py SOFTEN_AFTER): its QP infeasible or failed */
CTL_HELPER int soften_after(int sqp_status) {
  return SOFT && (sqp_status == GK_SQP_QP_INFEASIBLE || sqp_status == GK_SQP_QP_FAILED);
}

/* the candidate of the proof of th:feasibility-stability into cand (NH x NU): the plan
 * shifted by one stage with u_end appended (the reference input: u_bar, or the tracking law's
 * u_s), u_end repeated before any plan (RobustMPC.candidate, TrackingMPC.make_step) */
CTL_HELPER void shifted_candidate(double *cand, const double *plan, int has_plan,
                              const double *u_end) {
  if (has_plan) {
    memcpy(cand, plan + NU, (NH - 1) * NU * sizeof(double));
    memcpy(cand + (NH - 1) * NU, u_end, NU * sizeof(double));
  } else {
    for (int i = 0; i < NH; i++) memcpy(cand + i * NU, u_end, NU * sizeof(double));
  }
}

/* after a failed solve res, with chk the candidate's check: whether the solver's iterate is
 * applied instead of the candidate (controllers/laws/paper/mpc.py PaperMPC.make_step,
 * controllers/laws/tracking/mpc.py TrackingMPC.make_step: suboptimal MPC, a feasible
 * iterate no costlier than a feasible candidate) */
CTL_HELPER int keeps_iterate(const ctl_result *res, const ctl_result *chk) {
  const int feasible = chk->cv <= CT_FEAS_TOL && chk->tv <= CT_FEAS_TOL;
  return res->feasible && (!feasible || res->cost <= chk->cost);
}

/* keeps_iterate after a failed solve res, chk the candidate's check, with what the law
 * records: whether the candidate was feasible (StepRecord.candidate_feasible) and whether it
 * falls back on it */
CTL_HELPER int take_iterate(const ctl_result *res, const ctl_result *chk, int *cand_feasible,
                            int *fallback) {
  *cand_feasible = chk->cv <= CT_FEAS_TOL && chk->tv <= CT_FEAS_TOL;
  const int use = keeps_iterate(res, chk);
  *fallback = !use;
  return use;
}

/* a law's step is done: the input applied now (u_{-1} of the next step's input-rate term)
 * and what the step gave (last_record) */
CTL_HELPER void step_done(double *uprev, int *has_uprev, const double *u, ctl_last *last,
                          const ctl_result *res, const ctl_result *applied, int fallback) {
  memcpy(uprev, u, NU * sizeof(double));
  *has_uprev = 1;
  last_record(last, res, applied, fallback);
}

/* the plan the law keeps (the solver's, or the candidate on a fallback, whose input is
 * clipped to the box) into plan, and the input applied now into u (prefix_applied) */
CTL_HELPER void keep_plan(double *plan, const ctl_prefix *pf, const double *chosen,
                          int candidate, double *u) {
  memcpy(plan, chosen, NH * NU * sizeof(double));
  prefix_applied(pf, chosen, u);
  if (candidate)
    for (int j = 0; j < NU; j++) u[j] = gk_clip1(u[j]);
}

/* the answer check's judgement (controllers/ocp/fhocp_result.py set_residuals, judge) of the
 * solver's w into r, the assessment of (u, x) already there; iterations the SQP's */
CTL_HELPER void judge(ctl_result *r, const double *w, int sqp_status, const gk_sqp_info *info) {
  const int ok = sqp_status == GK_SQP_SOLVE_SUCCEEDED;
  r->iterations = info->iterations + info->discarded_iterations;
  r->feasible = all_finite(w, NW) && r->cv <= CT_FEAS_TOL && r->tv <= CT_FEAS_TOL &&
                r->defect <= CT_DEFECT_TOL;
  r->success = ok && r->feasible;
  r->status = r->success ? CTL_OPTIMAL
              : ok       ? CTL_RESIDUAL_CHECK_FAILED
                         : sqp_status_code(sqp_status);
}

/* a (NU x NU) is positive definite: its Cholesky factorisation exists */
CTL_HELPER int positive_definite(const double *a) {
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

/* why a value of R's diagonal entry j is refused (NULL: R stays positive definite) */
CTL_HELPER const char *refuse_r(const gk_ws *ws, int j, double value) {
  double r[NU * NU];
  memcpy(r, ws->mem.rw, sizeof r);
  r[j * (NU + 1)] = value;
  if (!(isfinite(value) && positive_definite(r)))
    return "must keep R positive definite (a finite diagonal weight > 0)";
  return 0;
}

/* ---------------------------------------------------------------- the operator
 * What the operator's settings impose on one solve (controllers/ocp/operator_terms.py
 * OperatorTerms, built by operator.c): u_0 in [lo0, hi0], the other free inputs and u_s
 * (HAS_ASS) in [lo, hi], the output rows' narrowing dh (eq:operator-rows); active: the
 * settings are engaged (else the FHOCP as designed) */
typedef struct ctl_ops {
  double lo0[NU], hi0[NU], lo[NU], hi[NU], dh[NL];
  int active;
} ctl_ops;

/* OperatorTerms.bound: the operator's bounds intersected with the solver's (in place) */
CTL_HELPER void ops_bound(const ctl_ops *o, double *lbx, double *ubx) {
  if (!o || !o->active) return;
  for (int i = 0; i < NM; i++)
    for (int j = 0; j < NU; j++) {
      const double lo = i == 0 ? o->lo0[j] : o->lo[j], hi = i == 0 ? o->hi0[j] : o->hi[j];
      lbx[i * NU + j] = fmax(lbx[i * NU + j], lo);
      ubx[i * NU + j] = fmin(ubx[i * NU + j], hi);
    }
#if HAS_ASS
  for (int j = 0; j < NU; j++) {
    lbx[NUU + j] = fmax(lbx[NUU + j], o->lo[j]);
    ubx[NUU + j] = fmin(ubx[NUU + j], o->hi[j]);
  }
#endif
}

/* OperatorTerms.clip: the first NM stages of a plan w inside the operator's bounds */
CTL_HELPER void ops_clip(const ctl_ops *o, double *w) {
  if (!o || !o->active) return;
  for (int i = 0; i < NM; i++)
    for (int j = 0; j < NU; j++) {
      const double lo = i == 0 ? o->lo0[j] : o->lo[j], hi = i == 0 ? o->hi0[j] : o->hi[j];
      w[i * NU + j] = fmin(fmax(w[i * NU + j], lo), hi);
    }
}

/* the tightened output bounds under the operator's narrowing: h - dh in place of h
 * (FHOCP.tightened_bounds with FHOCP.narrowing), in numpy's order */
CTL_HELPER void operator_bounds(const ctl_ops *o, double e_o, double *bnd) {
  if (!o || !o->active) {
    tightened_bounds(e_o, bnd);
    return;
  }
  for (int i = 0; i < NH; i++)
    for (int j = 0; j < NL; j++) {
      double v = (CT_H[j] - o->dh[j]) - CT_A[i * NL + j] * e_o;
      v = v - CT_B[i * NL + j];
      v = v - CT_WL[j];
      bnd[i * NL + j] = v - CT_LBO[j];
    }
}

/* the move limit's rows (HAS_MOVE, eq:move-constraint; controllers/ocp/input_rate.py
 * MoveRows): their bounds +-Delta, the last NMV rows of g */
CTL_HELPER void move_rows(double *lbg, double *ubg) {
#if HAS_MOVE
  for (int i = 0; i < NM; i++)
    for (int j = 0; j < NU; j++) {
      lbg[RMV + i * NU + j] = -CT_MOVE_DELTA[j];
      ubg[RMV + i * NU + j] = CT_MOVE_DELTA[j];
    }
#else
  (void)lbg; (void)ubg;
#endif
}
