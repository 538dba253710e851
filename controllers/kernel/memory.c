/* The compiled kernel of the single-shooting FHOCP (controllers.ocp.fhocp, eq:optimization):
 * its dimensions, variants and the solver instance's memory (gk_mem, gk_work).
 *
 * The generated header above this line defines the dimensions (NX states, NU inputs, NY
 * outputs, NH horizon stages, NQ reduced output-constraint rows) and declares the numbers,
 * which loader.c (joined last) reads at load time (controllers/kernel/constants.py): the
 * GRU weights (row-major,
 * eq:gru; U^T copies for column-oriented mat-vecs, J_z = [U_z W_z], J_r = [U_r W_r]), the cost
 * weights QW (NX x NX, QDIAG when diagonal), RW (NU x NU), SW (s), the reduced constraint rows
 * DUO (NQ x NX), the eigenvalue clipping margin CLIP (< 0: no clipping), HAS_DU and DW (NU,
 * when HAS_DU): the input-rate weights S = diag(DW) (controllers/ocp/input_rate.py), PFX(name), the
 * symbol prefix (a hash of the source: several kernels can live in one process), and the
 * interface types shared with Python (controllers/kernel/kernel_abi.py: gk_sqp_opts, gk_sqp_info,
 * the gk_sqp_status and gk_qp_status enums), generated from their one definition there.
 *
 * Decision variables w = (u_0 .. u_{N-1}, t[, eps]) (NW = NH*NU + 1 + NSL), parameters p = (x_hat, x_bar,
 * u_bar) (NP = 2 NX + NU), then u_prev = u_{-1} when HAS_DU (NP = 2 NX + 2 NU): the cost's
 * input-rate term sum_i (u_i - u_{i-1})' diag(DW) (u_i - u_{i-1}); without it (HAS_DU 0)
 * none of its code is compiled. HAS_ASS 1: the tracking law (controllers/laws/tracking/reference.py,
 * steady_state.c), w = (u_0 .. u_{NM-1}, u_s, t), p = (x_hat, x_s0, r[, u_prev]), the
 * artificial steady state x_s(u_s) in place of x_bar and u_s in place of u_bar; NM <= NH the
 * control horizon: u_i = u_s for i >= NM (UC, KC, NSC below; NM = NH without one).
 * Same mathematics as controllers/ocp/shooting.py (GRUShooting.rollout,
 * stage_hessians) and controllers/ocp/nlp_single_shooting.py (SingleShootingNLP.objective,
 * constraints, gradient, jacobian, hessian, hessian_convex) -- see there for the formulas;
 * checked against them to ~1e-14 (tests/controllers/kernel/test_compiled_kernel.py).
 *
 * Build-time variants (macros, chosen by controllers/kernel/compiled_kernel.py):
 *   (default)        W-mode: explicit J_h, [A B] and stage Hessians W_i, then Z_i^T W_i Z_i
 *                    (as numpy); best for n <~ N m.
 *   GK_CONTRACT      contracted mode: J_z Z_i, J_r Z_i, J_h Z_i carried forward instead of
 *                    J_h and A_i; O(N^2 n^2 m) instead of O(N n^3); best for large n.
 *   GK_BACKWARD      W-mode with the Hessian condensed backward (long horizons).
 *   GK_BLAS          the n x n x (n+m) / n x n x K products through dgemm (casadi's OpenBLAS).
 *   GK_LAPACK_EIG    eigenvalue clipping with LAPACK dsyevr instead of the own Householder
 *                    reduction, QL and inverse iteration (both: only the eigenpairs below
 *                    the margin).
 *   GK_TIMERS        in-kernel wall-clock accumulators (PFX(timers)).
 *   GK_NO_CLONES     no AVX2/FMA function clones (target_clones) on x86-64.
 *
 * The interface (exported entry points, instances, types): gru_fhocp.h.
 */
