/* Part of the compiled FHOCP kernel (controllers/kernel/compiled_kernel.py joins the
 * generated header, gru_fhocp.h and the parts into one translation unit): the GRU rollout,
 * the stage Jacobians and sensitivities, cached in the workspace, and the small dense
 * products they use. */
static const double ZERO_W[NW];
static const double ZERO_P[NP];
static const double ZERO_G[NG];

static double sigm(double a) { return 1.0 / (1.0 + exp(-a)); }

/* ---------------------------------------------------------------- small dense products */
/* Row-major C (m x n, ldc) = (acc ? C : 0) + op(A) B, op(A) = A (m x k, lda) or, when ta,
 * A^T (A is k x m). Every entry is summed over p = 0 .. k-1 in order, by both variants:
 *  - gk_gemm_loops: one row of C at a time (loads and stores the row per multiply-add);
 *  - gk_gemm_v4 (x86-64 with AVX2/FMA, chosen at run time): blocks of 4 rows x 8 / 4 / 2
 *    columns held in vector registers across the k loop, 2-5x faster on the kernel's
 *    20 x 20 x K products. It is its own function with an AVX2 target (not a clone) so
 *    that its 256-bit vectors are never emulated by the portable clone. */
static inline void gk_gemm_loops(int ta, int m, int n, int k, const double *A, int lda,
                                 const double *B, int ldb, double *C, int ldc, int acc,
                                 int upper) {
  for (int i = 0; i < m; i++) {
    double *__restrict ci = C + i * ldc;
    const int j0 = upper ? i : 0;
    if (!acc)
      for (int j = j0; j < n; j++) ci[j] = 0.0;
    for (int p = 0; p < k; p++) {
      const double a = ta ? A[p * lda + i] : A[i * lda + p], *bp = B + p * ldb;
#pragma GCC ivdep
      for (int j = j0; j < n; j++) ci[j] += a * bp[j];
    }
  }
}

#define GK_CHUNK 16

/* gk_accumulate's entries j0 .. j0 + C - 1 in C registers (C a literal) */
#define GK_ACCUMULATE_CHUNK(C)                                                  \
  do {                                                                          \
    double acc[C];                                                              \
    for (int t = 0; t < (C); t++) acc[t] = y0[j0 + t];                          \
    for (int k = (tri && j0 > k0) ? j0 : k0; k < k1; k++) {                     \
      const double c = a[k], *x = X + k * ldx + j0;                             \
      for (int t = 0; t < (C); t++) acc[t] += c * x[t];                         \
    }                                                                           \
    for (int t = 0; t < (C); t++) y[j0 + t] = acc[t];                           \
  } while (0)

/* y[j] = y0[j] + sum_{k = k0}^{k1 - 1} a[k] X[k ldx + j], j < n, each entry summed in
 * ascending k (the order of the scalar loop `for k: for j: y[j] += a[k] X[k][j]`; the last
 * bits as the compiler contracts products into FMAs), GK_CHUNK entries at a time in
 * registers, then chunks of 8 and 4 (the QP's n = N m + 1 would leave up to 15 entries to
 * the strided scalar loop): the rows of X are only read, y is written once (the scalar loop
 * stores y at every k). y0 may be y. tri: row k of X is zero beyond column k (a triangular
 * inverse), so a chunk from column j0 starts at k = j0. */
static inline void gk_accumulate(double *y, const double *y0, int n, const double *a,
                                 const double *X, int ldx, int k0, int k1, int tri) {
  int j0 = 0;
  for (; j0 + GK_CHUNK <= n; j0 += GK_CHUNK) GK_ACCUMULATE_CHUNK(GK_CHUNK);
  if (j0 + 8 <= n) {
    GK_ACCUMULATE_CHUNK(8);
    j0 += 8;
  }
  if (j0 + 4 <= n) {
    GK_ACCUMULATE_CHUNK(4);
    j0 += 4;
  }
  for (int j = j0; j < n; j++) {
    double acc = y0[j];
    for (int k = (tri && j > k0) ? j : k0; k < k1; k++) acc += a[k] * X[k * ldx + j];
    y[j] = acc;
  }
}

/* a'b, n terms, in 8 interleaved partial sums (vectorisable: an in-order sum is not),
 * combined pairwise */
