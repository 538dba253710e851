/* controllers/laws/paper/governor.c: the paper's law's admissible reference governor in C
 * (CT_GOVERNOR, the Python law's default), joined after controllers/laws/paper/law.c (whose
 * law_state, set-point checks and references it uses, and whose update_reference calls govern
 * after the first set-point).
 * It is the C twin of controllers/laws/paper/governor.py ReferenceGovernor with PaperLaw._govern
 * (controllers/laws/paper/law.py), in the same order of kernel calls:
 *
 *   govern      PaperLaw._govern and ReferenceGovernor.govern: a request outside the theory
 *               or unreachable refused; lambda_max adapted to the last solve
 *   gov_step    ReferenceGovernor.step: the largest fraction of the step, down to
 *               lambda_max / 2^(levels - 1), with an admissible equilibrium and a feasible
 *               candidate (the solve's initial guess and fallback, paper/law.c make_step);
 *               with more outputs than inputs along the surface of equilibrium outputs
 *               (gov_target: ReferenceGovernor.target)
 *   gov_newton  ReferenceGovernor.newton: the kernel's PFX(eq_newton)
 *   gov_feasible ReferenceGovernor.feasible: the kernel's PFX(assess)
 *
 * The equilibria are the kernel's (PFX(eq_newton), PFX(steady), PFX(equilibrium)), which the
 * Python governor calls too, so that the same measurements give the same inputs
 * (tests/cosim/adapters/test_controller_export.py).
 */
static const double GOV_ZERO_U[NU];

/* ReferenceGovernor.newton: the equilibrium with output y by the kernel's Newton from
 * (x0, u0) into x, u; 0, or 1 when it does not converge or leaves |u|inf <= 1 (kernel_lib.py
 * eq_newton) */
static int gov_newton(const double *y, const double *x0, const double *u0, double *x,
                      double *u) {
  if (PFX(eq_newton)(y, x0, u0, CT_EQ_NEWTON_MAX_ITER, CT_EQ_NEWTON_TOL, x, u) != 0) return 1;
  double umax = 0.0;
  for (int j = 0; j < NU; j++) umax = fmax(umax, fabs(u[j]));
  return umax > 1.0;
}

/* ReferenceGovernor.feasible: the sequence u satisfies every constraint of eq:optimization
 * from x_hat (the output rows at i >= 1, the terminal set |x_N - xb|inf <= alpha) */
static int gov_feasible(law_state *st, const double *xhat, const double *u, const double *xb,
                        double alpha) {
  gk_assessment out;
  PFX(assess)(st->ws, xhat, u, xb, GOV_ZERO_U, GOV_ZERO_U, st->bnd, alpha, st->gx, &out);
  return !(out.violation_rows > 0.0) && out.terminal_distance <= alpha;
}

#if NU < NY
/* ReferenceGovernor.target: the equilibrium (x_bar, u_bar)(r) into st (kept for the last r):
 * the Newton from the current reference, else the multi-start search; 0 when r is not
 * reachable */
static int gov_target(law_state *st, const double *r) {
  if (!st->has_target || memcmp(r, st->target_r, sizeof st->target_r) != 0) {
    memcpy(st->target_r, r, sizeof st->target_r);
    st->has_target = 1;
    st->target_ok =
        gov_newton(r, st->x_bar, st->u_bar, st->target_x, st->target_u) == 0 ||
        PFX(equilibrium)(st->ws, r, st->target_x, st->target_u) == 0;
  }
  return st->target_ok;
}
#endif

/* ReferenceGovernor.step: move the FHOCP's set-point from st->y_model towards r by the
 * largest of lam_max, lam_max/2, ... (CT_GOV_LEVELS values) whose equilibrium passes the
 * set-point checks and has a feasible candidate (the plan shifted with u_bar(v+) appended,
 * or that offset by u_bar(v+) - u_bar(v)) into st->gcand; the reference written. Returns the
 * fraction moved, 0 (the reference as it was) when none. */
