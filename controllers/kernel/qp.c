/* Part of the compiled FHOCP kernel (controllers/kernel/compiled_kernel.py joins the
 * generated header, gru_fhocp.h and the parts into one translation unit): the QP of one SQP
 * iteration, dense and strictly convex, by the dual active-set method of Goldfarb and Idnani
 * (Math. Programming 27, 1983):
 *
 *     min 1/2 d'H d + g'd   s.t.  lbx <= d <= ubx,  lba <= A d <= uba
 *
 * H (NW x NW, row-major, symmetric positive definite: the eigenvalue-clipped Hessian) is
 * factorised once, H = L L'; the method starts at the unconstrained minimum -H^-1 g and adds
 * the most violated constraint at a time, dropping active ones whose multiplier would turn
 * negative; it keeps J = L^-T Q and the upper-triangular R of the QR factorisation of
 * L^-1 N_A (N_A: the active constraints' normals), updated by Givens rotations. Every
 * iteration raises the dual objective, linearly dependent constraints (the terminal rows
 * |x_N - x_bar|_k <= t at t = 0) are handled by pure dual steps, and no feasible starting
 * point is needed. Cost: the factorisation O(NW^3 / 3) twice, then O(NW^2 + NG NW) per
 * working-set change -- no rebuild of a projected Hessian when H changes (qpOASES' cost).
 *
 * Constraint k of the 2 (NW + NG) one-sided ones: index k >> 1 (bounds first, then the rows
 * of A), k & 1 = 0 the lower side (n = +a, n'd >= lb), 1 the upper side (n = -a, n'd >= -ub).
 * Multipliers are returned in casadi's convention (H d + g + A' lam_a + lam_x = 0: positive
 * at an active upper bound, negative at an active lower one). */
#define QP_INF 1e300

/* the normal n and right-hand side b of one-sided constraint k (A column-major NG x NW) */
static void qp_normal(int k, const double *A, const double *lbx, const double *ubx,
                      const double *lba, const double *uba, double *n, double *b) {
  const int i = k >> 1, up = k & 1;
  if (i < NW) {
    memset(n, 0, sizeof(double) * NW);
    n[i] = up ? -1.0 : 1.0;
    *b = up ? -ubx[i] : lbx[i];
  } else {
    const int r = i - NW;
    for (int j = 0; j < NW; j++) n[j] = up ? -A[j * NG + r] : A[j * NG + r];
    *b = up ? -uba[r] : lba[r];
  }
}

/* rotate columns a, b of J (stored by columns: qJ + j * NW) by (c, s) */
static inline void qp_rotate(double *a, double *b, double c, double s) {
  for (int i = 0; i < NW; i++) {
    const double x = a[i], y = b[i];
    a[i] = c * x + s * y;
    b[i] = -s * x + c * y;
  }
}

/* Returns a gk_qp_status (GK_QP_OPTIMAL, _INFEASIBLE, _CHANGE_LIMIT, _NOT_POSITIVE_DEFINITE).
 * d, lam_x (NW), lam_a (NG) written; *changes: working-set changes made. The factors and the
 * working set live in the workspace ws. */
