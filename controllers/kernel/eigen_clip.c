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

HOT static int tql2(int n, double *V, double *d, double *e) {
#define VV(i, j) V[(i) * n + (j)]
  /* transpose: eigenvector j becomes row j, so that the QL rotations act on two
   * contiguous rows (vectorisable) */
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
        double r = hypot(p, 1.0);
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
          r = hypot(p, e[i]);
          e[i + 1] = s * r;
          s = e[i] / r;
          c = p / r;
          p = c * d[i] - s * g;
          d[i + 1] = h + s * (c * g + s * d[i]);
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
 * H (NW x NW, row-major) is block diagonal: the u-block (NUA x NUA) and H[t, t] (the cost
 * s t^2 does not couple t with u, and no constraint is nonlinear in t), so the u-block is
 * decomposed alone; same result as the eigendecomposition of the whole matrix. */
HOT static int clip_hessian(gk_ws *ws, double *H) {
  double *V = ws->work.V, *Hu = ws->work.Hu, *d = ws->work.d;
  ws->mem.n_calls++;
  if (CLIP < 0) return 0;
  if (H[IT * NW + IT] < CLIP) H[IT * NW + IT] = CLIP;
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
  /* full decomposition (tred2 + tql2): eigenvectors as rows of V. Computing only the
   * eigenpairs below CLIP by hand (QL without vectors + inverse iteration) was measured no
   * faster in closed loop (~2.4 eigenvalues clipped per decomposition) and removed. */
  if (symm_eig(NUA, V, d, ws->work.e) != 0) return -1;
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

