/* Part of the compiled FHOCP kernel (controllers/kernel/compiled_kernel.py joins the
 * generated header, gru_fhocp.h and the parts into one translation unit): the Hessian of
 * the Lagrangian, in its three variants (W-mode, backward condensing, contracted; chosen at
 * build time by controllers.kernel.compiled_kernel.choose_mode), and the curvature of x_s(u_s). */
/* ---------------------------------------------------------------- Hessian of the Lagrangian */
/* W = grad^2_(x,u) mu^T f(x, u) at a point with gates z, r, h and J_h = jh (NV x NV,
 * row-major, symmetric); Ph, Pz, Pr, G: NX x NV scratch */
VARIANT_ONLY HOT static void point_hessian(const double *x, const double *z, const double *r,
                                           const double *h, const double *jh, const double *mu,
                                           double *W, double *Ph, double *Pz, double *Pr,
                                           double *G) {
  double v[NX], nu[NX], d1[NX], d2[NX], d3[NX], d4[NX], d5[NX], d6[NX];
  for (int k = 0; k < NX; k++) {
    const double hp = 1.0 - h[k] * h[k];
    v[k] = mu[k] * (1.0 - z[k]) * hp;
    nu[k] = 0.0;
  }
  for (int k = 0; k < NX; k++) {      /* nu = U_h^T v */
    const double vk = v[k], *uh = UH + k * NX;
    for (int j = 0; j < NX; j++) nu[j] += vk * uh[j];
  }
  for (int k = 0; k < NX; k++) {
    const double zp = z[k] * (1.0 - z[k]), rp = r[k] * (1.0 - r[k]), hp = 1.0 - h[k] * h[k];
    const double zpp = zp * (1.0 - 2.0 * z[k]), rpp = rp * (1.0 - 2.0 * r[k]);
    const double hpp = -2.0 * h[k] * hp;
    d1[k] = mu[k] * (1.0 - z[k]) * hpp;
    d2[k] = nu[k] * rpp * x[k];
    d3[k] = mu[k] * (x[k] - h[k]) * zpp;
    d4[k] = mu[k] * zp * hp;
    d5[k] = mu[k] * zp;
    d6[k] = nu[k] * rp;
  }
  for (int k = 0; k < NX; k++) {
    const double *jhk = jh + k * NV, *jz = JZ + k * NV, *jr = JR + k * NV;
    double *ph = Ph + k * NV, *pz = Pz + k * NV, *pr = Pr + k * NV, *gk = G + k * NV;
    for (int c = 0; c < NV; c++) {
      ph[c] = d1[k] * jhk[c] - d4[k] * jz[c];
      pz[c] = d3[k] * jz[c] - d4[k] * jhk[c];
      pr[c] = d2[k] * jr[c];
      gk[c] = d5[k] * jz[c] + d6[k] * jr[c];
    }
  }
  /* W = J_h^T P_h + J_z^T P_z + J_r^T P_r (symmetric: upper triangle, then mirrored) */
#ifdef GK_BLAS_HESS   /* measured slower than the loops below (full instead of upper W) */
  rm_gemm(1, 0, NV, NV, NX, jh, NV, Ph, NV, 0.0, W, NV);
  rm_gemm(1, 0, NV, NV, NX, JZ, NV, Pz, NV, 1.0, W, NV);
  rm_gemm(1, 0, NV, NV, NX, JR, NV, Pr, NV, 1.0, W, NV);
#else
  /* the upper triangles (the lower one is overwritten by the mirror below) */
  gk_gemm_upper(1, NV, NV, NX, jh, NV, Ph, NV, W, NV, 0);
  gk_gemm_upper(1, NV, NV, NX, JZ, NV, Pz, NV, W, NV, 1);
  gk_gemm_upper(1, NV, NV, NX, JR, NV, Pr, NV, W, NV, 1);
#endif
  /* + T + T^T terms: W[a,b] += G[b,a] (b < NX) + G[a,b] (a < NX), upper triangle */
  for (int a = 0; a < NV; a++)
    for (int b = a; b < NV; b++) {
      double t = 0.0;
      if (b < NX) t += G[b * NV + a];
      if (a < NX) t += G[a * NV + b];
      W[a * NV + b] += t;
    }
  for (int a = 0; a < NV; a++)
    for (int b = 0; b < a; b++) W[a * NV + b] = W[b * NV + a];
}

