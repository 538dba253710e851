/* Part of the compiled FHOCP kernel (controllers/compiled_kernel.py concatenates the
 * generated header and 1_rollout.c ... 6_sqp.c into one translation unit): the SQP loop of
 * the FHOCP in C, the same iteration as casadi 3.8 sqpmethod with the exact Hessian (its
 * eigenvalue-clipped version, as hess_l) and an l1-merit Armijo line search, with the QP of
 * 5_qp.c in place of qpOASES:
 *
 *   loop: f, g and grad L = grad f + J' lam_g + lam_x at w (an adjoint sweep);
 *         stop when max violation < tol_pr and |grad L|inf < tol_du ("Solve_Succeeded"),
 *         at max_iter iterations, or when |dw|inf <= min_step_size after the first;
 *         grad f, jac g (sensitivities);
 *         H = clip(hess_l(w, lam_g)); QP for (dw, lam+) with the bounds shifted by w, g(w);
 *         sigma = max(sigma, 1.01 |lam+|inf); Armijo on f + sigma * sum of violations with
 *         slope dw' grad f - sigma * violations, t = 1, beta t, at most max_iter_ls trials
 *         (the last one accepted); lam = (1 - t) lam + t lam+, w += t dw.
 *
 * One call solves one FHOCP: no Python and no casadi between iterations. */
#include <time.h>

static double sq_now(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}

static double sq_gf[NW], sq_gz[NG], sq_J[NG * NW], sq_H[NW * NW], sq_gl[NW];
static double sq_lbx[NW], sq_ubx[NW], sq_lba[NG], sq_uba[NG], sq_dw[NW], sq_lx[NW],
              sq_la[NG], sq_wc[NW], sq_gc[NG];

/* The gradient of the Lagrangian f + lam_g' g + lam_x' w at w (its rollout cached, level >= 0)
 * by one adjoint sweep: mu_N = dL/dx_N, mu_i = 2 Q (x_i - x_bar) + D'lam_i + A_i' mu_{i+1},
 * dL/du_i = B_i' mu_{i+1} + 2 R (u_i - u_bar) + lam_x (adjoint_local and stage_vjp, as the
 * contracted Hessian's adjoints) -- O(N n^2), no sensitivities: what the
 * convergence test needs at an iterate whose Jacobian the SQP may never use. Same value as
 * grad f + J' lam_g + lam_x from jac_fg, up to rounding. */
HOT static void lagrangian_gradient(const double *w, const double *p, const double *lam_x,
                                    const double *lg, double *gl) {
  const double *xb = p + NX, *ub = p + 2 * NX;
  const int r0 = (NH - 1) * NQ;
  double mu[NX], mun[NX], gu[NU];
  double tg = 2.0 * SW * w[NUU];
  for (int k = 0; k < NX; k++) {
    mun[k] = lg[r0 + k] + lg[r0 + NX + k];
    tg += lg[r0 + NX + k] - lg[r0 + k];
  }
  gl[NUU] = tg + lam_x[NUU];
  for (int i = NH - 1; i >= 0; i--) {   /* mun = mu_{i+1} */
    if (i >= 1) adjoint_local(i, xb, 1.0, lg + (i - 1) * NQ, mu);
    else memset(mu, 0, sizeof mu);      /* x_0 = x_hat: its adjoint is not needed */
    stage_vjp(i, mun, mu, gu);
    for (int c = 0; c < NU; c++) {
      double s = 0.0;
      for (int j = 0; j < NU; j++) s += (w[i * NU + j] - ub[j]) * (2.0 * RW[j * NU + c]);
      gl[i * NU + c] = gu[c] + s + lam_x[i * NU + c];
    }
    memcpy(mun, mu, sizeof mu);
  }
}

/* test hook: lagrangian_gradient at (w, p) */
EXPORT void PFX(grad_l)(const double *w, const double *p, const double *lam_x,
                        const double *lam_g, double *gl) {
  roll(w, p, 0);
  lagrangian_gradient(w, p, lam_x, lam_g, gl);
}

/* casadi_max_viol / casadi_sum_viol of (w, g) against their bounds */
static double sq_viol(const double *w, const double *g, const double *lbx, const double *ubx,
                      const double *lbg, const double *ubg, int sum) {
  double r = 0.0;
  for (int i = 0; i < NW + NG; i++) {
    const double v = i < NW ? w[i] : g[i - NW];
    const double lo = i < NW ? lbx[i] : lbg[i - NW], hi = i < NW ? ubx[i] : ubg[i - NW];
    const double e = v < lo ? lo - v : (v > hi ? v - hi : 0.0);
    if (sum) r += e;
    else if (e > r) r = e;
  }
  return r;
}

/* Solve the FHOCP from w (NW), lam_x (NW) and lam_g (NG) (in/out: the initial guess in, the
 * answer out) at parameters p; g (NG) and *f receive the constraints and cost at the answer.
 * opt = {tol_pr, tol_du, max_iter, min_step_size, c1, beta, max_iter_ls, time budget [s]
 * (inf: none; checked before each iteration's Hessian, after the stopping tests)}.
 * info (double[8]) = {status, iterations, QP working-set changes, line-search failures,
 * seconds in: QP, Hessian (clipping included), f/grad f/g/jac g, f/g of the line search}.
 * status: 0 Solve_Succeeded, 1 Maximum_Iterations_Exceeded,
 * 2 Search_Direction_Becomes_Too_Small, 3 QP infeasible, 4 QP failed (working-set limit or
 * H not positive definite), 5 time budget exceeded. Returns status. */
