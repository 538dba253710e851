/* Part of the compiled FHOCP kernel (controllers/kernel/compiled_kernel.py joins the
 * generated header, gru_fhocp.h and the parts into one translation unit): eigenvalue clipping of the Hessian (convex QPs for the SQP). */
/* ---------------------------------------------------------------- eigenvalue clipping */
/* Householder tridiagonalisation + implicit QL (JAMA / EISPACK tred2, tql2). V (n x n,
 * row-major) holds the symmetric matrix on entry, the eigenvectors as ROWS on exit (row j:
 * eigenvector of d[j]); d the eigenvalues (unsorted). Returns 0, or -1 when QL does not
 * converge. */
HOT static void tred2(int n, double *V, double *d, double *e) {
#define VV(i, j) V[(i) * n + (j)]
  for (int j = 0; j < n; j++) d[j] = VV(n - 1, j);
  for (int i = n - 1; i > 0; i--) {
    double scale = 0.0, h = 0.0;
    for (int k = 0; k < i; k++) scale += fabs(d[k]);
    if (scale == 0.0) {
      e[i] = d[i - 1];
      for (int j = 0; j < i; j++) {
        d[j] = VV(i - 1, j);
        VV(i, j) = 0.0;
        VV(j, i) = 0.0;
      }
    } else {
      for (int k = 0; k < i; k++) {
        d[k] /= scale;
        h += d[k] * d[k];
      }
      double f = d[i - 1], g = sqrt(h);
      if (f > 0) g = -g;
      e[i] = scale * g;
      h = h - f * g;
      d[i - 1] = f - g;
      for (int j = 0; j < i; j++) e[j] = 0.0;
      for (int j = 0; j < i; j++) {
        f = d[j];
        VV(j, i) = f;
        g = e[j] + VV(j, j) * f;
        for (int k = j + 1; k <= i - 1; k++) {
          g += VV(k, j) * d[k];
          e[k] += VV(k, j) * f;
        }
        e[j] = g;
      }
      f = 0.0;
      for (int j = 0; j < i; j++) {
        e[j] /= h;
        f += e[j] * d[j];
      }
      const double hh = f / (h + h);
      for (int j = 0; j < i; j++) e[j] -= hh * d[j];
      for (int j = 0; j < i; j++) {
        f = d[j];
        g = e[j];
        for (int k = j; k <= i - 1; k++) VV(k, j) -= (f * e[k] + g * d[k]);
        d[j] = VV(i - 1, j);
        VV(i, j) = 0.0;
      }
    }
    d[i] = h;
  }
  for (int i = 0; i < n - 1; i++) {
    VV(n - 1, i) = VV(i, i);
    VV(i, i) = 1.0;
    const double h = d[i + 1];
    if (h != 0.0) {
      for (int k = 0; k <= i; k++) d[k] = VV(k, i + 1) / h;
      for (int j = 0; j <= i; j++) {
        double g = 0.0;
        for (int k = 0; k <= i; k++) g += VV(k, i + 1) * VV(k, j);
        for (int k = 0; k <= i; k++) VV(k, j) -= g * d[k];
      }
    }
    for (int k = 0; k <= i; k++) VV(k, i + 1) = 0.0;
  }
  for (int j = 0; j < n; j++) {
    d[j] = VV(n - 1, j);
    VV(n - 1, j) = 0.0;
  }
  VV(n - 1, n - 1) = 1.0;
  e[0] = 0.0;
#undef VV
}

/* hypot(a, b) by one square root where no square can overflow or underflow (libm's hypot,
 * correctly rounded, cost as much as the rest of a QL rotation; also the QP's Givens) */
static inline double gk_hypot(double a, double b) {
  const double m = fmax(fabs(a), fabs(b));
  return (m > 1e-150 && m < 1e150) ? sqrt(a * a + b * b) : hypot(a, b);
}