static inline double gk_dot(const double *a, const double *b, int n) {
  double s[8] = {0.0};
  int i = 0;
  for (; i + 8 <= n; i += 8)
    for (int t = 0; t < 8; t++) s[t] += a[i + t] * b[i + t];
  double r = ((s[0] + s[4]) + (s[1] + s[5])) + ((s[2] + s[6]) + (s[3] + s[7]));
  for (; i < n; i++) r += a[i] * b[i];
  return r;
}

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && __GNUC__ >= 11 && \
    !defined(GK_NO_CLONES)
#define GK_HAVE_V4 1
typedef double gk_v4 __attribute__((vector_size(32)));
typedef double gk_v4u __attribute__((vector_size(32), aligned(8)));
typedef double gk_v2 __attribute__((vector_size(16)));
typedef double gk_v2u __attribute__((vector_size(16), aligned(8)));
#define GK_A(r, p) (ta ? A[(p) * lda + (r)] : A[(r) * lda + (p)])
#define GK_L4(ptr) (*(const gk_v4u *)(ptr))
#define GK_L2(ptr) (*(const gk_v2u *)(ptr))
#define GK_S4(ptr, v) (*(gk_v4u *)(ptr) = (v))
#define GK_S2(ptr, v) (*(gk_v2u *)(ptr) = (v))
/* rows i .. i+3 of C at columns j .. j+W-1, one vector of type VT per row (W = 4 or 2) */
#define GK_TILE4(VT, LD, ST)                                                             \
  {                                                                                      \
    const VT z = {0};                                                                    \
    VT c0 = acc ? LD(C0 + j) : z, c1 = acc ? LD(C1 + j) : z;                             \
    VT c2 = acc ? LD(C2 + j) : z, c3 = acc ? LD(C3 + j) : z;                             \
    for (int p = 0; p < k; p++) {                                                        \
      const VT b0 = LD(B + p * ldb + j);                                                 \
      c0 += GK_A(i, p) * b0; c1 += GK_A(i + 1, p) * b0;                                  \
      c2 += GK_A(i + 2, p) * b0; c3 += GK_A(i + 3, p) * b0;                              \
    }                                                                                    \
    ST(C0 + j, c0); ST(C1 + j, c1); ST(C2 + j, c2); ST(C3 + j, c3);                      \
  }
__attribute__((target("arch=x86-64-v3"))) static void gk_gemm_v4(
    int ta, int m, int n, int k, const double *A, int lda, const double *B, int ldb,
    double *C, int ldc, int acc, int upper) {
  int i = 0;
  for (; i + 4 <= m; i += 4) {
    double *C0 = C + i * ldc, *C1 = C0 + ldc, *C2 = C1 + ldc, *C3 = C2 + ldc;
    int j = upper ? i : 0;
    for (; j + 8 <= n; j += 8) {
      const gk_v4 z = {0, 0, 0, 0};
      gk_v4 c00 = acc ? GK_L4(C0 + j) : z, c01 = acc ? GK_L4(C0 + j + 4) : z;
      gk_v4 c10 = acc ? GK_L4(C1 + j) : z, c11 = acc ? GK_L4(C1 + j + 4) : z;
      gk_v4 c20 = acc ? GK_L4(C2 + j) : z, c21 = acc ? GK_L4(C2 + j + 4) : z;
      gk_v4 c30 = acc ? GK_L4(C3 + j) : z, c31 = acc ? GK_L4(C3 + j + 4) : z;
      for (int p = 0; p < k; p++) {
        const gk_v4 b0 = GK_L4(B + p * ldb + j), b1 = GK_L4(B + p * ldb + j + 4);
        const double a0 = GK_A(i, p), a1 = GK_A(i + 1, p), a2 = GK_A(i + 2, p),
                     a3 = GK_A(i + 3, p);
        c00 += a0 * b0; c01 += a0 * b1; c10 += a1 * b0; c11 += a1 * b1;
        c20 += a2 * b0; c21 += a2 * b1; c30 += a3 * b0; c31 += a3 * b1;
      }
      GK_S4(C0 + j, c00); GK_S4(C0 + j + 4, c01); GK_S4(C1 + j, c10); GK_S4(C1 + j + 4, c11);
      GK_S4(C2 + j, c20); GK_S4(C2 + j + 4, c21); GK_S4(C3 + j, c30); GK_S4(C3 + j + 4, c31);
    }
    for (; j + 4 <= n; j += 4) GK_TILE4(gk_v4, GK_L4, GK_S4)
    for (; j + 2 <= n; j += 2) GK_TILE4(gk_v2, GK_L2, GK_S2)
    for (; j < n; j++) {
      double s0 = acc ? C0[j] : 0.0, s1 = acc ? C1[j] : 0.0, s2 = acc ? C2[j] : 0.0,
             s3 = acc ? C3[j] : 0.0;
      for (int p = 0; p < k; p++) {
        const double b = B[p * ldb + j];
        s0 += GK_A(i, p) * b; s1 += GK_A(i + 1, p) * b;
        s2 += GK_A(i + 2, p) * b; s3 += GK_A(i + 3, p) * b;
      }
      C0[j] = s0; C1[j] = s1; C2[j] = s2; C3[j] = s3;
    }
  }
  for (; i < m; i++) {
    double *Ci = C + i * ldc;
    int j = upper ? i : 0;
    for (; j + 8 <= n; j += 8) {
      const gk_v4 z = {0, 0, 0, 0};
      gk_v4 c0 = acc ? GK_L4(Ci + j) : z, c1 = acc ? GK_L4(Ci + j + 4) : z;
      for (int p = 0; p < k; p++) {
        const double a = GK_A(i, p);
        c0 += a * GK_L4(B + p * ldb + j);
        c1 += a * GK_L4(B + p * ldb + j + 4);
      }
      GK_S4(Ci + j, c0); GK_S4(Ci + j + 4, c1);
    }
    for (; j < n; j++) {
      double s = acc ? Ci[j] : 0.0;
      for (int p = 0; p < k; p++) s += GK_A(i, p) * B[p * ldb + j];
      Ci[j] = s;
    }
  }
}
/* the CPU runs gk_gemm_v4: set once when the library is loaded, read-only afterwards */
static int gk_v4_ok = 0;
__attribute__((constructor)) static void gk_cpu_init(void) {
  __builtin_cpu_init();
  gk_v4_ok = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
}
#endif