#ifndef GK_CONTRACT
/* The blocks of stage i's Z_i' T Z_i (Z_i = [S_i; E_i], T: the stage's W_i, or its
 * Hessian-to-go in backward mode) that involve u_i, added into the upper triangle of H
 * (row-major NW x NW, mirrored by hessian_finish): C = (T^ux S_i)' (K x NU, C[c NU + j]) at
 * (w_c, u_i,j) and T^uu (+ 2 lf R on a free input, R = rw) at (u_i, u_i), u_i at column uc = UC(i).
 * In the tail of a control horizon (uc < K: u_i = u_s is one of S_i's columns) the u_s
 * block receives C + C' (both halves of S_us' T^xu + T^ux S_us). */
__attribute__((always_inline)) static inline void add_stage_input(double *H, const double *C,
                                                                int K, int uc, int free_u,
                                                                const double *T, double lf,
                                                                const double *rw) {
  const int kf = K < uc ? K : uc;
  for (int c = 0; c < kf; c++)
    for (int j = 0; j < NU; j++) H[c * NW + uc + j] += C[c * NU + j];
  for (int j1 = 0; j1 < NU; j1++)
    for (int j2 = j1; j2 < NU; j2++) {
      double v = T[(NX + j1) * NV + NX + j2] + (free_u ? 2.0 * lf * rw[j1 * NU + j2] : 0.0);
      if (uc < K) v += C[(uc + j1) * NU + j2] + C[(uc + j2) * NU + j1];
      H[(uc + j1) * NW + uc + j2] += v;
    }
}

/* W = grad^2_(x,u) mu^T f(x_i, u_i) of stage i (NV x NV, row-major, symmetric) */
HOT static void stage_hessian(gk_ws *ws, int i, const double *mu, double *W) {
  point_hessian(ws->mem.X + i * NX, ws->mem.ZG + i * NX, ws->mem.RG + i * NX, ws->mem.HG + i * NX,
                ws->mem.JH + i * NX * NV, mu, W, ws->work.Ph, ws->work.Pz, ws->work.Pr, ws->work.G);
}

/* adjoints mu_i = d(Lagrangian)/dx_i, i = N .. 1, into MU */
__attribute__((always_inline)) static inline void adjoints(const gk_ws *ws, const double *p,
                                                         double lf, const double *lg,
                                                         double *MU) {
  const double *xb = XREF(ws, p);
  const int r0 = (NH - 1) * NQ;
  for (int k = 0; k < NX; k++) MU[NH * NX + k] = lg[r0 + k] + lg[r0 + NX + k];
  for (int i = NH - 1; i >= 1; i--) {
    double *mu = MU + i * NX;
    const double *mun = MU + (i + 1) * NX, *df = ws->mem.DF + i * NX * NV;
    adjoint_local(ws, i, xb, lf, lg + (i - 1) * NQ, mu);
    for (int j = 0; j < NX; j++) {      /* + A_i^T mu_{i+1} */
      const double mj = mun[j], *dfj = df + j * NV;
      for (int k = 0; k < NX; k++) mu[k] += dfj[k] * mj;
    }
  }
}

#ifdef GK_BACKWARD
/* full Hessian of the Lagrangian, row-major NW x NW (symmetric), by backward condensing
 * (long horizons): the same sum sum_i Z_i^T W_i Z_i (+ costs) regrouped stage by stage from
 * the end. With T_i = W_i + [A_i B_i]^T P_{i+1} [A_i B_i] (+ 2 Q on x_i, i >= 1), P_N = 0
 * and P_i = T_i^xx (the Hessian-to-go of x_i):
 *   H[u_i, u_i] = T_i^uu + 2 R,   H[u_i, u_j] = T_i^ux S_i[:, j]  (j < i)
 * (with a control horizon, u_i = u_s in the tail: those blocks summed into u_s's by
 * add_stage_input, S_i's u_s columns already summing the earlier tail stages' inputs).
 * O(N n^3 + N^2 n m^2) instead of W-mode's O(N^2 n^2 m + N^3 n m^2). */
