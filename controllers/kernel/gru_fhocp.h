/* gru_fhocp.h: the interface of a compiled FHOCP kernel (eq:optimization, single shooting).
 *
 * A kernel is one shared library per problem: the generated header before this one defines
 * its dimensions and constants (controllers/kernel/compiled_kernel.py: generate_source), the
 * symbol prefix PFX(name) (a hash of the source, so that several kernels live in one process)
 * and the interface types, generated from their one definition in kernel_abi.py:
 *
 *   gk_sqp_opts    the SQP's options (casadi sqpmethod's meanings, plus reuse_step)
 *   gk_sqp_info    what one SQP solve reports (status, iterations, timers, restarts)
 *   gk_assessment  the independent check of one input sequence (cost, violations, ...)
 *   gk_dims        the library's dimensions
 *   gk_counters    an instance's eigenvalue-clipping counts
 *   enum gk_sqp_status, enum gk_qp_status
 *
 * Vectors are double arrays, matrices row-major unless said otherwise. The decision vector
 * is w = (u_0 .. u_{NM-1}[, u_s], t) (NW entries; t the terminal slack), the parameters
 * p = (x_hat, x_bar, u_bar[, u_prev]) (paper law) or (x_hat, x_s0, r[, u_prev]) (tracking,
 * HAS_ASS), NP entries; inputs are normalised to [-1, 1].
 *
 * Numbers: the problem's (GRU weights, cost weights, constraint rows, clipping margin) are
 * declared by the generated header and loaded once, before any instance, from a data file
 * (PFX(load_data), loader.c; controllers/kernel/constants.py): the source and the binary are
 * the same for every problem of the same dimensions.
 *
 * State: a solver instance, gk_ws (memory.c), holds the memory that persists between calls
 * (gk_mem: the rollout cached by (w, p), counters) and the per-call workspace (gk_work); the
 * library itself holds only its numbers, written once by PFX(load_data), so instances solve
 * concurrently from several threads, one thread per instance, with the answers they give one
 * after the other.
 */
#ifndef GRU_FHOCP_H
#define GRU_FHOCP_H

#include <stddef.h>

typedef long long int casadi_int;
typedef struct gk_ws gk_ws;

/* ---- the numbers */
/* Load the library's numbers from the data file bytes[0 .. size) (loader.c): NULL, or why
 * they are refused (another layout, damaged, or other numbers than those already loaded),
 * written to msg (n chars). Nothing is written unless the whole file is valid. */
const char *PFX(load_data)(const unsigned char *bytes, size_t size, char *msg, size_t n);

/* ---- instances */
/* A new solver instance (NULL when out of memory or before PFX(load_data)); every call below
 * taking one writes only it. */
gk_ws *PFX(ws_new)(void);
void PFX(ws_free)(gk_ws *ws);
/* Forget the cached rollout. */
void PFX(invalidate)(gk_ws *ws);
/* The calling thread's shift of the biases (b_z, b_r, b_h; 3 NX): the measured disturbances
 * held over the horizon (controllers.disturbances); every later call on this thread sees it.
 * A cached rollout is not forgotten: invalidate the workspaces that hold one. A kernel
 * without HAS_SHIFT (no measured disturbances) ignores it. */
void PFX(set_bias_shift)(const double *db);

/* ---- the FHOCP */
/* The SQP of the FHOCP in one call (sqp.c): from the initial guess (w, lam_x, lam_g), which
 * receive the answer, with the bounds on w and on the constraints g(w, p) (NG); writes g and
 * f = the cost, fills info and returns a gk_sqp_status. */
int PFX(sqp)(gk_ws *ws, const double *p, const double *lbx, const double *ubx,
             const double *lbg, const double *ubg, double *w, double *lam_x, double *lam_g,
             double *g, double *f, const gk_sqp_opts *opt, gk_sqp_info *info);
/* The answer check of w at p (api.c): u = clip(w_u, -1, 1) into uc (NH x NU), its states x
 * (NH+1 x NX) and assessment out against the tightened bounds bnd (NH x NL) and the
 * terminal radius alpha; xs (NX): the steady state checked against (HAS_ASS). */