static double gov_step(law_state *st, const double *xhat, const double *r, double lam_max) {
  if (!st->has_plan) return 0.0;
#if NU < NY
  if (!gov_target(st, r)) return 0.0;
#endif
  double lam = lam_max;
  for (int level = 0; level < CT_GOV_LEVELS; level++) {
    double y[NY], xb[NX], ub[NU], alpha;
#if NU < NY
    int ok;
    if (lam == 1.0) {
      memcpy(y, r, sizeof y);
      memcpy(xb, st->target_x, sizeof xb);
      memcpy(ub, st->target_u, sizeof ub);
      ok = admissible(y, &alpha);
    } else {   /* the equilibrium output of u_bar(v) + lam (u_bar(r) - u_bar(v)) */
      for (int j = 0; j < NU; j++) ub[j] = st->u_bar[j] + lam * (st->target_u[j] - st->u_bar[j]);
      ok = PFX(steady)(st->ws, ub, st->x_bar, xb) == 0;
      if (ok) {
        PFX(output)(xb, y);
        ok = admissible(y, &alpha);
      }
    }
#else
    for (int a = 0; a < NY; a++) y[a] = st->y_model[a] + lam * (r[a] - st->y_model[a]);
    const int ok = admissible(y, &alpha) && gov_newton(y, st->x_bar, st->u_bar, xb, ub) == 0;
#endif
    if (ok) {
      double *cand = st->gcand;
      for (int option = 0; option < 2; option++) {
        shifted_candidate(cand, st->plan, 1, ub);
        if (option == 1)
          for (int c = 0; c < NH * NU; c++)
            cand[c] = gk_clip1(cand[c] + (ub[c % NU] - st->u_bar[c % NU]));
        prefix_impose(st->prefix, cand);   /* the inputs already applied stay as they were */
        if (gov_feasible(st, xhat, cand, xb, alpha)) {
          memcpy(st->y_model, y, sizeof y);
          memcpy(st->x_bar, xb, sizeof xb);
          memcpy(st->u_bar, ub, sizeof ub);
          st->alpha = alpha;
          return lam;
        }
      }
    }
    lam *= 0.5;
  }
  return 0.0;
}

/* PaperLaw._govern with ReferenceGovernor.govern: the FHOCP's set-point moved towards the
 * admissible target; a target outside the theory, or one no input in the box reaches (the
 * kernel's Newton, then its multi-start search), is refused (CTL_WARN_SETPOINT_REJECTED once
 * per request) and the last set-point kept. lambda_max halves (not below CT_GOV_LAM_MIN)
 * after a solve that did not converge and grows by CT_GOV_LAM_GROW (not above 1) after a
 * converged one that followed a move. */
static void govern(law_state *st, const double *xhat, const double *target, int changed,
                   int *warnings) {
  double alpha, x[NX], u[NU];
  if (!admissible(target, &alpha)) {
    if (changed) *warnings |= CTL_WARN_SETPOINT_REJECTED;
    return;
  }
  if (!changed && st->has_unreachable) {
    int same = 1;
    for (int a = 0; a < NY; a++) same &= target[a] == st->unreachable[a];
    if (same) return;   /* still the unreachable request: refused again */
  }
  if (changed && gov_newton(target, st->x_bar, st->u_bar, x, u) != 0 &&
      reference_of(st, target, x, u, &alpha) != 0) {
    *warnings |= CTL_WARN_SETPOINT_REJECTED;
    memcpy(st->unreachable, target, sizeof st->unreachable);
    st->has_unreachable = 1;
    return;
  }
  if (st->has_plan && !st->res.success)
    st->lam_max = fmax(st->lam_max * 0.5, CT_GOV_LAM_MIN);
  else if (st->moved && st->has_plan)
    st->lam_max = fmin(1.0, st->lam_max * CT_GOV_LAM_GROW);
  const double lam = gov_step(st, xhat, target, st->lam_max);
  st->moved = lam > 0.0;
  st->has_gcand = st->moved;
}