static inline void gk_gemm_any(int ta, int m, int n, int k, const double *A, int lda,
                               const double *B, int ldb, double *C, int ldc, int acc,
                               int upper) {
  if (m <= 0 || n <= 0) return;
#ifdef GK_HAVE_V4
  if (gk_v4_ok) {
    gk_gemm_v4(ta, m, n, k, A, lda, B, ldb, C, ldc, acc, upper);
    return;
  }
#endif
  gk_gemm_loops(ta, m, n, k, A, lda, B, ldb, C, ldc, acc, upper);
}

static inline void gk_gemm(int ta, int m, int n, int k, const double *A, int lda,
                           const double *B, int ldb, double *C, int ldc, int acc) {
  gk_gemm_any(ta, m, n, k, A, lda, B, ldb, C, ldc, acc, 0);
}

/* gk_gemm where only the upper triangle of C (j >= i) is wanted (a symmetric product whose
 * lower triangle the caller overwrites by mirroring): the entries at j >= i are computed as
 * by gk_gemm, to the bit (the same sum per entry); of those below, only some within the row
 * blocks, left unspecified. About half the work of a square product. */
static inline void gk_gemm_upper(int ta, int m, int n, int k, const double *A, int lda,
                                 const double *B, int ldb, double *C, int ldc, int acc) {
  gk_gemm_any(ta, m, n, k, A, lda, B, ldb, C, ldc, acc, 1);
}

#if defined(GK_BLAS_HESS) && !defined(GK_BLAS)
#define GK_BLAS
#endif
#if defined(GK_BLAS) || defined(GK_LAPACK_EIG)
/* optional BLAS (casadi's bundled OpenBLAS) for the O(n^3) products of large models */
extern void dgemm_(const char *, const char *, const int *, const int *, const int *,
                   const double *, const double *, const int *, const double *, const int *,
                   const double *, double *, const int *);
extern void openblas_set_num_threads(int);
extern void dsyevr_(const char *, const char *, const char *, const int *, double *,
                    const int *, const double *, const double *, const int *, const int *,
                    const double *, int *, double *, double *, const int *, int *, double *,
                    const int *, int *, const int *, int *);
/* one BLAS thread: small products, and one kernel per campaign worker thread (set once when
 * the library is loaded) */