EXPORT int PFX(sqp)(const double *p, const double *lbx, const double *ubx, const double *lbg,
                    const double *ubg, double *w, double *lam_x, double *lam_g, double *g,
                    double *f, const double *opt, double *info) {
  const double tol_pr = opt[0], tol_du = opt[1], min_step = opt[3], c1 = opt[4],
               beta = opt[5];
  const int max_iter = (int)opt[2], max_iter_ls = (int)opt[6];
  const double start = sq_now(), budget = opt[7];
  double sigma = 0.0, fk = 0.0;
  int iter = 0, status = 0;
  for (int k = 0; k < 8; k++) info[k] = 0.0;
  memset(sq_dw, 0, sizeof sq_dw);
  for (;;) {
    /* the stopping tests first: f, g and the Lagrangian's gradient need no sensitivities */
    double t0 = sq_now();
    roll(w, p, 0);
    fk = cost(w, p);
    constraints(w, p, sq_gz);
    lagrangian_gradient(w, p, lam_x, lam_g, sq_gl);
    double du = 0.0, dwn = 0.0;
    for (int j = 0; j < NW; j++) {
      if (fabs(sq_gl[j]) > du || sq_gl[j] != sq_gl[j]) du = fabs(sq_gl[j]);
      if (fabs(sq_dw[j]) > dwn) dwn = fabs(sq_dw[j]);
    }
    const double pr = sq_viol(w, sq_gz, lbx, ubx, lbg, ubg, 0);
    info[6] += sq_now() - t0;
    if (pr < tol_pr && du < tol_du) { status = 0; break; }
    if (iter >= max_iter) { status = 1; break; }
    if (iter >= 1 && dwn <= min_step) { status = 2; break; }
    if (sq_now() - start > budget) { status = 5; break; }
    /* another iteration: grad f and jac g (the sensitivities), the Hessian, the QP */
    t0 = sq_now();
    roll(w, p, 1);
    gradient(w, p, sq_gf);
    jacobian(sq_J);
    info[6] += sq_now() - t0;
    t0 = sq_now();
    hessian(w, p, 1.0, lam_g, sq_H);
    clip_hessian(sq_H);
    info[5] += sq_now() - t0;
    for (int j = 0; j < NW; j++) { sq_lbx[j] = lbx[j] - w[j]; sq_ubx[j] = ubx[j] - w[j]; }
    for (int r = 0; r < NG; r++) { sq_lba[r] = lbg[r] - sq_gz[r]; sq_uba[r] = ubg[r] - sq_gz[r]; }
    iter++;
    t0 = sq_now();
    int changes = 0;
    const int qs = qp_solve(sq_H, sq_gf, sq_J, sq_lbx, sq_ubx, sq_lba, sq_uba, sq_dw, sq_lx,
                            sq_la, &changes);
    info[4] += sq_now() - t0;
    info[2] += changes;
    if (qs == 1) { status = 3; break; }
    if (qs != 0) { status = 4; break; }
    /* l1-merit line search (max_iter_ls > 0), then the multipliers and the step */
    double lmax = 0.0;
    for (int j = 0; j < NW; j++) lmax = fabs(sq_lx[j]) > lmax ? fabs(sq_lx[j]) : lmax;
    for (int r = 0; r < NG; r++) lmax = fabs(sq_la[r]) > lmax ? fabs(sq_la[r]) : lmax;
    sigma = fmax(sigma, 1.01 * lmax);
    const double l1_infeas = sq_viol(w, sq_gz, lbx, ubx, lbg, ubg, 1);
    double slope = 0.0;
    for (int j = 0; j < NW; j++) slope += sq_dw[j] * sq_gf[j];
    const double tl1 = slope - sigma * l1_infeas, l1 = fk + sigma * l1_infeas;
    double t = 1.0;
    if (max_iter_ls > 0) {
      t0 = sq_now();
      for (int ls = 1;; ls++) {
        for (int j = 0; j < NW; j++) sq_wc[j] = w[j] + t * sq_dw[j];
        roll(sq_wc, p, 0);
        const double fc = cost(sq_wc, p);
        constraints(sq_wc, p, sq_gc);
        const double l1c = fc + sigma * sq_viol(sq_wc, sq_gc, lbx, ubx, lbg, ubg, 1);
        if (l1c <= l1 + t * c1 * tl1) break;
        if (ls == max_iter_ls) { info[3] += 1; break; }
        t *= beta;
      }
      info[7] += sq_now() - t0;
      for (int j = 0; j < NW; j++) lam_x[j] = (1.0 - t) * lam_x[j] + t * sq_lx[j];
      for (int r = 0; r < NG; r++) lam_g[r] = (1.0 - t) * lam_g[r] + t * sq_la[r];
      for (int j = 0; j < NW; j++) sq_dw[j] *= t;
    } else {
      memcpy(lam_x, sq_lx, sizeof sq_lx);
      memcpy(lam_g, sq_la, sizeof sq_la);
    }
    for (int j = 0; j < NW; j++) w[j] += sq_dw[j];
  }
  memcpy(g, sq_gz, sizeof sq_gz);
  *f = fk;
  info[0] = status;
  info[1] = iter;
  return status;
}