HOT static void hessian(gk_ws *ws, const double *w, const double *p, double lf, const double *lg,
                        double *H) {
  double *MU = ws->work.MU, *T = ws->work.W, *P = ws->work.P, *Y = ws->work.YB;
  (void)w;
  adjoints(ws, p, lf, lg, MU);
  memset(H, 0, sizeof(double) * NW * NW);
  for (int i = NH - 1; i >= 0; i--) {
    const double *df = ws->mem.DF + i * NX * NV;
    stage_hessian(ws, i, MU + (i + 1) * NX, T);
    if (i >= 1)
      for (int a = 0; a < NX; a++)
        for (int b = 0; b < NX; b++) T[a * NV + b] += 2.0 * lf * QW[a * NX + b];
    if (i < NH - 1) {     /* + D_f^T P_{i+1} D_f */
      gk_gemm(0, NX, NV, NX, P, NX, df, NV, Y, NV, 0);
      gk_gemm(1, NV, NV, NX, df, NV, Y, NV, T, NV, 1);
    }
    const int K = KC(i);
    const double *Si = ws->mem.S + i * NX * NSC;
    double C[NSC * NU];   /* (T^ux S_i)': H[w_c, u_i] */
    for (int j = 0; j < NU; j++) {
      const double *tj = T + (NX + j) * NV;
      for (int c = 0; c < K; c++) {
        double s = 0.0;
        for (int a = 0; a < NX; a++) s += tj[a] * Si[a * NSC + c];
        C[c * NU + j] = s;
      }
    }
    add_stage_input(H, C, K, UC(i), i < NM, T, lf, ws->mem.rw);
    for (int a = 0; a < NX; a++)
      for (int b = 0; b < NX; b++) P[a * NX + b] = T[a * NV + b];
  }
  hessian_finish(ws, p, lg, H, lf);
}
#else
/* full Hessian of the Lagrangian, row-major NW x NW (symmetric) */
HOT static void hessian(gk_ws *ws, const double *w, const double *p, double lf, const double *lg,
                        double *H) {
  double *MU = ws->work.MU, *W = ws->work.W, *Y = ws->work.Y;
  (void)w;
  adjoints(ws, p, lf, lg, MU);
  memset(H, 0, sizeof(double) * NW * NW);
  for (int i = 0; i < NH; i++) {
    stage_hessian(ws, i, MU + (i + 1) * NX, W);
    if (i >= 1)
      for (int a = 0; a < NX; a++)
        for (int b = 0; b < NX; b++) W[a * NV + b] += 2.0 * lf * QW[a * NX + b];
    const int K = KC(i);
    const double *Si = ws->mem.S + i * NX * NSC;
    double C[NSC * NU];   /* S_i' W_xu: H[w_c, u_i] */
    if (K > 0) {
#ifdef GK_BLAS_HESS
      rm_gemm(0, 0, NX, K, NX, W, NV, Si, NSC, 0.0, Y, NSC);
      rm_gemm(1, 0, K, K, NX, Si, NSC, Y, NSC, 1.0, H, NW);
#else
      /* Y = W_xx S_i (NX x K); H[:K, :K] += S_i^T Y (its upper triangle: the lower one is
       * overwritten by the mirror at the end) */
      gk_gemm(0, NX, K, NX, W, NV, Si, NSC, Y, NSC, 0);
      gk_gemm_upper(1, K, K, NX, Si, NSC, Y, NSC, H, NW, 1);
#endif
      for (int c = 0; c < K; c++)
        for (int j = 0; j < NU; j++) {
          double s = 0.0;
          for (int a = 0; a < NX; a++) s += Si[a * NSC + c] * W[a * NV + NX + j];
          C[c * NU + j] = s;
        }
    }
    add_stage_input(H, C, K, UC(i), i < NM, W, lf, ws->mem.rw);
  }
  hessian_finish(ws, p, lg, H, lf);
}
#endif /* GK_BACKWARD */

