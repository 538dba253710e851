/* Part of the compiled FHOCP kernel (controllers/kernel/compiled_kernel.py joins the
 * generated header, gru_fhocp.h and the parts into one translation unit): the SQP loop of
 * the FHOCP in C, the same iteration as casadi 3.8 sqpmethod with the exact Hessian (its
 * eigenvalue-clipped version, as hess_l) and an l1-merit Armijo line search, with the QP of
 * qp.c in place of qpOASES:
 *
 *   loop: f, g and grad L = grad f + J' lam_g + lam_x at w (an adjoint sweep);
 *         stop when max violation < tol_pr and |grad L|inf < tol_du ("Solve_Succeeded"; with
 *         tol_du_relative, |grad L|inf < tol_du (1 + |(lam_g, lam_x)|inf), ours),
 *         at max_iter iterations, or when |dw|inf <= min_step_size after the first;
 *         grad f, jac g (sensitivities);
 *         H = clip(hess_l(w, lam_g)); QP for (dw, lam+) with the bounds shifted by w, g(w);
 *         (ours, reuse_step > 0: near the last evaluation the last jac g and H are kept,
 *         with the adjoint-corrected gradient; iterate() below);
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

/* The gradient of the Lagrangian f + lam_g' g + lam_x' w at w (its rollout cached, level >= 0)
 * by one adjoint sweep: mu_N = dL/dx_N, mu_i = 2 Q (x_i - x_bar) + D'lam_i + A_i' mu_{i+1},
 * dL/du_i = B_i' mu_{i+1} + 2 R (u_i - u_bar) + lam_x (summed into u_s's over the tail of a
 * control horizon; + the input-rate term's gradient when
 * HAS_DU, du_gradient) (adjoint_local and stage_vjp, as the
 * contracted Hessian's adjoints) -- O(N n^2), no sensitivities: what the
 * convergence test needs at an iterate whose Jacobian the SQP may never use. Same value as
 * grad f + J' lam_g + lam_x from jac_fg, up to rounding. */
HOT static void lagrangian_gradient(const gk_ws *ws, const double *w, const double *p,
                                    const double *lam_x, const double *lg, double *gl) {
  const double *xb = XREF(ws, p), *ub = UREF(w, p);
  const int r0 = (NH - 1) * NQ;
  double mu[NX], mun[NX], gu[NU];
  double tg = 2.0 * SW * w[IT];
  for (int k = 0; k < NX; k++) {
    mun[k] = lg[r0 + k] + lg[r0 + NX + k];
    tg += lg[r0 + NX + k] - lg[r0 + k];
  }
  gl[IT] = tg + lam_x[IT];
  for (int c = NUU; c < NUA; c++) gl[c] = 0.0;   /* u_s: the tail's B_i' mu_{i+1}, then 1b */
  for (int i = NH - 1; i >= 0; i--) {   /* mun = mu_{i+1} */
    if (i >= 1) adjoint_local(ws, i, xb, 1.0, lg + (i - 1) * NQ, mu);
    else memset(mu, 0, sizeof mu);      /* x_0 = x_hat: its adjoint is not needed */
    stage_vjp(ws, i, mun, mu, gu);
    if (i < NM)
      for (int c = 0; c < NU; c++) {
        double s = 0.0;
        for (int j = 0; j < NU; j++) s += (w[i * NU + j] - ub[j]) * (2.0 * ws->mem.rw[j * NU + c]);
        gl[i * NU + c] = gu[c] + s + lam_x[i * NU + c];
      }
    else   /* the tail of a control horizon: u_i = u_s */
      for (int c = 0; c < NU; c++) gl[NUU + c] += gu[c];
    memcpy(mun, mu, sizeof mu);
  }
#if HAS_DU
  du_gradient(ws->mem.dw, w, UPREV(p), gl);
#endif
#if HAS_ASS
  ass_lagrangian_gradient(ws, w, p, lam_x, lg, gl);
#endif
#if SOFT
  soft_lagrangian_gradient(ws, w, lam_x, lg, gl);
#endif
#if HAS_MOVE
  move_lagrangian_gradient(lg, gl);
#endif
}

