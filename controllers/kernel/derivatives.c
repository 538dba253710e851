/* Part of the compiled FHOCP kernel (controllers/kernel/compiled_kernel.py joins the
 * generated header, gru_fhocp.h and the parts into one translation unit): f, g, their
 * derivatives and the adjoints (the Hessian of the Lagrangian: hessian.c). */
/* ---------------------------------------------------------------- f, g, grad f, jac g */
/* acc + (v - ref)^T W (v - ref), n <= NX + NU, W row-major n x n (terms added one by one) */
__attribute__((always_inline)) static inline double add_quad(
    double acc, const double *v, const double *ref, const double *W, int n, int diag) {
  double d[NX + NU];
  for (int k = 0; k < n; k++) d[k] = v[k] - ref[k];
  if (diag) {   /* the same sums: the off-diagonal terms are exact zeros */
    for (int k = 0; k < n; k++) acc += (d[k] * W[k * n + k]) * d[k];
    return acc;
  }
  for (int k = 0; k < n; k++) {
    double s = 0.0;
    for (int j = 0; j < n; j++) s += d[j] * W[j * n + k];
    acc += s * d[k];
  }
  return acc;
}

#if HAS_DU
/* The input-rate term (controllers/ocp/input_rate.py) of inputs u (nst x NU) after up = u_{-1}:
 * sum_i (u_i - u_{i-1})' diag(DW) (u_i - u_{i-1}); nst = NM on w (the free inputs: with a
 * control horizon the step to u_s is the tracking law's last term, ass_cost), NH on a
 * rollout's inputs */
static double du_cost(const double *dw, const double *u, const double *up, int nst) {
  double acc = 0.0;
  for (int i = 0; i < nst; i++) {
    const double *prev = i ? u + (i - 1) * NU : up;
    for (int j = 0; j < NU; j++) {
      const double d = u[i * NU + j] - prev[j];
      acc += (d * dw[j]) * d;
    }
  }
  return acc;
}

/* its gradient on w's free inputs 2 DW (d_i - d_{i+1}) (d_NM = 0) added into g (NUU) */
static void du_gradient(const double *dw, const double *u, const double *up, double *g) {
  for (int i = 0; i < NM; i++)
    for (int j = 0; j < NU; j++) {
      const double *prev = i ? u + (i - 1) * NU : up;
      double s = u[i * NU + j] - prev[j];
      if (i + 1 < NM) s -= u[(i + 1) * NU + j] - u[i * NU + j];
      g[i * NU + j] += 2.0 * dw[j] * s;
    }
}

/* lf times its constant Hessian 2 D' diag(DW) D added into the upper triangle of H (row-major
 * NW x NW): 4 DW on the diagonal blocks (2 DW on the last), -2 DW on the first superdiagonal
 * block (before hessian_finish mirrors the triangle) */
static void du_hessian(const double *dw, double lf, double *H) {
  for (int i = 0; i < NM; i++)
    for (int j = 0; j < NU; j++) {
      const int r = i * NU + j;
      H[r * NW + r] += 2.0 * lf * dw[j] * (i + 1 < NM ? 2.0 : 1.0);
      if (i + 1 < NM) H[r * NW + r + NU] -= 2.0 * lf * dw[j];
    }
}
#endif

HOT static double cost(const gk_ws *ws, const double *w, const double *p) {
  const double *xb = XREF(ws, p), *ub = UREF(w, p), t = w[IT];
  double acc = 0.0;
  for (int i = 0; i < NH; i++) acc = add_quad(acc, ws->mem.X + i * NX, xb, QW, NX, QDIAG);
  for (int i = 0; i < NM; i++) acc = add_quad(acc, w + i * NU, ub, ws->mem.rw, NU, 0);   /* tail: 0 */
#if HAS_ASS
  acc += ass_cost(ws, w, p);
#endif
#if SOFT
  acc += soft_penalty(ws->mem.slw, ws->mem.slq, w + IS);
#endif
#if HAS_DU
  return acc + SW * t * t + du_cost(ws->mem.dw, w, UPREV(p), NM);
#else
  return acc + SW * t * t;
#endif
}

#if HAS_MOVE
/* the move rows (MoveRows.rows): v_{i+1} - v_i along u_0 .. u_{NM-1}, u_end */
static void move_constraints(const double *w, const double *p, double *g) {
  const double *end = UREF(w, p);
  (void)p;
  for (int i = 0; i < NM; i++)
    for (int j = 0; j < NU; j++) {
      const double next = i + 1 < NM ? w[(i + 1) * NU + j] : end[j];
      g[RMV + i * NU + j] = next - w[i * NU + j];
    }
}

