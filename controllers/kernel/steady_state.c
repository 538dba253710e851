/* Part of the compiled FHOCP kernel (controllers/kernel/compiled_kernel.py joins the
 * generated header, gru_fhocp.h and the parts into one translation unit): the artificial steady state of
 * the tracking law (HAS_ASS 1; controllers/laws/tracking/reference.py, the same mathematics as
 * controllers/ocp/steady_state.py and controllers/laws/tracking/nlp.py).
 *
 * The decision vector ends with u_s (then t); x_s = x_s(u_s) is the GRU's fixed point
 * x_s = f(x_s, u_s) (unique: f(., u_s) contracts, th:stability-bonassi), found by Newton's
 * method from the parameter x_s0 (the previous step's x_s), and X_s = dx_s/du_s =
 * (I - A_s)^-1 B_s by the implicit function theorem, [A_s B_s] the stage Jacobian at
 * (x_s, u_s). The cost adds the offset term ||U_o x_s + b_o - r||^2_T (r = y_bar - d_hat,
 * TW = diag T) and, with HAS_DU, the terminal input-rate term ||u_{N-1} - u_s||^2_S; the
 * constraints add the rows D U_o x_s (the steady output in Y_s, bounds set per solve). The
 * Hessian's u_s block includes the curvature of x_s(u_s) (ass_curvature, hessian.c:
 * one transposed solve and the point Hessian at (x_s, u_s)).
 *
 * The steady state's Newton (steady_state) is compiled in every kernel: the equilibrium
 * search (equilibrium.c) runs on it, for either law; the rest only with HAS_ASS. */
#define XS_MAX_ITER 50
#define XS_TOL 1e-13

/* LU with partial pivoting of the row-major NX x NX matrix A in place; 1 when singular */
static int lu_factor(double *A, int *piv) {
  for (int c = 0; c < NX; c++) {
    int pr = c;
    double best = fabs(A[c * NX + c]);
    for (int r = c + 1; r < NX; r++)
      if (fabs(A[r * NX + c]) > best) { best = fabs(A[r * NX + c]); pr = r; }
    piv[c] = pr;
    if (!(best > 0.0)) return 1;
    if (pr != c)
      for (int q = 0; q < NX; q++) {
        const double t = A[c * NX + q]; A[c * NX + q] = A[pr * NX + q]; A[pr * NX + q] = t;
      }
    const double inv = 1.0 / A[c * NX + c];
    for (int r = c + 1; r < NX; r++) {
      const double l = A[r * NX + c] * inv;
      A[r * NX + c] = l;
      for (int q = c + 1; q < NX; q++) A[r * NX + q] -= l * A[c * NX + q];
    }
  }
  return 0;
}

/* solve (LU) x = b in place, b of NX entries with stride `st` (a column of a row-major
 * NX x st matrix). lu_factor swaps whole rows, multipliers included, so L is in the final
 * row order: every swap is applied to b before the forward substitution (interleaving them
 * pairs a multiplier with the wrong entry whenever a later column pivots). */
static void lu_solve(const double *LU, const int *piv, double *b, int st) {
  for (int c = 0; c < NX; c++) {       /* P b */
    const int pr = piv[c];
    if (pr != c) { const double t = b[c * st]; b[c * st] = b[pr * st]; b[pr * st] = t; }
  }
  for (int c = 0; c < NX; c++)         /* L v = P b (unit diagonal) */
    for (int r = c + 1; r < NX; r++) b[r * st] -= LU[r * NX + c] * b[c * st];
  for (int c = NX - 1; c >= 0; c--) {
    double s = b[c * st];
    for (int q = c + 1; q < NX; q++) s -= LU[c * NX + q] * b[q * st];
    b[c * st] = s / LU[c * NX + c];
  }
}

/* I - A at (x, us) into M (LU-factorised), [A B] into df, the gates and J_h into z, r, h, jh;
 * returns f(x, us) - x into F */
static int xs_linearise(const double *x, const double *us, double *F, double *M, int *piv,
                        double *df, double *z, double *r, double *h, double *jh) {
  stage_gates(x, us, 0, 0, z, r, h);
  for (int k = 0; k < NX; k++) F[k] = h[k] + z[k] * (x[k] - h[k]) - x[k];
  stage_jac(x, z, r, h, jh, df);
  for (int k = 0; k < NX; k++)
    for (int j = 0; j < NX; j++) M[k * NX + j] = (k == j ? 1.0 : 0.0) - df[k * NV + j];
  return lu_factor(M, piv);
}