/* test hook: lagrangian_gradient at (w, p) in workspace ws */
EXPORT void PFX(grad_l)(gk_ws *ws, const double *w, const double *p, const double *lam_x,
                        const double *lam_g, double *gl) {
  roll(ws, w, p, 0);
  lagrangian_gradient(ws, w, p, lam_x, lam_g, gl);
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

/* One SQP iteration at w (its rollout cached at level 0, f = fk, g in sq_gz and grad L in
 * sq_gl from the stopping tests): the derivatives, the QP for (dw, lam+), the l1-merit line
 * search, then w, lam_x, lam_g updated in place (and dw in sq_dw); a gk_sqp_status.
 *
 * Derivative reuse (reuse_step > 0, ours): while the iterates have moved at most
 * reuse_step (inf-norm, summed over the steps) since the Jacobian and the Hessian were
 * evaluated, the iteration keeps them and takes the QP's gradient as
 * grad L(w, lam) - J_d' lam_g - lam_x = grad f(w) + (J(w) - J_d)' lam_g (the adjoint-corrected
 * gradient of inexact-Jacobian SQP, Bock et al. 2007): its fixed points are exactly the
 * KKT points, so the answer meets the same stopping test; near a solution the step costs the
 * QP and two adjoint sweeps instead of the sensitivities and the Hessian. A reused step must
 * be taken whole (the line search's first trial); otherwise, or when its QP fails, the
 * iteration starts again with fresh derivatives. *drift: the steps' sum since the
 * derivatives (INFINITY: none yet). */
static int iterate(gk_ws *ws, const double *p, const double *lbx, const double *ubx,
                   const double *lbg, const double *ubg, double *w, double *lam_x,
                   double *lam_g, double fk, const gk_sqp_opts *opt, double reuse_step,
                   double *sigma, double *drift, gk_sqp_info *info) {
  double *sq_gf = ws->work.sq_gf, *sq_gz = ws->work.sq_gz, *sq_J = ws->work.sq_J, *sq_H = ws->work.sq_H,
         *sq_lbx = ws->work.sq_lbx, *sq_ubx = ws->work.sq_ubx, *sq_lba = ws->work.sq_lba,
         *sq_uba = ws->work.sq_uba, *sq_dw = ws->work.sq_dw, *sq_lx = ws->work.sq_lx, *sq_la = ws->work.sq_la,
         *sq_wc = ws->work.sq_wc, *sq_gc = ws->work.sq_gc;
  const double c1 = opt->c1, beta = opt->beta;
  const int max_iter_ls = opt->max_iter_ls;
  for (int j = 0; j < NW; j++) { sq_lbx[j] = lbx[j] - w[j]; sq_ubx[j] = ubx[j] - w[j]; }
  for (int r = 0; r < NG; r++) { sq_lba[r] = lbg[r] - sq_gz[r]; sq_uba[r] = ubg[r] - sq_gz[r]; }
  for (int reuse = reuse_step > 0.0 && *drift <= reuse_step;; reuse = 0) {
    const double *qlin = sq_gf;
    double t0 = sq_now();
    if (reuse) {   /* grad f by an adjoint sweep; the QP's gradient adjoint-corrected */
      lagrangian_gradient(ws, w, p, ws->work.sq_zx, ws->work.sq_zg, sq_gf);
      for (int j = 0; j < NW; j++)
        ws->work.sq_gq[j] = ws->work.sq_gl[j] - lam_x[j] - gk_dot(sq_J + (size_t)j * NG, lam_g, NG);
      qlin = ws->work.sq_gq;
      info->t_derivatives += sq_now() - t0;
    } else {       /* grad f and jac g (the sensitivities), the Hessian */
      roll(ws, w, p, 1);
      gradient(ws, w, p, sq_gf);
      jacobian(ws, sq_J);
      info->t_derivatives += sq_now() - t0;
      t0 = sq_now();
      hessian(ws, w, p, 1.0, lam_g, sq_H);
      const double t1 = sq_now();
      clip_hessian(ws, sq_H);
      const double t2 = sq_now();
      info->t_hessian += t2 - t0;
      info->t_clip += t2 - t1;
      *drift = 0.0;
    }
    t0 = sq_now();
    int changes = 0;
    const int qs = qp_solve(ws, sq_H, qlin, sq_J, sq_lbx, sq_ubx, sq_lba, sq_uba, sq_dw, sq_lx,
                            sq_la, &changes);
    info->t_qp += sq_now() - t0;
    info->qp_working_set_changes += changes;
    if (qs != GK_QP_OPTIMAL) {
      if (reuse) continue;
      return qs == GK_QP_INFEASIBLE ? GK_SQP_QP_INFEASIBLE : GK_SQP_QP_FAILED;
    }
    /* l1-merit line search (max_iter_ls > 0), then the multipliers and the step */
    double lmax = 0.0;   /* not the slacks' bounds (SOFT): linear, kept along the step */
    for (int j = 0; j < NW - NSL; j++) lmax = fabs(sq_lx[j]) > lmax ? fabs(sq_lx[j]) : lmax;
    for (int r = 0; r < NG; r++) lmax = fabs(sq_la[r]) > lmax ? fabs(sq_la[r]) : lmax;
    *sigma = fmax(*sigma, 1.01 * lmax);
    const double l1_infeas = sq_viol(w, sq_gz, lbx, ubx, lbg, ubg, 1);
    double slope = 0.0;
    for (int j = 0; j < NW; j++) slope += sq_dw[j] * sq_gf[j];
    const double tl1 = slope - *sigma * l1_infeas, l1 = fk + *sigma * l1_infeas;
    double t = 1.0;
    if (max_iter_ls > 0) {
      t0 = sq_now();
      int rejected = 0;
      for (int ls = 1;; ls++) {
        for (int j = 0; j < NW; j++) sq_wc[j] = w[j] + t * sq_dw[j];
        roll(ws, sq_wc, p, 0);
        const double fc = cost(ws, sq_wc, p);
        constraints(ws, sq_wc, p, sq_gc);
        const double l1c = fc + *sigma * sq_viol(sq_wc, sq_gc, lbx, ubx, lbg, ubg, 1);
        if (l1c <= l1 + t * c1 * tl1) break;
        if (reuse) { rejected = 1; break; }
        if (ls == max_iter_ls) { info->line_search_failures += 1; break; }
        t *= beta;
      }
      info->t_line_search += sq_now() - t0;
      if (rejected) continue;
      for (int j = 0; j < NW; j++) lam_x[j] = (1.0 - t) * lam_x[j] + t * sq_lx[j];
      for (int r = 0; r < NG; r++) lam_g[r] = (1.0 - t) * lam_g[r] + t * sq_la[r];
      for (int j = 0; j < NW; j++) sq_dw[j] *= t;
    } else {
      memcpy(lam_x, sq_lx, sizeof ws->work.sq_lx);
      memcpy(lam_g, sq_la, sizeof ws->work.sq_la);
    }
    double dwn = 0.0;
    for (int j = 0; j < NW; j++) {
      w[j] += sq_dw[j];
      dwn = fmax(dwn, fabs(sq_dw[j]));
    }
    *drift += dwn;
    info->derivative_reuses += reuse;
    return GK_SQP_SOLVE_SUCCEEDED;
  }
}

/* The SQP loop from (w, lam_x, lam_g) (in/out), reusing derivatives when reuse_step > 0: the
 * stopping tests, then iterate(), until a test ends it; its status. The iterations are counted
 * in info->iterations, the counters and timers added to info's. start: the solve's start
 * (sq_now), for the time budget. */
static int sqp_loop(gk_ws *ws, const double *p, const double *lbx, const double *ubx,
                    const double *lbg, const double *ubg, double *w, double *lam_x,
                    double *lam_g, double *f, const gk_sqp_opts *opt, double reuse_step,
                    double start, gk_sqp_info *info) {
  double *sq_gz = ws->work.sq_gz, *sq_gl = ws->work.sq_gl, *sq_dw = ws->work.sq_dw;
  const double tol_pr = opt->tol_pr, tol_du = opt->tol_du, min_step = opt->min_step_size;
  const int max_iter = opt->max_iter, du_relative = opt->tol_du_relative;
  double sigma = 0.0, fk = 0.0, drift = INFINITY;
  int iter = 0, status = GK_SQP_SOLVE_SUCCEEDED;
  memset(sq_dw, 0, sizeof ws->work.sq_dw);
  for (;;) {
    /* the stopping tests first: f, g and the Lagrangian's gradient need no sensitivities */
    double t0 = sq_now();
    roll(ws, w, p, 0);
    fk = cost(ws, w, p);
    constraints(ws, w, p, sq_gz);
    lagrangian_gradient(ws, w, p, lam_x, lam_g, sq_gl);
    double du = 0.0, dwn = 0.0;
    for (int j = 0; j < NW; j++) {
      if (fabs(sq_gl[j]) > du || sq_gl[j] != sq_gl[j]) du = fabs(sq_gl[j]);
      if (fabs(sq_dw[j]) > dwn) dwn = fabs(sq_dw[j]);
    }
    const double pr = sq_viol(w, sq_gz, lbx, ubx, lbg, ubg, 0);
    info->t_derivatives += sq_now() - t0;
    double du_scale = 1.0;   /* tol_du_relative: 1 + the multipliers' largest magnitude */
    if (du_relative) {
      double lm = 0.0;
      for (int r = 0; r < NG; r++) lm = fmax(lm, fabs(lam_g[r]));
      for (int j = 0; j < NW - NSL; j++) lm = fmax(lm, fabs(lam_x[j]));   /* not eps >= 0's: rho */
      du_scale += lm;
    }
    if (pr < tol_pr && du < tol_du * du_scale) { status = GK_SQP_SOLVE_SUCCEEDED; break; }
    if (iter >= max_iter) { status = GK_SQP_MAXIMUM_ITERATIONS_EXCEEDED; break; }
    if (iter >= 1 && dwn <= min_step) { status = GK_SQP_SEARCH_DIRECTION_BECOMES_TOO_SMALL; break; }
    if (sq_now() - start > opt->time_budget) { status = GK_SQP_USER_REQUESTED_STOP; break; }
    /* another iteration: its derivatives, the QP, the line search (iterate) */
    iter++;
    const int st = iterate(ws, p, lbx, ubx, lbg, ubg, w, lam_x, lam_g, fk, opt, reuse_step,
                           &sigma, &drift, info);
    if (st != GK_SQP_SOLVE_SUCCEEDED) { status = st; break; }
  }
  *f = fk;
  info->iterations = iter;
  return status;
}

/* Solve the FHOCP from w (NW), lam_x (NW) and lam_g (NG) (in/out: the initial guess in, the
 * answer out) at parameters p in workspace ws; g (NG) and *f receive the constraints and cost
 * at the answer. opt: the options (gk_sqp_opts: tol_pr, tol_du, max_iter, min_step_size, c1,
 * beta, max_iter_ls, time_budget [s], inf: none, checked before each iteration's Hessian,
 * after the stopping tests, tol_du_relative, reuse_step); info (gk_sqp_info) receives the
 * status, the iterations, the QP working-set changes, the line-search failures and the
 * seconds spent in the QP, the Hessian (clipping included; the clipping's share in t_clip),
 * f/grad f/g/jac g and the line search's f/g.
 *
 * Derivative reuse never costs convergence: a loop that reused derivatives and ended short of
 * "Solve_Succeeded" (at the iteration cap, a step too small, a failed or infeasible QP; not
 * the time budget) is discarded and the solve starts again from the same initial guess with
 * fresh derivatives in every iteration (info->fresh_restarts = 1, its iterations in
 * info->discarded_iterations): the answer and status are then those of the fresh-derivative
 * solve, to the bit. Returns the status, a gk_sqp_status (casadi sqpmethod's return statuses;
 * GK_SQP_USER_REQUESTED_STOP: the time budget ran out). */
EXPORT int PFX(sqp)(gk_ws *ws, const double *p, const double *lbx, const double *ubx,
                    const double *lbg, const double *ubg, double *w, double *lam_x,
                    double *lam_g, double *g, double *f, const gk_sqp_opts *opt,
                    gk_sqp_info *info) {
  const double start = sq_now();
  const int may_reuse = opt->reuse_step > 0.0;
  memset(info, 0, sizeof *info);
  if (may_reuse) {   /* the initial guess, for a fresh restart */
    memcpy(ws->work.sq_w0, w, sizeof ws->work.sq_w0);
    memcpy(ws->work.sq_lx0, lam_x, sizeof ws->work.sq_lx0);
    memcpy(ws->work.sq_lg0, lam_g, sizeof ws->work.sq_lg0);
  }
  int status = sqp_loop(ws, p, lbx, ubx, lbg, ubg, w, lam_x, lam_g, f, opt,
                        may_reuse ? opt->reuse_step : 0.0, start, info);
  if (may_reuse && info->derivative_reuses > 0 && status != GK_SQP_SOLVE_SUCCEEDED &&
      status != GK_SQP_USER_REQUESTED_STOP) {
    memcpy(w, ws->work.sq_w0, sizeof ws->work.sq_w0);
    memcpy(lam_x, ws->work.sq_lx0, sizeof ws->work.sq_lx0);
    memcpy(lam_g, ws->work.sq_lg0, sizeof ws->work.sq_lg0);
    info->fresh_restarts = 1;
    info->discarded_iterations = info->iterations;
    status = sqp_loop(ws, p, lbx, ubx, lbg, ubg, w, lam_x, lam_g, f, opt, 0.0, start, info);
  }
  memcpy(g, ws->work.sq_gz, sizeof ws->work.sq_gz);
  info->status = status;
  return status;
}
