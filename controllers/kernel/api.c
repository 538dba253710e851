/* Part of the compiled FHOCP kernel (controllers/kernel/compiled_kernel.py joins the
 * generated header, gru_fhocp.h and the parts into one translation unit): exported entry points: casadi external functions and a plain C API. */
/* ---------------------------------------------------------------- casadi external API */
static const casadi_int SP_X[3] = {NW, 1, 1}, SP_P[3] = {NP, 1, 1}, SP_1[3] = {1, 1, 1},
                        SP_G[3] = {NG, 1, 1}, SP_J[3] = {NG, NW, 1}, SP_H[3] = {NW, NW, 1};

#define ARG(i, zero) (arg[i] ? arg[i] : (zero))

static int fg_eval(gk_ws *ws, const double **arg, double **res) {
  const double *x = ARG(0, ZERO_W), *p = ARG(1, ZERO_P);
  roll(ws, x, p, 0);
  if (res[0]) res[0][0] = cost(ws, x, p);
  if (res[1]) constraints(ws, x, p, res[1]);
  return 0;
}

static int jac_fg_eval(gk_ws *ws, const double **arg, double **res) {
  const double *x = ARG(0, ZERO_W), *p = ARG(1, ZERO_P);
  roll(ws, x, p, 1);
  if (res[0]) res[0][0] = cost(ws, x, p);
  if (res[1]) gradient(ws, x, p, res[1]);
  if (res[2]) constraints(ws, x, p, res[2]);
  if (res[3]) jacobian(ws, res[3]);
  return 0;
}

HOT static int hess_eval(gk_ws *ws, const double **arg, double **res, int clip) {
  double *Hrm = ws->work.Hrm;
  const double *x = ARG(0, ZERO_W), *p = ARG(1, ZERO_P), *lg = ARG(3, ZERO_G);
  const double lf = arg[2] ? arg[2][0] : 0.0;
  if (!res[0]) return 0;
  roll(ws, x, p, 1);
  hessian(ws, x, p, lf, lg, Hrm);
  int flag = 0;
  if (clip) flag = clip_hessian(ws, Hrm);
  /* column-major output: H is symmetric up to rounding; write the transpose */
  for (int i = 0; i < NW; i++)
    for (int j = 0; j < NW; j++) res[0][j * NW + i] = Hrm[i * NW + j];
  return flag;
}

/* the casadi functions: each call evaluates in a solver instance laid out in casadi's work
 * vector w (memory.c: casadi_ws), timer TIMER of that instance (GK_TIMERS: fg, jac_fg,
 * hess_l, hess_raw) accumulating its time */
#define CASADI_EXTERNAL(F, EVAL, TIMER)                                                      \
  EXPORT int PFX(F)(const double **arg, double **res, casadi_int *iw, double *w, int mem) {   \
    (void)iw; (void)mem;                                                                      \
    if (!w) return 1;                                                                         \
    gk_ws *ws = casadi_ws(w);                                                                 \
    TK_START                                                                                  \
    const int rc = EVAL;                                                                      \
    TK_STOP(TIMER)                                                                            \
    return rc;                                                                                \
  }
CASADI_EXTERNAL(fg, fg_eval(ws, arg, res), 0)
CASADI_EXTERNAL(jac_fg, jac_fg_eval(ws, arg, res), 1)
CASADI_EXTERNAL(hess_l, hess_eval(ws, arg, res, 1), 2)
CASADI_EXTERNAL(hess_raw, hess_eval(ws, arg, res, 0), 3)