HOT static int qp_solve(gk_ws *ws, const double *H, const double *g, const double *A,
                        const double *lbx, const double *ubx, const double *lba,
                        const double *uba, double *d, double *lam_x, double *lam_a,
                        int *changes) {
  double *qL = ws->work.qL, *qJ = ws->work.qJ, *qR = ws->work.qR, *qd = ws->work.qd, *qz = ws->work.qz, *qr = ws->work.qr,
         *qu = ws->work.qu, *qn = ws->work.qn, *qax = ws->work.qax;
  int *qact = ws->work.qact;
  unsigned char *qin = ws->work.qin;
  const int limit = 10 * (NW + NG);
  int status = GK_QP_OPTIMAL, q = 0, it = 0;
  *changes = 0;
  memset(qin, 0, sizeof ws->work.qin);
  /* H = L L' (row-major lower L; eigen_clip.c's Cholesky, unshifted) */
  if (!pd_shifted(H, NW, 0.0, qL)) { status = GK_QP_NOT_POSITIVE_DEFINITE; goto done; }
  /* M = L^-1 row by row; column j of J = L^-T is row j of M */
  for (int i = 0; i < NW; i++) {
    /* row i: (e_i - sum_{k<i} L[i][k] M_k) / L[i][i], M_k zero beyond column k */
    double *Mi = qJ + i * NW, *neg = qd;
    memset(Mi, 0, sizeof(double) * NW);
    Mi[i] = 1.0;
    for (int k = 0; k < i; k++) neg[k] = -qL[i * NW + k];
    gk_accumulate(Mi, Mi, i + 1, neg, qJ, NW, 0, i, 1);
    const double inv = 1.0 / qL[i * NW + i];
    for (int j = 0; j <= i; j++) Mi[j] *= inv;
  }
  /* d = -J J' g */
  for (int j = 0; j < NW; j++) qd[j] = gk_dot(qJ + j * NW, g, NW);
  memset(d, 0, sizeof(double) * NW);
  for (int j = 0; j < NW; j++) qd[j] = -qd[j];
  gk_accumulate(d, d, NW, qd, qJ, NW, 0, NW, 0);
  for (;;) {
    /* the most violated constraint */
    int p = -1;
    double smin = -1e-11;
    for (int i = 0; i < NW; i++) {
      if (!qin[2 * i] && lbx[i] > -QP_INF && d[i] - lbx[i] < smin) { smin = d[i] - lbx[i]; p = 2 * i; }
      if (!qin[2 * i + 1] && ubx[i] < QP_INF && ubx[i] - d[i] < smin) { smin = ubx[i] - d[i]; p = 2 * i + 1; }
    }
    memset(qax, 0, sizeof ws->work.qax);
    gk_accumulate(qax, qax, NG, d, A, NG, 0, NW, 0);
    for (int r = 0; r < NG; r++) {
      const int k = 2 * (NW + r);
      if (!qin[k] && lba[r] > -QP_INF && qax[r] - lba[r] < smin) { smin = qax[r] - lba[r]; p = k; }
      if (!qin[k + 1] && uba[r] < QP_INF && uba[r] - qax[r] < smin) { smin = uba[r] - qax[r]; p = k + 1; }
    }
    if (p < 0) break;
    double bp;
    qp_normal(p, A, lbx, ubx, lba, uba, qn, &bp);
    qu[q] = 0.0;
    for (;;) {   /* add p, dropping active constraints on the way */
      if (++it > limit) { status = GK_QP_CHANGE_LIMIT; goto done; }
      if ((p >> 1) < NW) {   /* a bound: J' n is a row of J */
        const int i = p >> 1;
        const double sg = (p & 1) ? -1.0 : 1.0;
        for (int j = 0; j < NW; j++) qd[j] = sg * qJ[j * NW + i];
      } else {
        for (int j = 0; j < NW; j++) qd[j] = gk_dot(qJ + j * NW, qn, NW);
      }
      /* primal direction z = J2 d2, dual direction r = R^-1 d1 */
      double zn = 0.0, dd = 0.0;
      for (int j = 0; j < NW; j++) dd += qd[j] * qd[j];
      for (int j = q; j < NW; j++) zn += qd[j] * qd[j];   /* = z'n */
      const int dependent = !(zn > 1e-24 * dd);
      if (!dependent) {
        memset(qz, 0, sizeof ws->work.qz);
        gk_accumulate(qz, qz, NW, qd, qJ, NW, q, NW, 0);
      }
      for (int i = q - 1; i >= 0; i--) {
        double t = qd[i];
        for (int k = i + 1; k < q; k++) t -= qR[i * NW + k] * qr[k];
        qr[i] = t / qR[i * NW + i];
      }
      /* partial step (an active multiplier reaches zero) and full step (p satisfied) */
      double t1 = INFINITY, s = -bp;
      int l = -1;
      for (int k = 0; k < q; k++)
        if (qr[k] > 0.0 && qu[k] / qr[k] < t1) { t1 = qu[k] / qr[k]; l = k; }
      for (int i = 0; i < NW; i++) s += qn[i] * d[i];
      const double t2 = dependent ? INFINITY : -s / zn;
      const double t = t1 < t2 ? t1 : t2;
      if (!(t < INFINITY)) { status = GK_QP_INFEASIBLE; goto done; }
      for (int k = 0; k < q; k++) qu[k] -= t * qr[k];
      qu[q] += t;
      if (!dependent) {
        for (int i = 0; i < NW; i++) d[i] += t * qz[i];
        if (t2 <= t1) {   /* full step: p joins the working set */
          for (int j = NW - 1; j > q; j--) {
            const double a = qd[j - 1], b = qd[j], h = gk_hypot(a, b);
            if (b == 0.0) continue;
            qd[j - 1] = h;
            qd[j] = 0.0;
            qp_rotate(qJ + (j - 1) * NW, qJ + j * NW, a / h, b / h);
          }
          for (int k = 0; k <= q; k++) qR[k * NW + q] = qd[k];
          qact[q] = p;
          qin[p] = 1;
          q++;
          (*changes)++;
          break;
        }
      }
      /* drop active constraint l; R (upper Hessenberg from column l) back to triangular */
      qin[qact[l]] = 0;
      for (int k = l; k < q - 1; k++) {
        qact[k] = qact[k + 1];
        qu[k] = qu[k + 1];
        for (int i = 0; i <= k + 1; i++) qR[i * NW + k] = qR[i * NW + k + 1];
      }
      qu[q - 1] = qu[q];
      for (int k = l; k < q - 1; k++) {
        const double a = qR[k * NW + k], b = qR[(k + 1) * NW + k], h = gk_hypot(a, b);
        if (b == 0.0) continue;
        const double c = a / h, sn = b / h;
        qR[k * NW + k] = h;
        qR[(k + 1) * NW + k] = 0.0;
        for (int j = k + 1; j < q - 1; j++) {
          const double x = qR[k * NW + j], y = qR[(k + 1) * NW + j];
          qR[k * NW + j] = c * x + sn * y;
          qR[(k + 1) * NW + j] = -sn * x + c * y;
        }
        qp_rotate(qJ + k * NW, qJ + (k + 1) * NW, c, sn);
      }
      q--;
      (*changes)++;
    }
  }
done:
  memset(lam_x, 0, sizeof(double) * NW);
  memset(lam_a, 0, sizeof(double) * NG);
  for (int k = 0; k < q; k++) {
    const int c = qact[k], i = c >> 1;
    const double lam = (c & 1) ? qu[k] : -qu[k];
    if (i < NW) lam_x[i] = lam;
    else lam_a[i - NW] = lam;
  }
  return status;
}

/* test hook: one QP of this kernel's dimensions (H row-major NW x NW, A column-major NG x NW,
 * bounds +-1e300 or beyond for none) in workspace ws; returns qp_solve's status */
EXPORT int PFX(qp)(gk_ws *ws, const double *H, const double *g, const double *A,
                   const double *lbx, const double *ubx, const double *lba, const double *uba,
                   double *d, double *lam_x, double *lam_a, int *changes) {
  return qp_solve(ws, H, g, A, lbx, ubx, lba, uba, d, lam_x, lam_a, changes);
}