/* V NULL: the eigenvalues only (tql1), the same d as with V */
HOT static int tql2(int n, double *V, double *d, double *e) {
#define VV(i, j) V[(i) * n + (j)]
  /* transpose: eigenvector j becomes row j, so that the QL rotations act on two
   * contiguous rows (vectorisable) */
  if (V)
    for (int i = 0; i < n; i++)
      for (int j = i + 1; j < n; j++) {
        const double tmp = VV(i, j);
        VV(i, j) = VV(j, i);
        VV(j, i) = tmp;
      }
  /* QL */
  for (int i = 1; i < n; i++) e[i - 1] = e[i];
  e[n - 1] = 0.0;
  double f = 0.0, tst1 = 0.0;
  const double eps = 2.220446049250313e-16;
  for (int l = 0; l < n; l++) {
    tst1 = fmax(tst1, fabs(d[l]) + fabs(e[l]));
    int m = l;
    while (m < n) {
      if (fabs(e[m]) <= eps * tst1) break;
      m++;
    }
    if (m == n) m = n - 1;
    if (m > l) {
      int iter = 0;
      do {
        if (++iter > 60) return -1;
        double g = d[l];
        double p = (d[l + 1] - g) / (2.0 * e[l]);
        double r = gk_hypot(p, 1.0);
        if (p < 0) r = -r;
        d[l] = e[l] / (p + r);
        d[l + 1] = e[l] * (p + r);
        const double dl1 = d[l + 1];
        double h = g - d[l];
        for (int i = l + 2; i < n; i++) d[i] -= h;
        f += h;
        p = d[m];
        double c = 1.0, c2 = c, c3 = c, s = 0.0, s2 = 0.0;
        const double el1 = e[l + 1];
        for (int i = m - 1; i >= l; i--) {
          c3 = c2;
          c2 = c;
          s2 = s;
          g = c * e[i];
          h = c * p;
          r = gk_hypot(p, e[i]);
          e[i + 1] = s * r;
          s = e[i] / r;
          c = p / r;
          p = c * d[i] - s * g;
          d[i + 1] = h + s * (c * g + s * d[i]);
          if (!V) continue;
          double *vi = V + i * n, *vi1 = V + (i + 1) * n;
          for (int k = 0; k < n; k++) {
            const double hk = vi1[k], gk = vi[k];
            vi1[k] = s * gk + c * hk;
            vi[k] = c * gk - s * hk;
          }
        }
        p = -s * s2 * c3 * el1 * e[l] / dl1;
        e[l] = s * p;
        d[l] = c * p;
      } while (fabs(e[l]) > eps * tst1);
    }
    d[l] += f;
    e[l] = 0.0;
  }
  return 0;
#undef VV
}

VARIANT_ONLY static int symm_eig(int n, double *V, double *d, double *e) {
  tred2(n, V, d, e);
  return tql2(n, V, d, e);
}

/* Householder reduction of the symmetric A (n x n, row-major, both triangles) to the
 * tridiagonal T = Q' A Q, Q = H_0 H_1 ... H_{n-3}, H_k = I - tau_k v_k v_k' (LAPACK dsytd2's
 * reflectors, applied to the full trailing block so that every update is a contiguous row):
 * d the diagonal, e[i] = T[i][i-1] (e[0] = 0, tred2's layout), v_k = (0 .. 0, 1,
 * A[k][k+2 .. n-1]) left in row k of A, tau_k in tau[k]; p: n scratch. Q is not formed. */
VARIANT_ONLY HOT static void householder_tridiagonal(int n, double *A, double *d, double *e,
                                                     double *tau, double *p) {
  e[0] = 0.0;
  for (int k = 0; k + 2 < n; k++) {
    double *x = A + k * n + k + 1;   /* column k below the diagonal (= row k, symmetric) */
    const int m = n - k - 1;
    double sigma = 0.0;
    for (int i = 1; i < m; i++) sigma += x[i] * x[i];
    d[k] = A[k * n + k];
    if (sigma == 0.0) {              /* already tridiagonal in this column: H_k = I */
      tau[k] = 0.0;
      e[k + 1] = x[0];
      continue;
    }
    const double alpha = x[0], beta = -copysign(sqrt(alpha * alpha + sigma), alpha);
    const double t = (beta - alpha) / beta, scale = 1.0 / (alpha - beta);
    tau[k] = t;
    e[k + 1] = beta;
    x[0] = 1.0;
    for (int i = 1; i < m; i++) x[i] *= scale;
    /* p = tau A22 v, w = p - (tau/2)(p'v) v, A22 -= v w' + w v' */
    double pv = 0.0;
    for (int r = 0; r < m; r++) {
      const double *__restrict ar = A + (k + 1 + r) * n + k + 1;
      double s = 0.0;
      for (int c = 0; c < m; c++) s += ar[c] * x[c];
      p[r] = t * s;
      pv += p[r] * x[r];
    }
    const double kk = 0.5 * t * pv;
    for (int r = 0; r < m; r++) p[r] -= kk * x[r];
    for (int r = 0; r < m; r++) {
      double *__restrict ar = A + (k + 1 + r) * n + k + 1;
      const double vr = x[r], wr = p[r];
#pragma GCC ivdep
      for (int c = 0; c < m; c++) ar[c] -= vr * p[c] + wr * x[c];
    }
  }
  if (n >= 2) {
    d[n - 2] = A[(n - 2) * n + n - 2];
    e[n - 1] = A[(n - 1) * n + n - 2];
    tau[n - 2] = 0.0;
  }
  d[n - 1] = A[(n - 1) * n + n - 1];
  tau[n - 1] = 0.0;
}