#else /* GK_CONTRACT */
/* Hessian of the Lagrangian, contracted mode: per stage
 *   Z^T W Z = L^T R,  L = [PH; PZ; PR; S; G],  R = [D1 PH - D4 PZ; D3 PZ - D4 PH; D2 PR; G; S]
 * with G = diag(d5) PZ + diag(d6) PR + lf Q S (the T + T^T terms of stage_hessian and the
 * state cost), i.e. the same sums as W-mode, regrouped; 5 n Kc^2 per stage. */
HOT static void hessian(gk_ws *ws, const double *w, const double *p, double lf, const double *lg,
                        double *H) {
  const double *xb = XREF(ws, p);
  double *MU = ws->work.MU, *L = ws->work.L, *R = ws->work.R, *QS = ws->work.QS;
  (void)w;
  const int r0 = (NH - 1) * NQ;
  for (int k = 0; k < NX; k++) MU[NH * NX + k] = lg[r0 + k] + lg[r0 + NX + k];
  for (int i = NH - 1; i >= 1; i--) {
    double *mu = MU + i * NX;
    adjoint_local(ws, i, xb, lf, lg + (i - 1) * NQ, mu);
    stage_vjp(ws, i, MU + (i + 1) * NX, mu, 0);   /* + A_i^T mu_{i+1} */
  }
  memset(H, 0, sizeof(double) * NW * NW);
  for (int i = 0; i < NH; i++) {
    const double *mu = MU + (i + 1) * NX;
    const double *x = ws->mem.X + i * NX, *z = ws->mem.ZG + i * NX, *r = ws->mem.RG + i * NX,
                 *h = ws->mem.HG + i * NX;
    const double *Si = ws->mem.S + i * NX * NUU;
    const double *pz = ws->mem.PZ + i * NX * NUU, *pr = ws->mem.PR + i * NX * NUU,
                 *ph = ws->mem.PH + i * NX * NUU;
    const int K = i * NU, Kc = K + NU;
    double vv[NX], nu[NX];
    for (int k = 0; k < NX; k++) {
      vv[k] = mu[k] * (1.0 - z[k]) * (1.0 - h[k] * h[k]);
      nu[k] = 0.0;
    }
    for (int k = 0; k < NX; k++) {
      const double vk = vv[k], *uh = UH + k * NX;
      for (int j = 0; j < NX; j++) nu[j] += vk * uh[j];
    }
    if (i >= 1) {
#if QDIAG
      for (int k = 0; k < NX; k++)
        for (int c = 0; c < K; c++) QS[k * NUU + c] = QW[k * NX + k] * Si[k * NUU + c];
#else
      mm(NX, K, NX, QW, NX, Si, NUU, QS, NUU);
#endif
    }
    for (int k = 0; k < NX; k++) {
      const double zp = z[k] * (1.0 - z[k]), rp = r[k] * (1.0 - r[k]), hp = 1.0 - h[k] * h[k];
      const double zpp = zp * (1.0 - 2.0 * z[k]), rpp = rp * (1.0 - 2.0 * r[k]);
      const double hpp = -2.0 * h[k] * hp;
      const double d1 = mu[k] * (1.0 - z[k]) * hpp, d2 = nu[k] * rpp * x[k];
      const double d3 = mu[k] * (x[k] - h[k]) * zpp, d4 = mu[k] * zp * hp;
      const double d5 = mu[k] * zp, d6 = nu[k] * rp;
      const double *phk = ph + k * NUU, *pzk = pz + k * NUU, *prk = pr + k * NUU;
      const double *sk = Si + k * NUU, *qsk = QS + k * NUU;
      double *L0 = L + k * NUU, *L1 = L + (NX + k) * NUU, *L2 = L + (2 * NX + k) * NUU;
      double *L3 = L + (3 * NX + k) * NUU, *L4 = L + (4 * NX + k) * NUU;
      double *R0 = R + k * NUU, *R1 = R + (NX + k) * NUU, *R2 = R + (2 * NX + k) * NUU;
      double *R3 = R + (3 * NX + k) * NUU, *R4 = R + (4 * NX + k) * NUU;
      for (int c = 0; c < Kc; c++) {
        const double sc = c < K ? sk[c] : 0.0;
        const double g = d5 * pzk[c] + d6 * prk[c] + ((i >= 1 && c < K) ? lf * qsk[c] : 0.0);
        L0[c] = phk[c]; R0[c] = d1 * phk[c] - d4 * pzk[c];
        L1[c] = pzk[c]; R1[c] = d3 * pzk[c] - d4 * phk[c];
        L2[c] = prk[c]; R2[c] = d2 * prk[c];
        L3[c] = sc;     R3[c] = g;
        L4[c] = g;      R4[c] = sc;
      }
    }
#ifdef GK_BLAS
    rm_gemm(1, 0, Kc, Kc, 5 * NX, L, NUU, R, NUU, 1.0, H, NW);
#else
    /* the upper triangle of L^T R (the lower one is overwritten by the mirror at the end) */
    gk_gemm_upper(1, Kc, Kc, 5 * NX, L, NUU, R, NUU, H, NW, 1);
#endif
    for (int j1 = 0; j1 < NU; j1++)
      for (int j2 = j1; j2 < NU; j2++) H[(K + j1) * NW + K + j2] += 2.0 * lf * ws->mem.rw[j1 * NU + j2];
  }
  hessian_finish(ws, p, lg, H, lf);
}
#endif /* GK_CONTRACT */


