/* Compiled derivative kernel of the single-shooting FHOCP (controllers.fhocp, eq:optimization).
 *
 * The generated header above this line defines the dimensions (NX states, NU inputs, NY
 * outputs, NH horizon stages, NQ reduced output-constraint rows), the GRU weights (row-major,
 * eq:gru; U^T copies for column-oriented mat-vecs, J_z = [U_z W_z], J_r = [U_r W_r]), the cost
 * weights QW (NX x NX, QDIAG when diagonal), RW (NU x NU), SW (s), the reduced constraint rows
 * DUO (NQ x NX), the eigenvalue clipping margin CLIP (< 0: no clipping) and PFX(name), the
 * symbol prefix (a hash of the source: several kernels can live in one process).
 *
 * Decision variables w = (u_0 .. u_{N-1}, t) (NW = NH*NU + 1), parameters p = (x_hat, x_bar,
 * u_bar) (NP = 2 NX + NU). Same mathematics as controllers/shooting.py (GRUShooting.rollout,
 * stage_hessians) and controllers/nlp_single_shooting.py (SingleShootingNLP.objective,
 * constraints, gradient, jacobian, hessian, hessian_convex) -- see there for the formulas;
 * checked against them to ~1e-14 (tests/controllers/test_compiled_kernel.py).
 *
 * Build-time variants (macros, chosen by controllers/compiled_kernel.py):
 *   (default)        W-mode: explicit J_h, [A B] and stage Hessians W_i, then Z_i^T W_i Z_i
 *                    (as numpy); best for n <~ N m.
 *   GK_CONTRACT      contracted mode: J_z Z_i, J_r Z_i, J_h Z_i carried forward instead of
 *                    J_h and A_i; O(N^2 n^2 m) instead of O(N n^3); best for large n.
 *   GK_BLAS          the n x n x (n+m) / n x n x K products through dgemm (casadi's OpenBLAS).
 *   GK_LAPACK_EIG    eigenvalue clipping with LAPACK dsyevd instead of tred2/tql2 (N m >= 90).
 *   GK_TIMERS        in-kernel wall-clock accumulators (PFX(timers)).
 *   GK_NO_CLONES     no AVX2/FMA function clones (target_clones) on x86-64.
 *
 * One rollout (states, gates, stage Jacobians, sensitivities) is cached in static memory keyed
 * by (w, p): the f/g, Jacobian and Hessian evaluations at the same point share it. Not
 * thread safe; two FHOCPs of the same problem share one library and its cache, which is
 * correct because the cache is keyed by the full (w, p).
 *
 * Exported: casadi external functions (casadi's codegen calling convention) PFX(fg),
 * PFX(jac_fg), PFX(hess_l) (clipped), PFX(hess_raw) (unclipped), and plain C entry points for
 * ctypes: PFX(simulate), PFX(xtraj), PFX(eq_newton), PFX(clip), PFX(dims), PFX(counters).
 */
#include <math.h>
#include <string.h>
#ifdef GK_TIMERS
#include <time.h>
static double tk_now(void) { struct timespec t; clock_gettime(CLOCK_MONOTONIC, &t); return t.tv_sec + 1e-9 * t.tv_nsec; }
static double tk_acc[4];
#define TK_START double tk0_ = tk_now();
#define TK_STOP(i) tk_acc[i] += tk_now() - tk0_;
#else
#define TK_START
#define TK_STOP(i)
#endif

#define NV (NX + NU)
#define NUU (NH * NU)
#define NW (NUU + 1)
#define NG ((NH - 1) * NQ + 2 * NX)
#define NP (2 * NX + NU)
#define EXPORT __attribute__((visibility("default")))
/* hot entry points get an AVX2/FMA clone selected at load time (ifunc), portable otherwise */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && __GNUC__ >= 11 && \
    !defined(GK_NO_CLONES)
#define HOT __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define HOT
#endif

typedef long long int casadi_int;