#ifndef _POSIX_C_SOURCE
#define _POSIX_C_SOURCE 200809L   /* posix_memalign, clock_gettime under -std=c99 too */
#endif
#include <math.h>
#include <stdlib.h>
#include <string.h>
#ifdef GK_TIMERS
#include <time.h>
static double tk_now(void) { struct timespec t; clock_gettime(CLOCK_MONOTONIC, &t); return t.tv_sec + 1e-9 * t.tv_nsec; }
#define TK_START double tk0_ = tk_now();
#define TK_STOP(i) ws->mem.tk_acc[i] += tk_now() - tk0_;
#else
#define TK_START
#define TK_STOP(i)
#endif

#define NV (NX + NU)
#ifndef NM
#define NM NH
#endif
#if NM < NH && !HAS_ASS
#error "a control horizon NM < NH holds the tail at the artificial steady input (HAS_ASS)"
#endif
#if NM < NH && defined(GK_CONTRACT)
#error "a control horizon NM < NH is not implemented in the contracted mode"
#endif
#define NUF (NH * NU)              /* the inputs u_0 .. u_{N-1} of a rollout */
#define NUU (NM * NU)              /* the free inputs of w: u_0 .. u_{NM-1} */
#define NUA (NUU + HAS_ASS * NU)   /* the free inputs (and u_s): the Hessian's coupled block */
/* the control horizon (NM < NH): u_i = u_s for i >= NM, so u_i is read at w + UC(i), the
 * sensitivities S_i = dx_i/dw have NSC columns (the free inputs, then u_s when the tail holds
 * it) of which the first KC(i) can be nonzero; without one (NM = NH) UC(i) = KC(i) = i NU */
#define UC(i) (((i) < NM ? (i) : NM) * NU)
#define KC(i) (((i) <= NM ? (i) : NM + 1) * NU)
#define NSC (NUU + (NM < NH ? NU : 0))
#define IT NUA                     /* the epigraph variable t */
/* SOFT 1: the softened rows (controllers/ocp/soft.py): after t, one slack per row of L (NQ
 * = NL: the rows are not paired), then the terminal set's; their weights SLW, SLQ (rho,
 * rho2; per instance, gk_mem.slw/slq), SLT the answer check's tolerance of a plan's price */
#ifndef SOFT
#define SOFT 0
#endif
#if SOFT && NQ != NL
#error "softened rows are not paired: NQ = NL"
#endif
#define NSL (SOFT * (NQ + 1))      /* the slacks */
#define IS (IT + 1)                /* the first slack */
#define NW (NUA + 1 + NSL)
#ifndef HAS_MOVE
#define HAS_MOVE 0
#endif
/* the move limit's rows (controllers/ocp/input_rate.py MoveRows, eq:move-constraint): the
 * consecutive moves of u_0 .. u_{NM-1}, u_end (u_bar of p, or u_s of w), the last of g */
#define NMV (HAS_MOVE * NUU)
#define NG ((NH - 1) * NQ + 2 * NX + HAS_ASS * NQ + NMV)
#define RMV (NG - NMV)             /* the first move row */
#if HAS_ASS
/* the tracking law (steady_state.c): p = (x_hat, x_s0, r[, u_prev]), the set-point
 * reference x_bar = x_s(u_s) and u_bar = u_s of the decision vector */
#define NP (2 * NX + NY + HAS_DU * NU)
#define XREF(ws, p) ((void)(p), (const double *)(ws)->mem.xs)
#define UREF(w, p) ((w) + NUU)
#define UPREV(p) ((p) + 2 * NX + NY)
#else
#define NP (2 * NX + NU + HAS_DU * NU)
#define XREF(ws, p) ((p) + NX)
#define UREF(w, p) ((p) + 2 * NX)
#define UPREV(p) ((p) + 2 * NX + NU)
#endif
#define QP_NC (2 * (NW + NG))   /* one-sided constraints of the QP (qp.c) */
#ifndef EXPORT
#define EXPORT __attribute__((visibility("default")))
#endif
#define A32 __attribute__((aligned(32)))
/* hot entry points get an AVX2/FMA clone selected at load time (ifunc), portable otherwise */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && __GNUC__ >= 11 && \
    !defined(GK_NO_CLONES)
#define HOT __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define HOT
#endif
/* helpers that some build-time variants do not call */
#define VARIANT_ONLY __attribute__((unused))