/* their columns of the column-major NG x NW Jacobian (MoveRows.jacobian) */
static void move_jacobian(double *J) {
  for (int i = 0; i < NM; i++)
    for (int j = 0; j < NU; j++) {
      const int r = RMV + i * NU + j;
      J[(i * NU + j) * NG + r] = -1.0;
      if (i + 1 < NM || HAS_ASS) J[((i + 1) * NU + j) * NG + r] = 1.0;
    }
}

/* their share of the Lagrangian's gradient, J' lam_g over the move rows (the columns above) */
static void move_lagrangian_gradient(const double *lg, double *gl) {
  for (int i = 0; i < NM; i++)
    for (int j = 0; j < NU; j++) {
      const double l = lg[RMV + i * NU + j];
      gl[i * NU + j] -= l;
      if (i + 1 < NM || HAS_ASS) gl[(i + 1) * NU + j] += l;
    }
}
#endif

HOT static void constraints(const gk_ws *ws, const double *w, const double *p, double *g) {
  const double *xb = XREF(ws, p), t = w[IT], *X = ws->mem.X;
  for (int i = 1; i < NH; i++)
    for (int a = 0; a < NQ; a++) {
      double s = 0.0;
      for (int k = 0; k < NX; k++) s += DUO[a * NX + k] * X[i * NX + k];
      g[(i - 1) * NQ + a] = s;
    }
  const double *xN = X + NH * NX;
  for (int k = 0; k < NX; k++) {
    const double d = xN[k] - xb[k];
    g[(NH - 1) * NQ + k] = d - t;
    g[(NH - 1) * NQ + NX + k] = d + t;
  }
#if HAS_ASS
  ass_constraints(ws, g);
#endif
#if SOFT
  soft_constraints(w + IS, g);
#endif
#if HAS_MOVE
  move_constraints(w, p, g);
#endif
}

HOT static void gradient(const gk_ws *ws, const double *w, const double *p, double *grad) {
  const double *xb = XREF(ws, p), *ub = UREF(w, p), *X = ws->mem.X, *S = ws->mem.S;
  for (int c = 0; c < NUA; c++) grad[c] = 0.0;
  for (int i = 1; i < NH; i++) {
    double dq[NX];
    for (int k = 0; k < NX; k++) {
      double s = 0.0;
      for (int j = 0; j < NX; j++) s += (X[i * NX + j] - xb[j]) * (2.0 * QW[j * NX + k]);
      dq[k] = s;
    }
    const double *Si = S + i * NX * NSC;
    const int K = KC(i);
    for (int k = 0; k < NX; k++) {
      const double a = dq[k], *sk = Si + k * NSC;
      for (int c = 0; c < K; c++) grad[c] += a * sk[c];
    }
  }
  for (int i = 0; i < NM; i++)
    for (int k = 0; k < NU; k++) {
      double s = 0.0;
      for (int j = 0; j < NU; j++) s += (w[i * NU + j] - ub[j]) * (2.0 * ws->mem.rw[j * NU + k]);
      grad[i * NU + k] += s;
    }
#if HAS_DU
  du_gradient(ws->mem.dw, w, UPREV(p), grad);
#endif
#if HAS_ASS
  ass_gradient(ws, w, p, grad);
#endif
  grad[IT] = 2.0 * SW * w[IT];
#if SOFT
  for (int j = 0; j < NSL; j++) grad[IS + j] = ws->mem.slw + 2.0 * ws->mem.slq * w[IS + j];
#endif
}

/* dense column-major NG x NW */
HOT static void jacobian(const gk_ws *ws, double *J) {
  const double *S = ws->mem.S;
  memset(J, 0, sizeof(double) * NG * NW);
  for (int i = 1; i < NH; i++) {
    const double *Si = S + i * NX * NSC;
    const int K = KC(i);
    for (int a = 0; a < NQ; a++) {
      double row[NSC];
      for (int c = 0; c < K; c++) row[c] = 0.0;
      for (int k = 0; k < NX; k++) {
        const double d = DUO[a * NX + k], *sk = Si + k * NSC;
        for (int c = 0; c < K; c++) row[c] += d * sk[c];
      }
      const int r = (i - 1) * NQ + a;
      for (int c = 0; c < K; c++) J[c * NG + r] = row[c];
    }
  }
  const double *SN = S + NH * NX * NSC;
  const int r0 = (NH - 1) * NQ;
  for (int c = 0; c < NSC; c++) {
    double *col = J + c * NG + r0;
    for (int k = 0; k < NX; k++) {
      col[k] = SN[k * NSC + c];
      col[NX + k] = SN[k * NSC + c];
    }
  }
  for (int k = 0; k < NX; k++) {
    J[IT * NG + r0 + k] = -1.0;
    J[IT * NG + r0 + NX + k] = 1.0;
  }
#if HAS_ASS
  ass_jacobian(ws, J);
#endif
#if SOFT
  soft_jacobian(J);
#endif
#if HAS_MOVE
  move_jacobian(J);
#endif
}

