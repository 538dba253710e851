/* Part of the compiled FHOCP kernel (controllers/kernel/compiled_kernel.py joins the
 * generated header, gru_fhocp.h and the parts into one translation unit): the softened rows
 * (SOFT; controllers/ocp/soft.py): their terms in f, g and the derivatives, the instance's
 * phase (set_soft) and a plan's slacks (plan_slacks). */
#if SOFT
/* The softened rows' terms (controllers/ocp/soft.py, Slacks): the slacks eps = w[IS ..]
 * (one per row of L, then the terminal set's), the penalty rho sum eps + rho2 sum eps^2 with
 * the instance's weights (0 in the hard phase: PFX(set_soft)), -eps_j on row j's rows of
 * every stage (and on Y_s's row j with HAS_ASS), -/+ eps_T on the terminal rows
 * x_N - x_ref -/+ t */
static double soft_penalty(double rho, double rho2, const double *e) {
  double s1 = 0.0, s2 = 0.0;
  for (int j = 0; j < NSL; j++) s1 += e[j];
  for (int j = 0; j < NSL; j++) s2 += e[j] * e[j];
  return rho * s1 + rho2 * s2;
}

static void soft_constraints(const double *e, double *g) {
  const int r0 = (NH - 1) * NQ;
  for (int i = 1; i < NH; i++)
    for (int a = 0; a < NQ; a++) g[(i - 1) * NQ + a] -= e[a];
  for (int k = 0; k < NX; k++) {
    g[r0 + k] -= e[NQ];
    g[r0 + NX + k] += e[NQ];
  }
#if HAS_ASS
  for (int a = 0; a < NQ; a++) g[r0 + 2 * NX + a] -= e[a];
#endif
}

/* the slacks' columns of the column-major NG x NW Jacobian */
static void soft_jacobian(double *J) {
  const int r0 = (NH - 1) * NQ;
  for (int i = 1; i < NH; i++)
    for (int a = 0; a < NQ; a++) J[(IS + a) * NG + (i - 1) * NQ + a] = -1.0;
  for (int k = 0; k < NX; k++) {
    J[(IS + NQ) * NG + r0 + k] = -1.0;
    J[(IS + NQ) * NG + r0 + NX + k] = 1.0;
  }
#if HAS_ASS
  for (int a = 0; a < NQ; a++) J[(IS + a) * NG + r0 + 2 * NX + a] = -1.0;
#endif
}

/* the slacks' entries of the Lagrangian's gradient: rho (1 + 2 eps) + lam_x - the rows'
 * multipliers (their coefficients -1, the terminal rows' -/+ 1) */
static void soft_lagrangian_gradient(const gk_ws *ws, const double *w, const double *lam_x,
                                     const double *lg, double *gl) {
  const int r0 = (NH - 1) * NQ;
  const double rho = ws->mem.slw, rho2 = ws->mem.slq;
  for (int a = 0; a < NQ; a++) {
    double s = rho + 2.0 * rho2 * w[IS + a] + lam_x[IS + a];
    for (int i = 1; i < NH; i++) s -= lg[(i - 1) * NQ + a];
#if HAS_ASS
    s -= lg[r0 + 2 * NX + a];
#endif
    gl[IS + a] = s;
  }
  double s = rho + 2.0 * rho2 * w[IS + NQ] + lam_x[IS + NQ];
  for (int k = 0; k < NX; k++) s += lg[r0 + NX + k] - lg[r0 + k];
  gl[IS + NQ] = s;
}
#endif

/* the instance's softened-row weights: the design's (on, the softened phase) or 0 (the hard
 * phase, the slacks fixed at 0 by their bounds); controllers/ocp/soft.py */
EXPORT void PFX(set_soft)(gk_ws *ws, int on) {
#if SOFT
  ws->mem.slw = on ? SLW : 0.0;
  ws->mem.slq = on ? SLQ : 0.0;
#else
  (void)ws; (void)on;
#endif
}

/* The smallest slacks of the plan at (w, p) into w[IS ..] (SOFT, controllers/ocp/soft.py
 * Slacks.initial; nothing without SOFT): each row's largest excess over i >= 1 against bnd
 * (NH x NL, with HAS_ASS one more row: Y_s's on x_s), the terminal set's max(0, gap -
 * alpha); returns the gap |x_N - x_ref|inf (terminal_gap) */
EXPORT double PFX(plan_slacks)(gk_ws *ws, double *w, const double *p, const double *bnd,
                               double alpha) {
  const double gap = PFX(terminal_gap)(ws, w, p);
#if SOFT
  const double *X = ws->mem.X;
  for (int j = 0; j < NL; j++) {
    double e = 0.0;
    for (int i = 1; i < NH; i++) {
      double s = 0.0;
      for (int k = 0; k < NX; k++) s += LUO[j * NX + k] * X[i * NX + k];
      if (s - bnd[i * NL + j] > e) e = s - bnd[i * NL + j];
    }
#if HAS_ASS
    double s = 0.0;
    for (int k = 0; k < NX; k++) s += LUO[j * NX + k] * ws->mem.xs[k];
    if (s - bnd[NH * NL + j] > e) e = s - bnd[NH * NL + j];
#endif
    w[IS + j] = e;
  }
  w[IS + NL] = fmax(0.0, gap - alpha);
#else
  (void)w; (void)bnd; (void)alpha;
#endif
  return gap;
}