/* ---------------------------------------------------------------- the solver's memory
 * As acados splits a solver's state into mem and work: gk_mem is what persists from one call
 * to the next (the cached rollout, keyed by (w, p), with the derivatives and the steady state
 * of that point, and the counters and timers a caller reads afterwards); gk_work is the
 * scratch one call overwrites (the Hessian's, the eigenvalue clipping's, the QP's and the
 * SQP's). A solver instance, gk_ws, holds one of each, in one allocation. */
typedef struct gk_mem {
  /* the cached rollout at (c_w, c_p) (rollout.c: roll) */
  int c_level;                           /* -1 empty, 0 states, 1 states + derivatives */
  double c_w[NW], c_p[NP];
  A32 double X[(NH + 1) * NX];           /* states x_0 .. x_N */
  A32 double ZG[NH * NX], RG[NH * NX], HG[NH * NX];   /* gates z, r, h per stage */
#ifndef GK_CONTRACT
  A32 double JH[NH * NX * NV];           /* J_h per stage */
  A32 double DF[NH * NX * NV];           /* [A_i B_i] per stage */
#else
  /* contracted mode: J_z Z_i, J_r Z_i, J_h Z_i per stage (NX x NUU, first (i+1) NU columns) */
  A32 double PZ[NH * NX * NUU], PR[NH * NX * NUU], PH[NH * NX * NUU];
#endif
  A32 double S[(NH + 1) * NX * NSC];     /* S_i = dx_i/dw_u, NX x NSC row-major; cols >= KC(i) 0 */
  double uf[NUF];                        /* the inputs u_0 .. u_{N-1} of the cached point */
  /* the steady state x_s = f(x_s, u_s) of the last Newton (steady_state.c; the artificial
   * steady state of the cached point with HAS_ASS, the equilibrium search's in every
   * kernel): X_s = dx_s/du_s = (I - A_s)^-1 B_s (NX x NU row-major), LU of I - A_s,
   * Newton's status */
  double xs[NX], XS[NX * NU], xs_lu[NX * NX];
  double xs_z[NX], xs_r[NX], xs_h[NX], xs_jh[NX * NV];   /* its gates and J_h */
  int xs_piv[NX], xs_status;
  /* the cost weights a solve reads, per instance: R (NU x NU), S = diag(dw) (HAS_DU), the
   * offset weights T = diag(tw) (HAS_ASS); the library's RW, DW, TW at ws_reset, tunable
   * between solves (the exported controller's parameters, controller.c). Q and s stay the
   * library's: s = n lambda_max(Q) / (1 - rho_s^2) is the certificate's (eq:definition_s). */
  double rw[NU * NU];
#if HAS_DU
  double dw[NU];
#endif
#if HAS_ASS
  double tw[NY];
#endif
#if SOFT
  /* the softened rows' weights a solve reads: SLW, SLQ (rho, rho2), or 0 in the hard phase
   * (PFX(set_soft); controllers/ocp/soft.py) */
  double slw, slq;
#endif
  long n_calls, n_eig, n_clipped, n_evs, n_full_eig; /* clipping counters (PFX(counters)) */
#ifdef GK_TIMERS
  double tk_acc[4];
#endif
} gk_mem;