/* the last lines of every Hessian variant: the input-rate term's constant Hessian (HAS_DU),
 * the artificial steady input's rows (HAS_ASS), the upper triangle of the input block
 * mirrored into the lower one, and the terminal slack's entry */
VARIANT_ONLY static void ass_curvature(gk_ws *ws, const double *p, double lf,
                                       const double *lg, double *H);

__attribute__((always_inline)) static inline void hessian_finish(gk_ws *ws, const double *p,
                                                               const double *lg, double *H,
                                                               double lf) {
#if HAS_DU
  du_hessian(ws->mem.dw, lf, H);
#endif
#if HAS_ASS
  ass_hessian(ws, lf, H);
  ass_curvature(ws, p, lf, lg, H);
#else
  (void)ws; (void)p; (void)lg;
#endif
  for (int r = 0; r < NUA; r++)
    for (int c = 0; c < r; c++) H[r * NW + c] = H[c * NW + r];
  H[IT * NW + IT] = 2.0 * lf * SW;
#if SOFT
  for (int j = 0; j < NSL; j++) H[(IS + j) * NW + IS + j] = 2.0 * lf * ws->mem.slq;
#endif
}

/* ---------------------------------------------------------------- adjoints */
/* the local part of the adjoint mu_i = dL/dx_i (1 <= i < N): 2 lf Q (x_i - x_bar) + D' lam_i
 * (lam_i: the multipliers of stage i's output rows), into mu */
__attribute__((always_inline)) static inline void adjoint_local(const gk_ws *ws, int i,
                                                              const double *xb, double lf,
                                                              const double *lam, double *mu) {
  const double *X = ws->mem.X;
  for (int k = 0; k < NX; k++) {
    double s = 0.0;
    for (int j = 0; j < NX; j++) s += (X[i * NX + j] - xb[j]) * QW[j * NX + k];
    s *= 2.0 * lf;
    for (int a = 0; a < NQ; a++) s += lam[a] * DUO[a * NX + k];
    mu[k] = s;
  }
}

/* v' [A_i B_i] of stage i without forming [A_i B_i] (a vector-Jacobian product of eq:gru,
 * O(n^2)): gx += A_i' v and, when gu is not NULL, gu = B_i' v. With x+ = h + z (x - h):
 * [A B]' v = J_z' (a v) + J_h' (b v) + [z v; 0], a = (x - h) z (1 - z), b = (1 - z)(1 - h^2),
 * and J_h' y = J_r' (c1 q) + [r q; W_h' y], q = U_h' y, c1 = x r (1 - r). */
__attribute__((always_inline)) static inline void stage_vjp(const gk_ws *ws, int i,
                                                          const double *v, double *gx,
                                                          double *gu) {
  const double *x = ws->mem.X + i * NX, *z = ws->mem.ZG + i * NX, *r = ws->mem.RG + i * NX,
               *h = ws->mem.HG + i * NX;
  double av[NX], bv[NX], q[NX], cq[NX];
  for (int k = 0; k < NX; k++) {
    const double zp = z[k] * (1.0 - z[k]), hp = 1.0 - h[k] * h[k];
    av[k] = (x[k] - h[k]) * zp * v[k];
    bv[k] = (1.0 - z[k]) * hp * v[k];
    q[k] = 0.0;
  }
  for (int k = 0; k < NX; k++) {
    const double bk = bv[k], *uh = UH + k * NX;
    for (int j = 0; j < NX; j++) q[j] += bk * uh[j];
  }
  for (int k = 0; k < NX; k++) cq[k] = x[k] * (r[k] * (1.0 - r[k])) * q[k];
  for (int k = 0; k < NX; k++) {
    const double ak = av[k], ck = cq[k], *uz = UZ + k * NX, *ur = UR + k * NX;
    for (int j = 0; j < NX; j++) gx[j] += ak * uz[j] + ck * ur[j];
  }
  for (int k = 0; k < NX; k++) gx[k] += r[k] * q[k] + z[k] * v[k];
  if (gu)
    for (int c = 0; c < NU; c++) {
      double s = 0.0;
      for (int k = 0; k < NX; k++)
        s += WZ[k * NU + c] * av[k] + WR[k * NU + c] * cq[k] + WH[k * NU + c] * bv[k];
      gu[c] = s;
    }
}