__attribute__((constructor)) static void gk_blas_init(void) { openblas_set_num_threads(1); }
/* row-major C (m x n, ldc) = op(A) op(B) + beta C, op(X) = X^T when tX */
VARIANT_ONLY static void rm_gemm(int ta, int tb, int m, int n, int k, const double *A, int lda,
                    const double *B, int ldb, double beta, double *C, int ldc) {
  const double one = 1.0;
  const char cA = ta ? 'T' : 'N', cB = tb ? 'T' : 'N';
  if (m <= 0 || n <= 0) return;
  dgemm_(&cB, &cA, &n, &m, &k, &one, B, &ldb, A, &lda, &beta, C, &ldc);
}
#endif

#if HAS_SHIFT
/* The measured disturbances held over the horizon, as a shift of the biases b_z, b_r, b_h
 * (controllers.disturbances: W v + b = W_u u + (b + W_d d)): per thread, so that two
 * controllers stepping on two threads never see each other's; set by PFX(set_bias_shift)
 * before the calls of a control step, zero until then. Only in a kernel of a model with
 * measured disturbances (the first use on a thread allocates glibc's block for it). */
static __thread double gk_db[3 * NX];
#endif

/* gates z, r, h of one stage at (x, u), with extra gate inputs dz, dr (eq:observer; NULL:
 * none). Always inlined: compiled inside each AVX2 / portable clone of its callers. */
__attribute__((always_inline)) static inline void stage_gates(
    const double *xi, const double *ui, const double *dz, const double *dr, double *zi,
    double *ri, double *hi) {
  double az[NX], ar[NX], ah[NX], rho[NX];
  for (int k = 0; k < NX; k++) {
#if HAS_SHIFT
    double sz = BZ[k] + gk_db[k], sr = BR[k] + gk_db[NX + k], sh = BH[k] + gk_db[2 * NX + k];
#else
    double sz = BZ[k], sr = BR[k], sh = BH[k];
#endif
    for (int j = 0; j < NU; j++) {
      sz += WZ[k * NU + j] * ui[j];
      sr += WR[k * NU + j] * ui[j];
      sh += WH[k * NU + j] * ui[j];
    }
    az[k] = sz;
    ar[k] = sr;
    ah[k] = sh;
  }
  /* column-oriented mat-vec (contiguous, vectorisable): a += U[:, j] x_j with U^T stored */
  for (int j = 0; j < NX; j++) {
    const double xj = xi[j], *uzt = UZT + j * NX, *urt = URT + j * NX;
    for (int k = 0; k < NX; k++) {
      az[k] += uzt[k] * xj;
      ar[k] += urt[k] * xj;
    }
  }
  for (int k = 0; k < NX; k++) {
    zi[k] = sigm(dz ? az[k] + dz[k] : az[k]);
    ri[k] = sigm(dr ? ar[k] + dr[k] : ar[k]);
    rho[k] = ri[k] * xi[k];
  }
  for (int j = 0; j < NX; j++) {
    const double rj = rho[j], *uht = UHT + j * NX;
    for (int k = 0; k < NX; k++) ah[k] += uht[k] * rj;
  }
  for (int k = 0; k < NX; k++) hi[k] = tanh(ah[k]);
}

/* one stage: gates z, r, h and x+ = f(x, u) */
__attribute__((always_inline)) static inline void simulate_stage(
    const double *xi, const double *ui, double *zi, double *ri, double *hi, double *xn) {
  stage_gates(xi, ui, 0, 0, zi, ri, hi);
  for (int k = 0; k < NX; k++) xn[k] = hi[k] + zi[k] * (xi[k] - hi[k]);
}

/* states x_0..x_N and gates from x_0 = xh under u (NH x NU) into x, z, r, h */
HOT static void simulate(const double *xh, const double *u, double *x, double *z, double *r,
                         double *h) {
  memcpy(x, xh, NX * sizeof(double));
  for (int i = 0; i < NH; i++)
    simulate_stage(x + i * NX, u + i * NU, z + i * NX, r + i * NX, h + i * NX,
                   x + (i + 1) * NX);
}

/* row-major C (m x n, ldc) = A (m x k, lda) B (k x n, ldb): BLAS or loops */
static inline void mm(int m, int n, int k, const double *A, int lda, const double *B, int ldb,
                      double *C, int ldc) {
  if (n <= 0) return;
#ifdef GK_BLAS
  rm_gemm(0, 0, m, n, k, A, lda, B, ldb, 0.0, C, ldc);
#else
  gk_gemm(0, m, n, k, A, lda, B, ldb, C, ldc, 0);
#endif
}