/* boilerplate of the casadi external interface for function F with given I/O */
#define CASADI_BOILERPLATE(F, NIN, NOUT, NAMES_IN, NAMES_OUT, SP_IN, SP_OUT)                  \
  EXPORT casadi_int PFX(F##_n_in)(void) { return NIN; }                                       \
  EXPORT casadi_int PFX(F##_n_out)(void) { return NOUT; }                                     \
  EXPORT const char *PFX(F##_name_in)(casadi_int i) {                                         \
    static const char *n[] = NAMES_IN;                                                        \
    return (i >= 0 && i < NIN) ? n[i] : 0;                                                    \
  }                                                                                           \
  EXPORT const char *PFX(F##_name_out)(casadi_int i) {                                        \
    static const char *n[] = NAMES_OUT;                                                       \
    return (i >= 0 && i < NOUT) ? n[i] : 0;                                                   \
  }                                                                                           \
  EXPORT const casadi_int *PFX(F##_sparsity_in)(casadi_int i) {                               \
    static const casadi_int *s[] = SP_IN;                                                     \
    return (i >= 0 && i < NIN) ? s[i] : 0;                                                    \
  }                                                                                           \
  EXPORT const casadi_int *PFX(F##_sparsity_out)(casadi_int i) {                              \
    static const casadi_int *s[] = SP_OUT;                                                    \
    return (i >= 0 && i < NOUT) ? s[i] : 0;                                                   \
  }                                                                                           \
  EXPORT int PFX(F##_work)(casadi_int * sz_arg, casadi_int * sz_res, casadi_int * sz_iw,      \
                           casadi_int * sz_w) {                                               \
    if (sz_arg) *sz_arg = NIN;                                                                \
    if (sz_res) *sz_res = NOUT;                                                               \
    if (sz_iw) *sz_iw = 0;                                                                    \
    if (sz_w) *sz_w = GK_CASADI_W;                                                            \
    return 0;                                                                                 \
  }                                                                                           \
  EXPORT int PFX(F##_checkout)(void) { return 0; } /* the memory is casadi's work vector */  \
  EXPORT void PFX(F##_release)(int mem) { (void)mem; }                                        \
  EXPORT void PFX(F##_incref)(void) {}                                                        \
  EXPORT void PFX(F##_decref)(void) {}

#define LIST(...) {__VA_ARGS__}
CASADI_BOILERPLATE(fg, 2, 2, LIST("x", "p"), LIST("f", "g"), LIST(SP_X, SP_P), LIST(SP_1, SP_G))
CASADI_BOILERPLATE(jac_fg, 2, 4, LIST("x", "p"), LIST("f", "grad_f_x", "g", "jac_g_x"),
                   LIST(SP_X, SP_P), LIST(SP_1, SP_X, SP_G, SP_J))
CASADI_BOILERPLATE(hess_l, 4, 1, LIST("x", "p", "lam_f", "lam_g"), LIST("hess_gamma_x_x"),
                   LIST(SP_X, SP_P, SP_1, SP_G), LIST(SP_H))
CASADI_BOILERPLATE(hess_raw, 4, 1, LIST("x", "p", "lam_f", "lam_g"), LIST("hess_gamma_x_x"),
                   LIST(SP_X, SP_P, SP_1, SP_G), LIST(SP_H))

/* ---------------------------------------------------------------- plain C API (ctypes) */
/* states x_0..x_N (NH+1 x NX) from x0 under u (NH x NU); does not touch the cache */
EXPORT void PFX(simulate)(gk_ws *ws, const double *x0, const double *u, double *x) {
  simulate(x0, u, x, ws->work.sz, ws->work.sr, ws->work.sh);
}

/* the solver's trajectory at (w, p): the cached one when (w, p) matches, else a rollout */
EXPORT void PFX(xtraj)(gk_ws *ws, const double *w, const double *p, double *x) {
  roll(ws, w, p, 0);
  memcpy(x, ws->mem.X, sizeof ws->mem.X);
}

/* The output y = U_o x + b_o (the sum over x first, then b_o: the observer's y_hat, in Python
 * and in the exported controller alike) */
EXPORT void PFX(output)(const double *x, double *y) {
  for (int a = 0; a < NY; a++) {
    double s = 0.0;
    for (int k = 0; k < NX; k++) s += UO[a * NX + k] * x[k];
    y[a] = s + BO[a];
  }
}

/* One GRU step x+ = f(x, u) with extra gate inputs dz, dr (the observer eq:observer, as
 * controllers.gru.step) */
EXPORT void PFX(gru_step)(const double *x, const double *u, const double *dz,
                          const double *dr, double *xn) {
  double z[NX], r[NX], h[NX];
  stage_gates(x, u, dz, dr, z, r, h);
  for (int k = 0; k < NX; k++) xn[k] = z[k] * x[k] + (1.0 - z[k]) * h[k];   /* as numpy */
}

/* The independent check of an input sequence (controllers.ocp.fhocp: FHOCP.cost and
 * FHOCP._residuals on a plain rollout, in one call): states x (NH+1 x NX) from xh under u
 * (NH x NU, used as given), and in out (gk_assessment, controllers/kernel/kernel_abi.py) the cost of
 * eq:optimization-cost with t = |x_N - x_bar|_inf (+ the input-rate term after up = u_{-1}
 * when HAS_DU; up is not read otherwise), the worst i = 0 output row and the worst of the
 * rows i >= 1 (-inf when none), max |u|, |x_N - x_bar|_inf and the active constraints (output
 * rows i >= 1 and the terminal set within 1e-6, inputs with |u| > 1 - 1e-6, as
 * FHOCP._residuals counts them). bnd: the tightened bounds h - a_i e_o - b_i - w_L - L b_o
 * (NH x NL); alpha the terminal set's radius. SOFT (controllers/ocp/soft.py): the cost is
 * the plan's price (Slacks.of_plan, plan_terminal): eps_j the largest excess of row j over
 * i >= 1 beyond SLT (with HAS_ASS also over Y_s's row j, L U_o x_s <= bnd's row NH: bnd is
 * (NH + 1) x NL), eps_T = max(0, |x_N - x_bar|_inf - alpha - SLT), t = alpha when it is
 * positive, else |x_N - x_bar|_inf, and rho sum eps + rho2 sum eps^2 (the design's weights,
 * in either phase). */
static void assess_core(gk_ws *ws, const double *xh, const double *u, const double *xb,
                        const double *ub, const double *up, const double *bnd, double alpha,
                        double *x, gk_assessment *out) {
  simulate(xh, u, x, ws->work.sz, ws->work.sr, ws->work.sh);
  double acc = 0.0;
  for (int i = 0; i < NH; i++) acc = add_quad(acc, x + i * NX, xb, QW, NX, QDIAG);
  for (int i = 0; i < NH; i++) acc = add_quad(acc, u + i * NU, ub, ws->mem.rw, NU, 0);
  double dN = 0.0;
  for (int k = 0; k < NX; k++) {
    const double d = fabs(x[NH * NX + k] - xb[k]);
    if (d > dN || d != d) dN = d;
  }
  double v0 = -INFINITY, v1 = -INFINITY, umax = 0.0;
  double ex[NL + 1];   /* each row's largest excess over i >= 1 (SOFT) */
  for (int j = 0; j < NL + 1; j++) ex[j] = 0.0;
  int act = 0;
  for (int i = 0; i < NH; i++)
    for (int j = 0; j < NL; j++) {
      double s = 0.0;
      for (int k = 0; k < NX; k++) s += LUO[j * NX + k] * x[i * NX + k];
      const double d = s - bnd[i * NL + j];
      if (i == 0) {
        if (d > v0) v0 = d;
      } else {
        if (d > v1) v1 = d;
        if (d > ex[j]) ex[j] = d;
        if (d > -1e-6) act++;
      }
    }
  for (int c = 0; c < NUF; c++) {
    const double a = fabs(u[c]);
    if (a > umax) umax = a;
    if (a > 1.0 - 1e-6) act++;
  }
  if (dN - alpha > -1e-6) act++;
#if SOFT
  const double tN = dN - alpha <= SLT ? dN : fmax(alpha, 0.0);
#if HAS_ASS
  for (int j = 0; j < NL; j++) {   /* Y_s's rows on x_s = xb */
    double s = 0.0;
    for (int k = 0; k < NX; k++) s += LUO[j * NX + k] * xb[k];
    if (s - bnd[NH * NL + j] > ex[j]) ex[j] = s - bnd[NH * NL + j];
  }
#endif
  for (int j = 0; j < NL; j++) ex[j] = fmax(0.0, ex[j] - SLT);
  ex[NL] = fmax(0.0, dN - alpha - SLT);
#else
  const double tN = dN;
#endif
#if HAS_DU
  out->cost = acc + SW * tN * tN + du_cost(ws->mem.dw, u, up, NH);
#else
  (void)up;
  out->cost = acc + SW * tN * tN;
#endif
#if SOFT
  out->cost += soft_penalty(SLW, SLQ, ex);
#else
  (void)ex;
#endif
  out->violation_first = v0;
  out->violation_rows = v1;
  out->u_max = umax;
  out->terminal_distance = dN;
  out->active = act;
  out->defect = 0.0;
  out->steady_residual = 0.0;
}

EXPORT void PFX(assess)(gk_ws *ws, const double *xh, const double *u, const double *xb,
                        const double *ub, const double *up, const double *bnd, double alpha,
                        double *x, gk_assessment *out) {
  assess_core(ws, xh, u, xb, ub, up, bnd, alpha, x, out);
}

/* The check of the solver's answer w at p = (x_hat, x_bar, u_bar[, u_prev]): u = clip(w_u, -1, 1)
 * into uc (NH x NU: the tail of a control horizon at u_s), assess_core of uc into x and out,
 * and out->defect the defect max |x_solver - x| against the solver's own trajectory at (w, p)
 * (the cached rollout). With HAS_ASS (the tracking law, p = (x_hat, x_s0, r[, u_prev])) the
 * reference is x_s(u_s) of the clipped u_s (Newton from x_s0), written to xs (NX), out->cost
 * adds the offset term and the last input's step to u_s (as ArtificialSteadyState.cost), and
 * out->steady_residual is the fixed point residual |f(x_s, u_s) - x_s|inf by a plain GRU step
 * (NaN when Newton failed); without HAS_ASS xs is not written and the residual is 0. */
EXPORT void PFX(assess_w)(gk_ws *ws, const double *w, const double *p, const double *bnd,
                          double alpha, double *uc, double *x, gk_assessment *out,
                          double *xs_out) {
  for (int i = 0; i < NH; i++)
    for (int j = 0; j < NU; j++) {
      const double v = w[UC(i) + j];
      uc[i * NU + j] = v < -1.0 ? -1.0 : (v > 1.0 ? 1.0 : v);
    }
#if HAS_ASS
  double wc[NW], xs[NX], xn[NX];
  for (int c = 0; c < NW; c++) wc[c] = c < NUA ? fmin(fmax(w[c], -1.0), 1.0) : w[c];
  const double *us = wc + NUU;
  roll(ws, wc, p, 0);   /* x_s(u_s): the reference of the check */
  memcpy(xs, ws->mem.xs, sizeof xs);
  assess_core(ws, p, uc, xs, us, UPREV(p), bnd, alpha, x, out);
  const double *ry = p + 2 * NX;
  for (int a = 0; a < NY; a++) {
    double e = BO[a] - ry[a];
    for (int k = 0; k < NX; k++) e += UO[a * NX + k] * xs[k];
    out->cost += (e * ws->mem.tw[a]) * e;
  }
#if HAS_DU
  for (int j = 0; j < NU; j++) {   /* zero with a control horizon: u_{N-1} = u_s */
    const double d = uc[(NH - 1) * NU + j] - us[j];
    out->cost += (d * ws->mem.dw[j]) * d;
  }
#endif
  PFX(gru_step)(xs, us, 0, 0, xn);
  double fp = 0.0;
  for (int k = 0; k < NX; k++) {
    const double e = fabs(xn[k] - xs[k]);
    if (e > fp || e != e) fp = e;
  }
  out->steady_residual = fp;
  memcpy(xs_out, xs, sizeof xs);
#else
  (void)xs_out;
  assess_core(ws, p, uc, XREF(ws, p), UREF(w, p), UPREV(p), bnd, alpha, x, out);
#endif
  roll(ws, w, p, 0);
  double d = 0.0;
  for (int c = 0; c < (NH + 1) * NX; c++) {
    const double e = fabs(ws->mem.X[c] - x[c]);
    if (e > d || e != e) d = e;
  }
  out->defect = d;
}

/* |x_N - x_ref|inf of the rollout at (w, p) (x_ref: x_bar, or x_s(u_s) with HAS_ASS), the
 * smallest feasible terminal slack t; the rollout stays cached for the SQP (t is not part of
 * its key) */
EXPORT double PFX(terminal_gap)(gk_ws *ws, const double *w, const double *p) {
  roll(ws, w, p, 0);
  const double *xN = ws->mem.X + NH * NX, *xb = XREF(ws, p);
  double d = 0.0;
  for (int k = 0; k < NX; k++) {
    const double e = fabs(xN[k] - xb[k]);
    if (e > d || e != e) d = e;
  }
  return d;
}

/* Solve A z = b in place (A n x n, row-major, destroyed; z into b): Gaussian elimination
 * with partial pivoting, as LAPACK gesv. 0, or 2 on a zero pivot. Always inlined into
 * eq_newton's clones: compiled once per clone, the same arithmetic (FMA contraction
 * included) in every library built from this source, the exported controller's too. */
static inline __attribute__((always_inline)) int eq_gauss(double *A, double *b, int n) {
  for (int c = 0; c < n; c++) {
    int piv = c;
    double best = fabs(A[c * n + c]);
    for (int rr = c + 1; rr < n; rr++)
      if (fabs(A[rr * n + c]) > best) { best = fabs(A[rr * n + c]); piv = rr; }
    if (best == 0.0) return 2;
    if (piv != c) {
      for (int q = 0; q < n; q++) {
        const double t = A[c * n + q]; A[c * n + q] = A[piv * n + q]; A[piv * n + q] = t;
      }
      const double t = b[c]; b[c] = b[piv]; b[piv] = t;
    }
    const double inv = 1.0 / A[c * n + c];
    for (int rr = c + 1; rr < n; rr++) {
      const double l = A[rr * n + c] * inv;
      if (l == 0.0) continue;
      for (int q = c; q < n; q++) A[rr * n + q] -= l * A[c * n + q];
      b[rr] -= l * b[c];
    }
  }
  for (int c = n - 1; c >= 0; c--) {
    double s = b[c];
    for (int q = c + 1; q < n; q++) s -= A[c * n + q] * b[q];
    b[c] = s / A[c * n + c];
  }
  return 0;
}

/* Equilibrium x = f(x, u), U_o x + b_o = y by Newton's method from (x0, u0), as
 * controllers.equilibrium.equilibrium_newton: the Newton matrix K is (NX + NY) x (NX + NU);
 * square (NU == NY), each step solves K d = -F; wide (NU > NY), each step is the
 * minimum-norm solution d = K^T z, (K K^T) z = -F (the equilibrium closest to (x0, u0) along
 * the continuation); tall (NU < NY), the Gauss-Newton step (K^T K) d = -K^T F (a zero
 * residual only for a y on the surface of equilibrium outputs). Returns 0 when max|F| < tol
 * was reached (x, u written; the caller checks |u| <= 1), 1 when not converged in max_iter
 * iterations, 2 on a singular Newton matrix. */
HOT EXPORT int PFX(eq_newton)(const double *y, const double *x0, const double *u0, int max_iter,
                              double tol, double *xo, double *uo) {
  enum { NR = NX + NY, NC = NX + NU };
  double x[NX], u[NU], F[NR], K[NR * NC], z[NX], r[NX], h[NX], jh[NX * NV], df[NX * NV];
  double xn[NX], d[NC];
#if NU > NY
  double A[NR * NR], zz[NR];
#elif NU < NY
  double A[NC * NC];
#endif
  memcpy(x, x0, sizeof x);
  memcpy(u, u0, sizeof u);
  for (int it = 0; it < max_iter; it++) {
    simulate_stage(x, u, z, r, h, xn);
    double fmax = 0.0;
    for (int k = 0; k < NX; k++) F[k] = xn[k] - x[k];
    for (int a = 0; a < NY; a++) {
      double s = BO[a];
      for (int k = 0; k < NX; k++) s += UO[a * NX + k] * x[k];
      F[NX + a] = s - y[a];
    }
    for (int k = 0; k < NR; k++) fmax = fmax > fabs(F[k]) ? fmax : fabs(F[k]);
    if (!(fmax == fmax)) return 1;   /* NaN */
    if (fmax < tol) {
      memcpy(xo, x, sizeof x);
      memcpy(uo, u, sizeof u);
      return 0;
    }
    stage_jac(x, z, r, h, jh, df);
    for (int k = 0; k < NX; k++) {
      for (int c = 0; c < NV; c++) K[k * NC + c] = df[k * NV + c];
      K[k * NC + k] -= 1.0;
    }
    for (int a = 0; a < NY; a++) {
      for (int c = 0; c < NX; c++) K[(NX + a) * NC + c] = UO[a * NX + c];
      for (int c = 0; c < NU; c++) K[(NX + a) * NC + NX + c] = 0.0;
    }
#if NU == NY
    for (int k = 0; k < NR; k++) d[k] = -F[k];
    if (eq_gauss(K, d, NR) != 0) return 2;
#elif NU > NY
    for (int i = 0; i < NR; i++)
      for (int j = 0; j < NR; j++) {
        double s = 0.0;
        for (int c = 0; c < NC; c++) s += K[i * NC + c] * K[j * NC + c];
        A[i * NR + j] = s;
      }
    for (int k = 0; k < NR; k++) zz[k] = -F[k];
    if (eq_gauss(A, zz, NR) != 0) return 2;
    for (int c = 0; c < NC; c++) {
      double s = 0.0;
      for (int i = 0; i < NR; i++) s += K[i * NC + c] * zz[i];
      d[c] = s;
    }
#else
    for (int i = 0; i < NC; i++) {
      for (int j = 0; j < NC; j++) {
        double s = 0.0;
        for (int q = 0; q < NR; q++) s += K[q * NC + i] * K[q * NC + j];
        A[i * NC + j] = s;
      }
      double s = 0.0;
      for (int q = 0; q < NR; q++) s -= K[q * NC + i] * F[q];
      d[i] = s;
    }
    if (eq_gauss(A, d, NC) != 0) return 2;
#endif
    for (int k = 0; k < NX; k++) x[k] += d[k];
    for (int k = 0; k < NU; k++) u[k] += d[NX + k];
  }
  return 1;
}

/* the steady state of u_s by Newton from x0 (steady_state.c) into xs (NX); 0 when
 * converged. Uses the workspace's steady-state scratch and invalidates its cache. */
EXPORT int PFX(steady)(gk_ws *ws, const double *us, const double *x0, double *xs) {
  ws->mem.c_level = -1;
  steady_state(ws, us, x0);
  memcpy(xs, ws->mem.xs, sizeof ws->mem.xs);
  return ws->mem.xs_status;
}

EXPORT void PFX(dims)(gk_dims *out) {
  out->n_states = NX; out->n_inputs = NU; out->horizon = NH; out->n_reduced_rows = NQ;
  out->n_decision = NW; out->n_constraints = NG; out->n_parameters = NP;
  out->control_horizon = NM; out->n_assess_rows = NL; out->n_outputs = NY;
}

/* the interface types' layout, then the instance's size (kernel_abi.check_layout) */
EXPORT void PFX(abi)(long *out) {
  static const long sizes[GK_ABI_COUNT] = GK_ABI_SIZES;
  for (int i = 0; i < GK_ABI_COUNT; i++) out[i] = sizes[i];
}

/* the instance's clipping counters (a casadi function's evaluations keep none) */
EXPORT void PFX(counters)(const gk_ws *ws, gk_counters *out) {
  out->hess_calls = ws->mem.n_calls;
  out->eig = ws->mem.n_eig;
  out->clipped = ws->mem.n_clipped;
  out->eigenvalues_clipped = ws->mem.n_evs;
  out->full_eig = ws->mem.n_full_eig;
}

EXPORT void PFX(invalidate)(gk_ws *ws) { ws->mem.c_level = -1; }

/* the instance's cost weights (gk_mem.rw, dw, tw: R, S = diag(dw) with HAS_DU, T = diag(tw)
 * with HAS_ASS), set between solves (controllers/ocp/fhocp.py FHOCP.set_weight; the exported
 * controller's tunable parameters write the same memory) */
EXPORT void PFX(set_weights)(gk_ws *ws, const double *rw, const double *dw, const double *tw) {
  memcpy(ws->mem.rw, rw, sizeof ws->mem.rw);
#if HAS_DU
  memcpy(ws->mem.dw, dw, sizeof ws->mem.dw);
#else
  (void)dw;
#endif
#if HAS_ASS
  memcpy(ws->mem.tw, tw, sizeof ws->mem.tw);
#else
  (void)tw;
#endif
}

EXPORT void PFX(set_bias_shift)(const double *db) {
#if HAS_SHIFT
  memcpy(gk_db, db, sizeof gk_db);
#else
  (void)db;   /* no measured disturbances: nothing moves */
#endif
}

EXPORT void PFX(timers)(const gk_ws *ws, double *out) {
#ifdef GK_TIMERS
  for (int i = 0; i < 4; i++) out[i] = ws->mem.tk_acc[i];
#else
  (void)ws;
  for (int i = 0; i < 4; i++) out[i] = -1.0;
#endif
}

/* test hook: clip a symmetric NW x NW row-major matrix in place (block structure assumed:
 * row/column IT only on the diagonal) */
EXPORT int PFX(clip)(gk_ws *ws, double *H) { return clip_hessian(ws, H); }