void PFX(assess_w)(gk_ws *ws, const double *w, const double *p, const double *bnd,
                   double alpha, double *uc, double *x, gk_assessment *out, double *xs);
/* The same check of a given input sequence u (NH x NU) from xh towards (xb, ub). */
void PFX(assess)(gk_ws *ws, const double *xh, const double *u, const double *xb,
                 const double *ub, const double *up, const double *bnd, double alpha,
                 double *x, gk_assessment *out);
/* |x_N - x_ref|inf of the rollout at (w, p): the smallest feasible terminal slack. */
double PFX(terminal_gap)(gk_ws *ws, const double *w, const double *p);
double PFX(plan_slacks)(gk_ws *ws, double *w, const double *p, const double *bnd,
                        double alpha);
void PFX(set_soft)(gk_ws *ws, int on);
/* States x_0 .. x_N from x0 under u (no cache involved); the rollout at (w, p). */
void PFX(simulate)(gk_ws *ws, const double *x0, const double *u, double *x);
void PFX(xtraj)(gk_ws *ws, const double *w, const double *p, double *x);

/* ---- the model */
/* The output y = U_o x + b_o (NY). */
void PFX(output)(const double *x, double *y);
/* One step of eq:gru with extra gate inputs dz, dr (eq:observer; NULL: none). */
void PFX(gru_step)(const double *x, const double *u, const double *dz, const double *dr,
                   double *xn);
/* The equilibrium x = f(x, u) with output y by Newton from (x0, u0) (NU > NY: minimum-norm
 * steps; NU < NY: Gauss-Newton); 0 converged, 1 not converged or NaN, 2 singular. */
int PFX(eq_newton)(const double *y, const double *x0, const double *u0, int max_iter,
                   double tol, double *xo, double *uo);
/* The steady state x_s(u_s) = f(x_s, u_s) by Newton from x0; 0 converged. */
int PFX(steady)(gk_ws *ws, const double *us, const double *x0, double *xs);
/* The equilibrium (x, u), |u|inf <= 1, whose output U_o x + b_o is closest to y
 * (equilibrium.c): 0 when y is reached, 1 for the closest reachable one. */
int PFX(equilibrium)(gk_ws *ws, const double *y, double *x, double *u);

/* ---- the library */
void PFX(dims)(gk_dims *out);
/* sizeof of each interface struct, in kernel_abi.py's order, then of gk_ws: GK_ABI_COUNT
 * entries (read before any struct is trusted: kernel_abi.check_layout). */
void PFX(abi)(long *out);
void PFX(counters)(const gk_ws *ws, gk_counters *out);
/* GK_TIMERS builds: seconds in fg, jac_fg, hess_l, hess_raw; -1 otherwise. */
void PFX(timers)(const gk_ws *ws, double *out);

/* ---- casadi external functions (casadi's codegen calling convention; loop="casadi"):
 * PFX(fg), PFX(jac_fg), PFX(hess_l) (eigenvalue-clipped), PFX(hess_raw), with their
 * _n_in, _n_out, _name_in, _name_out, _sparsity_in, _sparsity_out, _work, _checkout,
 * _release, _incref, _decref. Each evaluates in casadi's work vector (memory.c). */
int PFX(fg)(const double **arg, double **res, casadi_int *iw, double *w, int mem);
int PFX(jac_fg)(const double **arg, double **res, casadi_int *iw, double *w, int mem);
int PFX(hess_l)(const double **arg, double **res, casadi_int *iw, double *w, int mem);
int PFX(hess_raw)(const double **arg, double **res, casadi_int *iw, double *w, int mem);

/* ---- test hooks */
int PFX(qp)(gk_ws *ws, const double *H, const double *g, const double *A, const double *lbx,
            const double *ubx, const double *lba, const double *uba, double *d,
            double *lam_x, double *lam_a, int *changes);
void PFX(grad_l)(gk_ws *ws, const double *w, const double *p, const double *lam_x,
                 const double *lam_g, double *gl);
int PFX(clip)(gk_ws *ws, double *H);

#endif /* GRU_FHOCP_H */