/* J_h and D_f = [A B] of one stage at (x, gates z, r, h) */
static inline void stage_jac(const double *x, const double *z, const double *r, const double *h,
                             double *jh, double *df) {
  double c1[NX];
  for (int j = 0; j < NX; j++) c1[j] = x[j] * (r[j] * (1.0 - r[j]));
  /* J_h = U_h (diag(x r') J_r + [diag(r) 0]) + [0 W_h] */
#ifdef GK_BLAS
  double M[NX * NX];
  for (int k = 0; k < NX; k++)
    for (int j = 0; j < NX; j++) M[k * NX + j] = UH[k * NX + j] * c1[j];
  rm_gemm(0, 0, NX, NV, NX, M, NX, JR, NV, 0.0, jh, NV);
  for (int k = 0; k < NX; k++) {
    double *row = jh + k * NV;
    for (int j = 0; j < NX; j++) row[j] += UH[k * NX + j] * r[j];
    for (int c = 0; c < NU; c++) row[NX + c] += WH[k * NU + c];
  }
#else
  double M[NX * NX];
  for (int k = 0; k < NX; k++)
    for (int j = 0; j < NX; j++) M[k * NX + j] = UH[k * NX + j] * c1[j];
  gk_gemm(0, NX, NV, NX, M, NX, JR, NV, jh, NV, 0);
  for (int k = 0; k < NX; k++) {
    double *row = jh + k * NV;
    for (int j = 0; j < NX; j++) row[j] += UH[k * NX + j] * r[j];
    for (int c = 0; c < NU; c++) row[NX + c] += WH[k * NU + c];
  }
#endif
  /* D_f = diag((x - h) z') J_z + diag((1 - z) h') J_h + [diag(z) 0] */
  for (int k = 0; k < NX; k++) {
    const double zp = z[k] * (1.0 - z[k]), hp = 1.0 - h[k] * h[k];
    const double a = (x[k] - h[k]) * zp, b = (1.0 - z[k]) * hp;
    const double *jz = JZ + k * NV, *jhk = jh + k * NV;
    double *dfk = df + k * NV;
    for (int c = 0; c < NV; c++) dfk[c] = a * jz[c] + b * jhk[c];
    dfk[k] += z[k];
  }
}

#ifndef GK_CONTRACT
/* stage Jacobians D_f = [A B], J_h and sensitivities S of the cached states */
HOT static void derivatives(gk_ws *ws) {
  for (int i = 0; i < NH; i++) {
    const double *x = ws->mem.X + i * NX, *z = ws->mem.ZG + i * NX, *r = ws->mem.RG + i * NX,
                 *h = ws->mem.HG + i * NX;
    double *jh = ws->mem.JH + i * NX * NV, *df = ws->mem.DF + i * NX * NV;
    stage_jac(x, z, r, h, jh, df);
    /* S_{i+1} = A_i S_i + B_i E_i (the first KC(i) columns of S_i are nonzero; B_i goes to
     * u_i's columns UC(i): new ones, or u_s's, already among them, in the tail) */
    const double *Si = ws->mem.S + i * NX * NSC;
    double *Sn = ws->mem.S + (i + 1) * NX * NSC;
    const int K = KC(i), uc = UC(i);
#ifdef GK_BLAS
    if (K > 0) rm_gemm(0, 0, NX, K, NX, df, NV, Si, NSC, 0.0, Sn, NSC);
#else
    gk_gemm(0, NX, K, NX, df, NV, Si, NSC, Sn, NSC, 0);
#endif
    for (int k = 0; k < NX; k++)
      for (int c = 0; c < NU; c++) {
        const double b = df[k * NV + NX + c];
        Sn[k * NSC + uc + c] = uc < K ? Sn[k * NSC + uc + c] + b : b;
      }
  }
}

#else /* GK_CONTRACT */
/* contracted mode (large n): no explicit J_h or A_i. Per stage, with Z_i = [S_i; E_i]
 * (K = i NU nonzero columns of S_i, Kc = K + NU active columns):
 *   PZ = J_z Z = U_z S + W_z E,  PR = J_r Z = U_r S + W_r E,
 *   PH = J_h Z = U_h (diag(x r') PR + diag(r) S) + W_h E,
 *   S_{i+1} = diag((x - h) z') PZ + diag((1 - z) h') PH + diag(z) S.
 * 3 n^2 Kc per stage instead of n^2 (n + m) + n^2 K. */