/* lf-independent part of the u_s block: the curvature of x_s(u_s), lambda' d2x_s/du_s2 with
 * lambda = dL/dx_s (the explicit partial: the cost's, the terminal rows' -I, the Y_s rows'
 * D U_o): Z' grad^2_(x,u)(mu' f) Z at (x_s, u_s), Z = [X_s; I], mu = (I - A_s)^-T lambda */
VARIANT_ONLY static void ass_curvature(gk_ws *ws, const double *p, double lf,
                                       const double *lg, double *H) {
#if HAS_ASS
  const int r0 = (NH - 1) * NQ, r1 = r0 + 2 * NX;
  double lx[NX], W[NV * NV];
  ass_dcost_dxs(ws, p, lx);
  for (int k = 0; k < NX; k++) {
    lx[k] *= lf;
    lx[k] -= lg[r0 + k] + lg[r0 + NX + k];
  }
  for (int a = 0; a < NQ; a++)
    for (int k = 0; k < NX; k++) lx[k] += DUO[a * NX + k] * lg[r1 + a];
  lu_solve_t(ws->mem.xs_lu, ws->mem.xs_piv, lx);
  point_hessian(ws->mem.xs, ws->mem.xs_z, ws->mem.xs_r, ws->mem.xs_h, ws->mem.xs_jh, lx, W, ws->work.xs_P,
                ws->work.xs_P + NX * NV, ws->work.xs_P + 2 * NX * NV, ws->work.xs_P + 3 * NX * NV);
  const double *XS = ws->mem.XS;
  for (int a = 0; a < NU; a++) {
    double za[NV];    /* W Z[:, a] */
    for (int k = 0; k < NV; k++) {
      double s = W[k * NV + NX + a];
      for (int l = 0; l < NX; l++) s += W[k * NV + l] * XS[l * NU + a];
      za[k] = s;
    }
    for (int b = 0; b < NU; b++) {
      double s = za[NX + b];
      for (int k = 0; k < NX; k++) s += XS[k * NU + b] * za[k];
      H[(NUU + b) * NW + NUU + a] += s;
    }
  }
#else
  (void)ws; (void)p; (void)lf; (void)lg; (void)H;
#endif
}