/* x_s(u_s) by Newton from x0: steps (I - A) d = f(x) - x until |d|inf <= XS_TOL max(1, |x|inf)
 * (at most XS_MAX_ITER); then X_s at the answer. Not converged: x_s, X_s = NaN
 * (xs_status 1), which makes the cost NaN and the line search step back. */
static void steady_state(gk_ws *ws, const double *us, const double *x0) {
  double F[NX], df[NX * NV];
  double *x = ws->mem.xs, *M = ws->mem.xs_lu, *z = ws->mem.xs_z, *r = ws->mem.xs_r, *h = ws->mem.xs_h,
         *jh = ws->mem.xs_jh;
  int *piv = ws->mem.xs_piv;
  memcpy(x, x0, sizeof ws->mem.xs);
  ws->mem.xs_status = 1;
  for (int it = 0; it < XS_MAX_ITER; it++) {
    if (xs_linearise(x, us, F, M, piv, df, z, r, h, jh)) break;
    lu_solve(M, piv, F, 1);
    double dn = 0.0, xn = 1.0;
    for (int k = 0; k < NX; k++) {
      x[k] += F[k];
      if (!(fabs(F[k]) <= dn)) dn = fabs(F[k]);
      if (fabs(x[k]) > xn) xn = fabs(x[k]);
    }
    if (!(dn == dn)) break;
    if (dn <= XS_TOL * xn) { ws->mem.xs_status = 0; break; }
  }
  if (ws->mem.xs_status == 0 && xs_linearise(x, us, F, M, piv, df, z, r, h, jh)) ws->mem.xs_status = 1;
  if (ws->mem.xs_status != 0) {
    for (int k = 0; k < NX; k++) x[k] = NAN;
    for (int k = 0; k < NX * NU; k++) ws->mem.XS[k] = NAN;
    return;
  }
  for (int k = 0; k < NX; k++)
    for (int j = 0; j < NU; j++) ws->mem.XS[k * NU + j] = df[k * NV + NX + j];
  for (int j = 0; j < NU; j++) lu_solve(M, piv, ws->mem.XS + j, NU);
}

#if HAS_ASS
/* solve (LU)' y = b in place (the transposed system of lu_factor's matrix) */
static void lu_solve_t(const double *LU, const int *piv, double *b) {
  for (int c = 0; c < NX; c++) {      /* U' w = b */
    double s = b[c];
    for (int q = 0; q < c; q++) s -= LU[q * NX + c] * b[q];
    b[c] = s / LU[c * NX + c];
  }
  for (int c = NX - 1; c >= 0; c--) { /* L' v = w (unit diagonal) */
    double s = b[c];
    for (int q = c + 1; q < NX; q++) s -= LU[q * NX + c] * b[q];
    b[c] = s;
  }
  for (int c = NX - 1; c >= 0; c--) { /* y = P' v: the row swaps in reverse */
    const int pr = piv[c];
    if (pr != c) { const double t = b[c]; b[c] = b[pr]; b[pr] = t; }
  }
}

/* the tracking law's extra cost: ||U_o x_s + b_o - r||^2_T (+ ||u_{NM-1} - u_s||^2_S: the
 * last free input's step to u_s, u_{N-1}'s without a control horizon) */
static double ass_cost(const gk_ws *ws, const double *w, const double *p) {
  const double *r = p + 2 * NX;
  double acc = 0.0;
  for (int a = 0; a < NY; a++) {
    double e = BO[a] - r[a];
    for (int k = 0; k < NX; k++) e += UO[a * NX + k] * ws->mem.xs[k];
    acc += (e * ws->mem.tw[a]) * e;
  }
#if HAS_DU
  for (int j = 0; j < NU; j++) {
    const double d = w[(NM - 1) * NU + j] - w[NUU + j];
    acc += (d * ws->mem.dw[j]) * d;
  }
#else
  (void)w;
#endif
  return acc;
}