HOT static void derivatives(gk_ws *ws) {
  double *T = ws->work.T;
  for (int i = 0; i < NH; i++) {
    const double *x = ws->mem.X + i * NX, *z = ws->mem.ZG + i * NX, *r = ws->mem.RG + i * NX,
                 *h = ws->mem.HG + i * NX;
    const double *Si = ws->mem.S + i * NX * NUU;
    double *Sn = ws->mem.S + (i + 1) * NX * NUU;
    double *pz = ws->mem.PZ + i * NX * NUU, *pr = ws->mem.PR + i * NX * NUU,
           *ph = ws->mem.PH + i * NX * NUU;
    const int K = i * NU, Kc = K + NU;
    mm(NX, K, NX, UZ, NX, Si, NUU, pz, NUU);
    mm(NX, K, NX, UR, NX, Si, NUU, pr, NUU);
    for (int k = 0; k < NX; k++)
      for (int c = 0; c < NU; c++) {
        pz[k * NUU + K + c] = WZ[k * NU + c];
        pr[k * NUU + K + c] = WR[k * NU + c];
      }
    for (int k = 0; k < NX; k++) {
      const double c1 = x[k] * (r[k] * (1.0 - r[k])), rk = r[k];
      const double *prk = pr + k * NUU, *sk = Si + k * NUU;
      double *tk = T + k * NUU;
      for (int c = 0; c < K; c++) tk[c] = c1 * prk[c] + rk * sk[c];
      for (int c = K; c < Kc; c++) tk[c] = c1 * prk[c];
    }
    mm(NX, Kc, NX, UH, NX, T, NUU, ph, NUU);
    for (int k = 0; k < NX; k++)
      for (int c = 0; c < NU; c++) ph[k * NUU + K + c] += WH[k * NU + c];
    for (int k = 0; k < NX; k++) {
      const double zp = z[k] * (1.0 - z[k]), hp = 1.0 - h[k] * h[k];
      const double a = (x[k] - h[k]) * zp, b = (1.0 - z[k]) * hp, zk = z[k];
      const double *pzk = pz + k * NUU, *phk = ph + k * NUU, *sk = Si + k * NUU;
      double *snk = Sn + k * NUU;
      for (int c = 0; c < K; c++) snk[c] = a * pzk[c] + b * phk[c] + zk * sk[c];
      for (int c = K; c < Kc; c++) snk[c] = a * pzk[c] + b * phk[c];
    }
  }
}
#endif

#if HAS_ASS
static void steady_state(gk_ws *ws, const double *us, const double *x0);   /* 1b */
#endif

/* make the workspace's cache valid at (w, p) up to `level` (with HAS_ASS: the artificial
 * steady state x_s(u_s) from Newton's start x_s0 = p + NX too, at level 0) */
HOT static void roll(gk_ws *ws, const double *w, const double *p, int level) {
  /* keyed by the inputs (u, and u_s with HAS_ASS) and p: the terminal slack t does not enter
   * the rollout, so setting it (terminal_gap, then the SQP) keeps the cache */
  if (ws->mem.c_level < 0 || memcmp(w, ws->mem.c_w, NUA * sizeof(double)) != 0 ||
      memcmp(p, ws->mem.c_p, sizeof ws->mem.c_p) != 0) {
    memcpy(ws->mem.c_w, w, sizeof ws->mem.c_w);
    memcpy(ws->mem.c_p, p, sizeof ws->mem.c_p);
#if NM < NH   /* the tail of a control horizon: u_i = u_s, expanded into uf */
    for (int i = 0; i < NH; i++) memcpy(ws->mem.uf + i * NU, w + UC(i), NU * sizeof(double));
    simulate(p, ws->mem.uf, ws->mem.X, ws->mem.ZG, ws->mem.RG, ws->mem.HG);
#else         /* u_0 .. u_{N-1} are w's first NUF entries */
    simulate(p, w, ws->mem.X, ws->mem.ZG, ws->mem.RG, ws->mem.HG);
#endif
#if HAS_ASS
    steady_state(ws, w + NUU, p + NX);
#endif
    ws->mem.c_level = 0;
  }
  if (level >= 1 && ws->mem.c_level < 1) {
    derivatives(ws);
    ws->mem.c_level = 1;
  }
}