/* the eigenvector y (n) of the tridiagonal (d, e: T[i][i-1] = e[i]) for its eigenvalue lam,
 * by inverse iteration (LU of T - lam I with partial pivoting, solves from a fixed start,
 * each orthogonalised against the nvec vectors in prev, rows of n: the eigenvalues below
 * it, as LAPACK dstein does within a cluster), until the residual |T y - lam y|inf <= tol
 * after the second solve or later (0), at most four solves (else -1). lu: 4 n, piv: n
 * scratch. */
VARIANT_ONLY static int tridiagonal_eigenvector(int n, const double *d, const double *e,
                                                double lam, const double *prev, int nvec,
                                                double tol, double *y, double *lu,
                                                unsigned char *piv) {
  double *a = lu, *b = lu + n, *c = lu + 2 * n, *f = lu + 3 * n;   /* U: a, b, c; L: f */
  const double tiny = fmax(tol / (64.0 * n), 1e-300);   /* eps |T|: a zero pivot's stand-in */
  /* LU of T - lam I, row i: (e[i], d[i] - lam, e[i+1]) */
  a[0] = d[0] - lam;
  b[0] = n > 1 ? e[1] : 0.0;
  for (int i = 0; i + 1 < n; i++) {
    const double sub = e[i + 1], diag = d[i + 1] - lam, sup = i + 2 < n ? e[i + 2] : 0.0;
    c[i] = 0.0;
    if (fabs(a[i]) >= fabs(sub)) {         /* no swap: row i + 1 -= f row i */
      piv[i] = 0;
      f[i] = a[i] != 0.0 ? sub / a[i] : 0.0;
      a[i + 1] = diag - f[i] * b[i];
      b[i + 1] = sup;
    } else {                               /* swap rows i, i + 1 */
      piv[i] = 1;
      f[i] = a[i] / sub;
      a[i] = sub;
      const double bi = b[i];
      b[i] = diag;
      c[i] = sup;
      a[i + 1] = bi - f[i] * diag;
      b[i + 1] = -f[i] * sup;
    }
  }
  c[n - 1] = 0.0;
  for (int i = 0; i < n; i++) {
    if (fabs(a[i]) < tiny) a[i] = copysign(tiny, a[i]);   /* lam is an eigenvalue */
    y[i] = 1.0 / sqrt((double)n) * (1.0 + 0.01 * (i % 7));
  }
  for (int it = 0; it < 4; it++) {
    for (int i = 0; i + 1 < n; i++) {      /* L: the row operations, in order */
      if (piv[i]) {
        const double t = y[i];
        y[i] = y[i + 1];
        y[i + 1] = t - f[i] * y[i + 1];
      } else {
        y[i + 1] -= f[i] * y[i];
      }
    }
    for (int i = n - 1; i >= 0; i--) {     /* U */
      double s = y[i];
      if (i + 1 < n) s -= b[i] * y[i + 1];
      if (i + 2 < n) s -= c[i] * y[i + 2];
      y[i] = s / a[i];
    }
    for (int j = 0; j < nvec; j++) {
      const double *q = prev + j * n;
      double s = 0.0;
      for (int i = 0; i < n; i++) s += q[i] * y[i];
      for (int i = 0; i < n; i++) y[i] -= s * q[i];
    }
    double nrm = 0.0;
    for (int i = 0; i < n; i++) nrm += y[i] * y[i];
    nrm = sqrt(nrm);
    if (!(nrm > 0.0) || !isfinite(nrm)) return -1;
    for (int i = 0; i < n; i++) y[i] /= nrm;
    if (it == 0) continue;   /* the first solve only brings the start vector near */
    double res = 0.0;
    for (int i = 0; i < n; i++) {
      double s = (d[i] - lam) * y[i];
      if (i > 0) s += e[i] * y[i - 1];
      if (i + 1 < n) s += e[i + 1] * y[i + 1];
      res = fmax(res, fabs(s));
    }
    if (res <= tol) return 0;
  }
  return -1;
}