/* ---------------------------------------------------------------- cache of one rollout */
static int c_level = -1;                 /* -1 empty, 0 states, 1 states + derivatives */
static double c_w[NW], c_p[NP];
static double X[(NH + 1) * NX];          /* states x_0 .. x_N */
static double ZG[NH * NX], RG[NH * NX], HG[NH * NX];   /* gates z, r, h per stage */
#ifndef GK_CONTRACT
static double JH[NH * NX * NV];          /* J_h per stage */
static double DF[NH * NX * NV];          /* [A_i B_i] per stage */
#else
/* contracted mode: J_z Z_i, J_r Z_i, J_h Z_i per stage (NX x NUU, first (i+1) NU columns) */
static double PZ[NH * NX * NUU], PR[NH * NX * NUU], PH[NH * NX * NUU];
#endif
static double S[(NH + 1) * NX * NUU];    /* S_i = dx_i/du, NX x NUU row-major; cols >= i NU are 0 */

static const double ZERO_W[NW];
static const double ZERO_P[NP];
static const double ZERO_G[NG];

static double sigm(double a) { return 1.0 / (1.0 + exp(-a)); }

#if defined(GK_BLAS_HESS) && !defined(GK_BLAS)
#define GK_BLAS
#endif
#if defined(GK_BLAS) || defined(GK_LAPACK_EIG)
/* optional BLAS (casadi's bundled OpenBLAS) for the O(n^3) products of large models */
extern void dgemm_(const char *, const char *, const int *, const int *, const int *,
                   const double *, const double *, const int *, const double *, const int *,
                   const double *, double *, const int *);
extern void openblas_set_num_threads(int);
extern void dsyevd_(const char *, const char *, const int *, double *, const int *, double *,
                    double *, const int *, int *, const int *, int *);
/* row-major C (m x n, ldc) = op(A) op(B) + beta C, op(X) = X^T when tX */
static void rm_gemm(int ta, int tb, int m, int n, int k, const double *A, int lda,
                    const double *B, int ldb, double beta, double *C, int ldc) {
  static int init = 0;
  if (!init) { openblas_set_num_threads(1); init = 1; }
  const double one = 1.0;
  const char cA = ta ? 'T' : 'N', cB = tb ? 'T' : 'N';
  if (m <= 0 || n <= 0) return;
  dgemm_(&cB, &cA, &n, &m, &k, &one, B, &ldb, A, &lda, &beta, C, &ldc);
}
#endif

/* one stage: gates z, r, h and x+ = f(x, u) */
static inline void simulate_stage(const double *xi, const double *ui, double *zi, double *ri,
                                  double *hi, double *xn) {
  double az[NX], ar[NX], ah[NX], rho[NX];
  for (int k = 0; k < NX; k++) {
    double sz = BZ[k], sr = BR[k], sh = BH[k];
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
    zi[k] = sigm(az[k]);
    ri[k] = sigm(ar[k]);
    rho[k] = ri[k] * xi[k];
  }
  for (int j = 0; j < NX; j++) {
    const double rj = rho[j], *uht = UHT + j * NX;
    for (int k = 0; k < NX; k++) ah[k] += uht[k] * rj;
  }
  for (int k = 0; k < NX; k++) {
    const double hk = tanh(ah[k]);
    hi[k] = hk;
    xn[k] = hk + zi[k] * (xi[k] - hk);
  }
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
  for (int r = 0; r < m; r++) {
    double *__restrict cr = C + r * ldc;
    for (int c = 0; c < n; c++) cr[c] = 0.0;
    for (int j = 0; j < k; j++) {
      const double a = A[r * lda + j], *bj = B + j * ldb;
#pragma GCC ivdep
      for (int c = 0; c < n; c++) cr[c] += a * bj[c];
    }
  }
#endif
}