/* the rows D U_o x_s (y_s in Y_s) after the terminal rows */
static void ass_constraints(const gk_ws *ws, double *g) {
  double *gs = g + (NH - 1) * NQ + 2 * NX;
  for (int a = 0; a < NQ; a++) {
    double s = 0.0;
    for (int k = 0; k < NX; k++) s += DUO[a * NX + k] * ws->mem.xs[k];
    gs[a] = s;
  }
}

/* dJ/dx_s with lf = 1: -2 Q sum_{i<N} (x_i - x_s) + 2 U_o' T (U_o x_s + b_o - r), into gx */
static void ass_dcost_dxs(const gk_ws *ws, const double *p, double *gx) {
  const double *r = p + 2 * NX, *xs = ws->mem.xs;
  double dx[NX], te[NY];
  for (int k = 0; k < NX; k++) dx[k] = 0.0;
  for (int i = 0; i < NH; i++)
    for (int k = 0; k < NX; k++) dx[k] += ws->mem.X[i * NX + k] - xs[k];
  for (int k = 0; k < NX; k++) {
    double s = 0.0;
    for (int j = 0; j < NX; j++) s += dx[j] * (2.0 * QW[j * NX + k]);
    gx[k] = -s;
  }
  for (int a = 0; a < NY; a++) {
    double e = BO[a] - r[a];
    for (int k = 0; k < NX; k++) e += UO[a * NX + k] * xs[k];
    te[a] = 2.0 * ws->mem.tw[a] * e;
  }
  for (int a = 0; a < NY; a++)
    for (int k = 0; k < NX; k++) gx[k] += UO[a * NX + k] * te[a];
}

/* added into the u_s entries of grad f (and the terminal input-rate term's gradient on
 * u_{NM-1}), given lx = dL/dx_s (the explicit partial derivative): X_s' lx - 2 R sum_{i<NM}
 * (u_i - u_s) (- 2 S (u_{NM-1} - u_s)) */
static void ass_grad_us(const gk_ws *ws, const double *w, const double *lx, double *grad) {
  const double *us = w + NUU;
  for (int c = 0; c < NU; c++) {
    double s = 0.0;
    for (int k = 0; k < NX; k++) s += ws->mem.XS[k * NU + c] * lx[k];
    for (int i = 0; i < NM; i++)
      for (int j = 0; j < NU; j++) s -= (w[i * NU + j] - us[j]) * (2.0 * ws->mem.rw[j * NU + c]);
    grad[NUU + c] += s;
  }
#if HAS_DU
  for (int j = 0; j < NU; j++) {
    const double d = 2.0 * ws->mem.dw[j] * (w[(NM - 1) * NU + j] - us[j]);
    grad[(NM - 1) * NU + j] += d;
    grad[NUU + j] -= d;
  }
#endif
}

static void ass_gradient(const gk_ws *ws, const double *w, const double *p, double *grad) {
  double gx[NX];
  ass_dcost_dxs(ws, p, gx);
  ass_grad_us(ws, w, gx, grad);
}

/* the u_s entries of the Lagrangian's gradient (lam_g' g: the terminal rows -I, the Y_s rows
 * D U_o, on x_s), lam_x included, after lagrangian_gradient filled the rest */
static void ass_lagrangian_gradient(const gk_ws *ws, const double *w, const double *p,
                                    const double *lam_x, const double *lg, double *gl) {
  const int r0 = (NH - 1) * NQ, r1 = r0 + 2 * NX;
  double lx[NX];
  ass_dcost_dxs(ws, p, lx);
  for (int k = 0; k < NX; k++) lx[k] -= lg[r0 + k] + lg[r0 + NX + k];
  for (int a = 0; a < NQ; a++)
    for (int k = 0; k < NX; k++) lx[k] += DUO[a * NX + k] * lg[r1 + a];
  ass_grad_us(ws, w, lx, gl);
  for (int c = 0; c < NU; c++) gl[NUU + c] += lam_x[NUU + c];
}

/* the u_s columns of the constraint Jacobian (column-major NG x NW): -X_s added to the
 * terminal rows (which hold S_N's u_s columns in the tail of a control horizon), the Y_s
 * rows */