/* The eigenpairs of the symmetric A (n x n, row-major, both triangles; overwritten) with
 * eigenvalues below clip, without the full decomposition: Householder to tridiagonal, its
 * eigenvalues by QL (tql2 without vectors), the few below clip by inverse iteration on the
 * tridiagonal, brought back by the reflectors. Eigenvalues into d[0 .. *ne) (ascending),
 * eigenvector j into row j of Y (n x n); 0, or -1 when QL does not converge or an inverse
 * iteration misses its residual test (then: the full decomposition). e, tau, td, te: n
 * scratch each, lu: 4 n, piv: n. */
VARIANT_ONLY HOT static int eig_below(int n, double *A, double clip, double *d, double *Y,
                                      int *ne, double *e, double *tau, double *td, double *te,
                                      double *lu, unsigned char *piv) {
  householder_tridiagonal(n, A, td, te, tau, lu);
  memcpy(d, td, sizeof(double) * n);
  memcpy(e, te, sizeof(double) * n);
  if (tql2(n, NULL, d, e) != 0) return -1;
  double tnorm = 0.0;                       /* |T|inf */
  for (int i = 0; i < n; i++)
    tnorm = fmax(tnorm, fabs(td[i]) + fabs(te[i]) + (i + 1 < n ? fabs(te[i + 1]) : 0.0));
  int m = 0;                                /* the eigenvalues below clip, ascending */
  for (int i = 0; i < n; i++)
    if (d[i] < clip) {
      const double v = d[i];
      int j = m++;
      for (; j > 0 && d[j - 1] > v; j--) d[j] = d[j - 1];
      d[j] = v;
    }
  const double tol = 64.0 * n * 2.220446049250313e-16 * fmax(tnorm, 1e-300);
  for (int j = 0; j < m; j++)   /* orthogonalised against the earlier ones, in T's basis */
    if (tridiagonal_eigenvector(n, td, te, d[j], Y, j, tol, Y + j * n, lu, piv) != 0) return -1;
  for (int j = 0; j < m; j++) {
    double *y = Y + j * n;
    for (int k = n - 3; k >= 0; k--) {      /* y = H_k y, k = n-3 .. 0 */
      if (tau[k] == 0.0) continue;
      const double *v = A + k * n + k + 1;
      double s = y[k + 1];
      for (int i = k + 2; i < n; i++) s += v[i - k - 1] * y[i];
      s *= tau[k];
      y[k + 1] -= s;
      for (int i = k + 2; i < n; i++) y[i] -= s * v[i - k - 1];
    }
  }
  *ne = m;
  return 0;
}

/* Cholesky of a copy of H - clip I (n x n, lower triangle read); 1 when positive definite.
 * Right-looking on the upper triangle U = L' (row k of U scaled, then the trailing rows
 * updated by contiguous axpys, which vectorise), L written at the end: the same operations
 * in the same order as the left-looking dot products L[i][j] = (H[i][j] - sum_{k<j}
 * L[i][k] L[j][k]) / L[j][j] (the same factor to the bit), 2.5x faster at n = 160. */
HOT static int pd_shifted(const double *H, int n, double clip, double *L) {
  for (int i = 0; i < n; i++) {   /* U's rows from H's lower triangle: U[i][j] = H[j][i] */
    double *ui = L + i * n;
    for (int j = i; j < n; j++) ui[j] = H[j * n + i];
    ui[i] -= clip;
  }
  for (int k = 0; k < n; k++) {
    double *uk = L + k * n;
    const double dkk = uk[k];
    if (!(dkk > 0.0)) return 0;
    const double r = sqrt(dkk);
    uk[k] = r;
    for (int j = k + 1; j < n; j++) uk[j] /= r;
    for (int i = k + 1; i < n; i++) {
      const double a = uk[i];
      double *__restrict ui = L + i * n;
      const double *__restrict ukk = uk;
#pragma GCC ivdep
      for (int j = i; j < n; j++) ui[j] -= a * ukk[j];
    }
  }
  for (int i = 0; i < n; i++)    /* L = U' into the lower triangle */
    for (int j = 0; j < i; j++) L[i * n + j] = L[j * n + i];
  return 1;
}