typedef struct gk_work {
#ifdef GK_CONTRACT
  A32 double T[NX * NUU];                /* the contracted derivatives' scratch */
#endif
#if HAS_ASS
  A32 double xs_P[4 * NX * NV];          /* the steady state's gate derivatives */
  A32 double ass_ssum[NX * NSC];        /* sum_{i>=1} S_i (ass_hessian) */
#endif
  /* the Hessian of the Lagrangian (hessian.c) */
  A32 double MU[(NH + 1) * NX];          /* adjoints */
#ifndef GK_CONTRACT
  A32 double Ph[NX * NV], Pz[NX * NV], Pr[NX * NV], G[NX * NV];   /* stage_hessian */
  A32 double W[NV * NV], Y[NX * NSC];    /* one stage's W_i and W_i,xx S_i */
#ifdef GK_BACKWARD
  A32 double P[NX * NX], YB[NX * NV];    /* the Hessian-to-go, P D_f */
#endif
#else
  A32 double L[5 * NX * NUU], R[5 * NX * NUU], QS[NX * NUU];
#endif
  /* plain rollouts (PFX(simulate), assess): the gates, not kept */
  A32 double sz[NH * NX], sr[NH * NX], sh[NH * NX];
  A32 double Hrm[NW * NW];               /* the casadi Hessian's row-major copy */
  /* eigenvalue clipping (eigen_clip.c) */
  A32 double V[NUA * NUA], Hu[NUA * NUA];
  double d[NUA], e[NUA], tau[NUA], td[NUA], te[NUA], lu[4 * NUA];
  unsigned char piv[NUA];
#ifdef GK_LAPACK_EIG
  A32 double Z[NUA * NUA], lapack_work[26 * NUA];
  int iwork[10 * NUA], isuppz[2 * NUA];
#endif
  /* the QP (qp.c) */
  A32 double qL[NW * NW], qJ[NW * NW], qR[NW * NW];
  double qd[NW], qz[NW], qr[NW], qu[NW + 1], qn[NW], qax[NG];
  int qact[NW + 1];
  unsigned char qin[QP_NC];
  /* the SQP (sqp.c) */
  A32 double sq_J[NG * NW], sq_H[NW * NW];
  double sq_gf[NW], sq_gz[NG], sq_gl[NW], sq_lbx[NW], sq_ubx[NW], sq_lba[NG], sq_uba[NG],
      sq_dw[NW], sq_lx[NW], sq_la[NG], sq_wc[NW], sq_gc[NG], sq_gq[NW], sq_zx[NW], sq_zg[NG],
      sq_w0[NW], sq_lx0[NW], sq_lg0[NG];   /* the initial guess, for a fresh restart */
} gk_work;

/* one solver instance: what every entry point taking a workspace reads and writes */
struct gk_ws {
  gk_mem mem;
  gk_work work;
};

/* the library's cost weights into the instance's (gk_mem.rw, dw, tw) */
static void ws_default_weights(gk_ws *ws) {
  memcpy(ws->mem.rw, RW, sizeof ws->mem.rw);
#if HAS_DU
  memcpy(ws->mem.dw, DW, sizeof ws->mem.dw);
#endif
#if HAS_ASS
  memcpy(ws->mem.tw, TW, sizeof ws->mem.tw);
#endif
#if SOFT
  ws->mem.slw = SLW;
  ws->mem.slq = SLQ;
#endif
}

static void ws_reset(gk_ws *ws) {
  memset(ws, 0, sizeof *ws);
  ws->mem.c_level = -1;
  ws_default_weights(ws);
}

/* a new workspace (NULL when out of memory); free it with PFX(ws_free) */
/* whether the library's numbers are loaded (loader.c, joined last: PFX(load_data)) */
static int gk_data_ready(void);

EXPORT gk_ws *PFX(ws_new)(void) {
  void *mem = 0;
  if (!gk_data_ready()) return 0;
  if (posix_memalign(&mem, 64, sizeof(gk_ws)) != 0) return 0;
  ws_reset((gk_ws *)mem);
  return (gk_ws *)mem;
}

EXPORT void PFX(ws_free)(gk_ws *ws) { free(ws); }

/* ---------------------------------------------------------------- the casadi functions' memory
 * casadi calls an external function with its own work vector w of the size the function asks
 * for (PFX(F_work)), one per casadi memory object, never shared by two concurrent calls.
 * The casadi functions PFX(fg), PFX(jac_fg), PFX(hess_l) evaluate in a solver instance laid
 * out in that vector (aligned to 64 bytes, hence the slack), reset at each call: casadi may
 * use the vector for other work between two calls, so nothing is kept from one to the next
 * and there is no file-level state. */
#define GK_CASADI_W ((casadi_int)((sizeof(gk_ws) + 63) / sizeof(double)) + 8)

static gk_ws *casadi_ws(double *w) {
  gk_ws *ws = (gk_ws *)(((unsigned long)w + 63) & ~(unsigned long)63);
  ws_reset(ws);
  return ws;
}