static void ass_jacobian(const gk_ws *ws, double *J) {
  const int r0 = (NH - 1) * NQ, r1 = r0 + 2 * NX;
  for (int c = 0; c < NU; c++) {
    double *col = J + (NUU + c) * NG;
    for (int k = 0; k < NX; k++) {
      col[r0 + k] -= ws->mem.XS[k * NU + c];
      col[r0 + NX + k] -= ws->mem.XS[k * NU + c];
    }
    for (int a = 0; a < NQ; a++) {
      double s = 0.0;
      for (int k = 0; k < NX; k++) s += DUO[a * NX + k] * ws->mem.XS[k * NU + c];
      col[r1 + a] = s;
    }
  }
}

/* lf times the u_s rows of the Hessian's upper triangle (row-major NW x NW; before
 * hessian_finish mirrors it): the cross blocks -sum_{i>=1} S_i' 2Q X_s (and its transpose:
 * S_i's own u_s columns in the tail of a control horizon) and -2R per free stage (-2S on
 * u_{NM-1}), the block X_s' (2N Q + 2 U_o' T U_o) X_s + 2 NM R (+ 2S), and the terminal
 * input-rate term's 2S on u_{NM-1} */
HOT static void ass_hessian(gk_ws *ws, double lf, double *H) {
  double QX[NX * NU], MX[NX * NU];
  const double *XS = ws->mem.XS;
  for (int k = 0; k < NX; k++)
    for (int c = 0; c < NU; c++) {
      double s = 0.0, t = 0.0;
      for (int l = 0; l < NX; l++) s += 2.0 * QW[k * NX + l] * XS[l * NU + c];
      for (int a = 0; a < NY; a++) {
        double ux = 0.0;
        for (int l = 0; l < NX; l++) ux += UO[a * NX + l] * XS[l * NU + c];
        t += UO[a * NX + k] * 2.0 * ws->mem.tw[a] * ux;
      }
      QX[k * NU + c] = s;
      MX[k * NU + c] = NH * s + t;
    }
  /* sum_{i>=1} S_i' QX = (sum_{i>=1} S_i)' QX (S_i's columns from KC(i) on are zero: inputs
   * after stage i do not move x_i), the sum by contiguous rows */
  double *SS = ws->work.ass_ssum, V[NSC * NU];
  memset(SS, 0, sizeof ws->work.ass_ssum);
  for (int i = 1; i < NH; i++) {
    const double *Si = ws->mem.S + i * NX * NSC;
    const int K = KC(i);
    for (int k = 0; k < NX; k++) {
      double *__restrict sk = SS + k * NSC;
      const double *__restrict si = Si + k * NSC;
      for (int cc = 0; cc < K; cc++) sk[cc] += si[cc];
    }
  }
  for (int cc = 0; cc < NSC; cc++)
    for (int c = 0; c < NU; c++) {
      double s = 0.0;
      for (int k = 0; k < NX; k++) s += SS[k * NSC + cc] * QX[k * NU + c];
      V[cc * NU + c] = s;
    }
  for (int cc = 0; cc < NUU; cc++)
    for (int c = 0; c < NU; c++) H[cc * NW + NUU + c] -= lf * V[cc * NU + c];
  for (int a = 0; a < NSC - NUU; a++)   /* the tail's own u_s columns: V_us + V_us' */
    for (int b = a; b < NU; b++)
      H[(NUU + a) * NW + NUU + b] -= lf * (V[(NUU + a) * NU + b] + V[(NUU + b) * NU + a]);
  for (int i = 0; i < NM; i++)
    for (int a = 0; a < NU; a++)
      for (int b = 0; b < NU; b++) H[(i * NU + a) * NW + NUU + b] -= 2.0 * lf * ws->mem.rw[a * NU + b];
  for (int a = 0; a < NU; a++)
    for (int b = 0; b < NU; b++) {
      double s = 2.0 * NM * ws->mem.rw[a * NU + b];
      for (int k = 0; k < NX; k++) s += XS[k * NU + a] * MX[k * NU + b];
      H[(NUU + a) * NW + NUU + b] += lf * s;
    }
#if HAS_DU
  for (int j = 0; j < NU; j++) {
    const int r = (NM - 1) * NU + j;
    H[r * NW + r] += 2.0 * lf * ws->mem.dw[j];
    H[r * NW + NUU + j] -= 2.0 * lf * ws->mem.dw[j];
    H[(NUU + j) * NW + NUU + j] += 2.0 * lf * ws->mem.dw[j];
  }
#endif
}
#endif