/* eigenvalues of H below CLIP raised to CLIP: H += sum_j (CLIP - ev_j) v_j v_j^T.
 * H (NW x NW, row-major) is block diagonal: the u-block (NUA x NUA), H[t, t] and the slacks'
 * diagonal (the cost s t^2 + rho (eps + eps^2) does not couple them with u, and no
 * constraint is nonlinear in them), so the u-block is
 * decomposed alone; same result as the eigendecomposition of the whole matrix. */
HOT static int clip_hessian(gk_ws *ws, double *H) {
  double *V = ws->work.V, *Hu = ws->work.Hu, *d = ws->work.d;
  ws->mem.n_calls++;
  if (CLIP < 0) return 0;
  for (int c = IT; c < NW; c++)   /* t and the slacks: diagonal entries */
    if (H[c * NW + c] < CLIP) H[c * NW + c] = CLIP;
  for (int i = 0; i < NUA; i++)
    for (int j = 0; j < NUA; j++) Hu[i * NUA + j] = H[i * NW + j];
  if (pd_shifted(Hu, NUA, CLIP, V)) return 0;
  ws->mem.n_eig++;
  /* symmetric copy from the lower triangle H[i][j], i >= j (what numpy's eigh reads) */
  for (int i = 0; i < NUA; i++)
    for (int j = 0; j < NUA; j++) V[i * NUA + j] = (j <= i) ? Hu[i * NUA + j] : Hu[j * NUA + i];
  int any = 0, ne = NUA;
#ifdef GK_LAPACK_EIG
  {
    /* LAPACK dsyevr: only the eigenpairs below CLIP (the tridiagonal reduction is shared;
     * MRRR then finds the ~2 clipped pairs without the full QL). Row-major symmetric V =
     * column-major V; eigenvector j comes back as column j of the column-major Z = row j of
     * the row-major one. */
    const int nn = NUA, lwork = 26 * NUA, liwork = 10 * NUA, il = 1, iu = NUA;
    const double vl = -1e300, vu = CLIP, abstol = 0.0;
    int info = 0;
    dsyevr_("V", "V", "U", &nn, V, &nn, &vl, &vu, &il, &iu, &abstol, &ne, d, ws->work.Z, &nn,
            ws->work.isuppz, ws->work.lapack_work, &lwork, ws->work.iwork, &liwork, &info);
    if (info != 0) return -1;
    memcpy(V, ws->work.Z, sizeof(double) * NUA * ne);
  }
#else
  /* the eigenpairs below CLIP only (~2.4 per decomposition on the paper scenario): 33
   * against 45 us for the full tred2 + tql2 at N m = 30 (benchmarks/bench_mpc.py --clip),
   * which remains the fallback */
  if (eig_below(NUA, V, CLIP, d, Hu, &ne, ws->work.e, ws->work.tau, ws->work.td, ws->work.te,
                ws->work.lu, ws->work.piv) == 0) {
    memcpy(V, Hu, sizeof(double) * NUA * ne);
  } else {
    ws->mem.n_full_eig++;
    for (int i = 0; i < NUA; i++)
      for (int j = 0; j < NUA; j++) V[i * NUA + j] = (j <= i) ? H[i * NW + j] : H[j * NW + i];
    ne = NUA;
    if (symm_eig(NUA, V, d, ws->work.e) != 0) return -1;
  }
#endif
  for (int j = 0; j < ne; j++) {
    if (d[j] >= CLIP) continue;
    any = 1;
    ws->mem.n_evs++;
    const double a = CLIP - d[j], *vj = V + j * NUA;
    for (int r = 0; r < NUA; r++) {
      const double vr = a * vj[r];
      double *hr = H + r * NW;
      for (int c = 0; c < NUA; c++) hr[c] += vr * vj[c];
    }
  }
  if (any) ws->mem.n_clipped++;
  return 0;
}