/* J_h and D_f = [A B] of one stage at (x, gates z, r, h) */
static inline void stage_jac(const double *x, const double *z, const double *r, const double *h,
                             double *jh, double *df) {
  double c1[NX];
  for (int j = 0; j < NX; j++) c1[j] = x[j] * (r[j] * (1.0 - r[j]));
  /* J_h = U_h (diag(x r') J_r + [diag(r) 0]) + [0 W_h] */
#ifdef GK_BLAS
  static double M[NX * NX];
  for (int k = 0; k < NX; k++)
    for (int j = 0; j < NX; j++) M[k * NX + j] = UH[k * NX + j] * c1[j];
  rm_gemm(0, 0, NX, NV, NX, M, NX, JR, NV, 0.0, jh, NV);
  for (int k = 0; k < NX; k++) {
    double *row = jh + k * NV;
    for (int j = 0; j < NX; j++) row[j] += UH[k * NX + j] * r[j];
    for (int c = 0; c < NU; c++) row[NX + c] += WH[k * NU + c];
  }
#else
  for (int k = 0; k < NX; k++) {
    double *row = jh + k * NV;
    for (int c = 0; c < NV; c++) row[c] = 0.0;
    for (int j = 0; j < NX; j++) {
      const double a = UH[k * NX + j] * c1[j], *jr = JR + j * NV;
      for (int c = 0; c < NV; c++) row[c] += a * jr[c];
    }
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
HOT static void derivatives(void) {
  for (int i = 0; i < NH; i++) {
    const double *x = X + i * NX, *z = ZG + i * NX, *r = RG + i * NX, *h = HG + i * NX;
    double *jh = JH + i * NX * NV, *df = DF + i * NX * NV;
    stage_jac(x, z, r, h, jh, df);
    /* S_{i+1} = A_i S_i + B_i E_i (only the first i NU columns of S_i are nonzero) */
    const double *Si = S + i * NX * NUU;
    double *Sn = S + (i + 1) * NX * NUU;
    const int K = i * NU;
#ifdef GK_BLAS
    if (K > 0) rm_gemm(0, 0, NX, K, NX, df, NV, Si, NUU, 0.0, Sn, NUU);
    for (int k = 0; k < NX; k++)
      for (int c = 0; c < NU; c++) Sn[k * NUU + K + c] = df[k * NV + NX + c];
#else
    for (int k = 0; k < NX; k++) {
      double *srow = Sn + k * NUU;
      const double *dfk = df + k * NV;
      for (int c = 0; c < K; c++) srow[c] = 0.0;
      for (int j = 0; j < NX; j++) {
        const double a = dfk[j], *sj = Si + j * NUU;
#pragma GCC ivdep
        for (int c = 0; c < K; c++) srow[c] += a * sj[c];
      }
      for (int c = 0; c < NU; c++) srow[K + c] = dfk[NX + c];
    }
#endif
  }
}

#else /* GK_CONTRACT */
/* contracted mode (large n): no explicit J_h or A_i. Per stage, with Z_i = [S_i; E_i]
 * (K = i NU nonzero columns of S_i, Kc = K + NU active columns):
 *   PZ = J_z Z = U_z S + W_z E,  PR = J_r Z = U_r S + W_r E,
 *   PH = J_h Z = U_h (diag(x r') PR + diag(r) S) + W_h E,
 *   S_{i+1} = diag((x - h) z') PZ + diag((1 - z) h') PH + diag(z) S.
 * 3 n^2 Kc per stage instead of n^2 (n + m) + n^2 K. */
HOT static void derivatives(void) {
  static double T[NX * NUU];
  for (int i = 0; i < NH; i++) {
    const double *x = X + i * NX, *z = ZG + i * NX, *r = RG + i * NX, *h = HG + i * NX;
    const double *Si = S + i * NX * NUU;
    double *Sn = S + (i + 1) * NX * NUU;
    double *pz = PZ + i * NX * NUU, *pr = PR + i * NX * NUU, *ph = PH + i * NX * NUU;
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

/* make the cache valid at (w, p) up to `level` */
HOT static void roll(const double *w, const double *p, int level) {
  if (c_level < 0 || memcmp(w, c_w, sizeof c_w) != 0 || memcmp(p, c_p, sizeof c_p) != 0) {
    memcpy(c_w, w, sizeof c_w);
    memcpy(c_p, p, sizeof c_p);
    simulate(p, w, X, ZG, RG, HG);
    c_level = 0;
  }
  if (level >= 1 && c_level < 1) {
    derivatives();
    c_level = 1;
  }
}

