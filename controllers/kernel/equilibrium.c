/* Part of the compiled FHOCP kernel (controllers/kernel/compiled_kernel.py joins the
 * generated header, gru_fhocp.h and the parts into one translation unit), every
 * kernel: the model equilibrium whose output is closest to a given one (controllers/
 * equilibrium.py equilibrium_for_output), on the steady state's Newton (steady_state.c).
 * The observer starts there (paper section V), the tracking law's steady state too, and the
 * paper's law finds the reference (x_bar, u_bar) of each set-point with it, in Python and in
 * the exported controller alike. */
/* Residual below which an output counts as reached (controllers/equilibrium.py REACH_TOL). */
#define GK_REACH_TOL 1e-8

/* v clipped to [-1, 1] (the exported controller's step uses it too) */
static double gk_clip1(double v) { return v < -1.0 ? -1.0 : (v > 1.0 ? 1.0 : v); }

static double gk_max_abs_diff(const double *a, const double *b, int n) {
  double d = 0.0;
  for (int k = 0; k < n; k++) {
    const double e = fabs(a[k] - b[k]);
    if (e > d || e != e) d = e;
  }
  return d;
}

/* The output of the state equilibrium of u: x(u) = f(x(u), u) by the kernel's Newton from x
 * (written back), F = U_o x(u) + b_o - y and, when J is given, J = dF/du = U_o X_s (NY x NU,
 * X_s = (I - A_s)^-1 B_s of that Newton). Returns 0, or 1 when Newton fails. */
static int eq_residual(gk_ws *ws, const double *u, const double *y, double *x, double *F,
                       double *J) {
  double xs[NX];
  if (PFX(steady)(ws, u, x, xs) != 0) return 1;
  memcpy(x, xs, sizeof xs);
  PFX(output)(x, F);
  for (int a = 0; a < NY; a++) F[a] -= y[a];
  if (J)
    for (int a = 0; a < NY; a++)
      for (int j = 0; j < NU; j++) {
        double s = 0.0;
        for (int k = 0; k < NX; k++) s += UO[a * NX + k] * ws->mem.XS[k * NU + j];
        J[a * NU + j] = s;
      }
  return 0;
}

static double half_sq(const double *F) {
  double f = 0.0;
  for (int a = 0; a < NY; a++) f += F[a] * F[a];
  return 0.5 * f;
}

/* min ||U_o x(u) + b_o - y||^2 over ||u||inf <= 1 from u0 (bounded least squares, as scipy's
 * least_squares in controllers/equilibrium.py _solve): projected Gauss-Newton on the inputs
 * not held at a bound, damped (Levenberg) when a step does not decrease the residual, with a
 * projected backtracking search, to a stationary point. Writes u. */
static void bounded_lsq(gk_ws *ws, const double *y, const double *u0, double *u) {
  double x[NX] = {0.0}, F[NY], J[NY * NU], un[NU], xn[NX], Fn[NY];
  for (int j = 0; j < NU; j++) u[j] = gk_clip1(u0[j]);
  if (eq_residual(ws, u, y, x, F, J) != 0) return;
  double f = half_sq(F), mu = 0.0;
  for (int it = 0; it < 200; it++) {
    double g[NU], H[NU * NU], d[NU];
    int freev[NU], nf = 0;
    double pg = 0.0;
    for (int j = 0; j < NU; j++) {
      double s = 0.0;
      for (int a = 0; a < NY; a++) s += J[a * NU + j] * F[a];
      g[j] = s;
      const int held = (u[j] <= -1.0 && s > 0.0) || (u[j] >= 1.0 && s < 0.0);
      if (!held) {
        freev[nf++] = j;
        pg = fmax(pg, fabs(s));
      }
    }
    if (nf == 0 || pg <= 1e-300) break;
    /* (J_F' J_F + mu I) d_F = -g_F by Gaussian elimination with partial pivoting */
    for (int r = 0; r < nf; r++) {
      for (int c = 0; c < nf; c++) {
        double s = 0.0;
        for (int a = 0; a < NY; a++) s += J[a * NU + freev[r]] * J[a * NU + freev[c]];
        H[r * NU + c] = s + (r == c ? mu : 0.0);
      }
      d[r] = -g[freev[r]];
    }
    int singular = 0;
    for (int c = 0; c < nf && !singular; c++) {
      int piv = c;
      for (int r = c + 1; r < nf; r++)
        if (fabs(H[r * NU + c]) > fabs(H[piv * NU + c])) piv = r;
      if (H[piv * NU + c] == 0.0) { singular = 1; break; }
      for (int q = 0; q < nf; q++) {
        const double t = H[c * NU + q]; H[c * NU + q] = H[piv * NU + q]; H[piv * NU + q] = t;
      }
      const double t = d[c]; d[c] = d[piv]; d[piv] = t;
      for (int r = c + 1; r < nf; r++) {
        const double l = H[r * NU + c] / H[c * NU + c];
        for (int q = c; q < nf; q++) H[r * NU + q] -= l * H[c * NU + q];
        d[r] -= l * d[c];
      }
    }
    if (singular) { mu = mu > 0.0 ? 10.0 * mu : 1e-10; continue; }
    for (int c = nf - 1; c >= 0; c--) {
      double s = d[c];
      for (int q = c + 1; q < nf; q++) s -= H[c * NU + q] * d[q];
      d[c] = s / H[c * NU + c];
    }
    /* the projected step, halved until the residual decreases */
    int accepted = 0;
    double moved = 0.0;
    for (double t = 1.0; t > 1e-12 && !accepted; t *= 0.5) {
      memcpy(un, u, sizeof un);
      for (int r = 0; r < nf; r++) un[freev[r]] = gk_clip1(u[freev[r]] + t * d[r]);
      memcpy(xn, x, sizeof xn);
      if (eq_residual(ws, un, y, xn, Fn, 0) != 0) continue;
      const double fn = half_sq(Fn);
      if (fn < f) {
        moved = gk_max_abs_diff(un, u, NU);
        accepted = 1;
        memcpy(u, un, sizeof un);
        memcpy(x, xn, sizeof xn);
        f = fn;
      }
    }
    if (!accepted) {
      if (mu > 1e6) break;
      mu = mu > 0.0 ? 10.0 * mu : 1e-10;
      continue;
    }
    mu *= 0.1;
    if (eq_residual(ws, u, y, x, F, J) != 0 || moved <= 1e-15 || f <= 0.0) break;
  }
}

/* The equilibrium (x, u), ||u||inf <= 1, whose output is closest to y (controllers/
 * equilibrium.py equilibrium_for_output and _solve, the same starting inputs and choice):
 * bounded least squares from each start, the best residual kept, until one reaches y or
 * two agree; x the state equilibrium of u from zero. Returns 0 when y is reached (to
 * GK_REACH_TOL), else 1 (the closest reachable equilibrium). */
EXPORT int PFX(equilibrium)(gk_ws *ws, const double *y, double *x, double *u) {
  double u0[NU], ub[NU], xb[NX], F[NY], zero[NX] = {0.0}, best = INFINITY;
  int agree = 0, have = 0;
  const int nstart = 3 + 2 * NU;
  for (int s = 0; s < nstart; s++) {
    for (int j = 0; j < NU; j++) u0[j] = (s == 1) ? 0.5 : (s == 2) ? -0.5 : 0.0;
    if (s >= 3) u0[(s - 3) / 2] = (s - 3) % 2 == 0 ? 0.5 : -0.5;
    bounded_lsq(ws, y, u0, ub);
    memcpy(xb, zero, sizeof xb);
    if (eq_residual(ws, ub, y, xb, F, 0) != 0) continue;
    double err = 0.0;
    for (int a = 0; a < NY; a++) err = fmax(err, fabs(F[a]));
    if (have && gk_max_abs_diff(ub, u, NU) < 1e-7) agree++;
    if (!have || err < best - 1e-15) {
      memcpy(u, ub, sizeof ub);
      memcpy(x, xb, sizeof xb);
      best = err;
      have = 1;
    }
    if (err < GK_REACH_TOL * 1e-3 || agree >= 2) break;
  }
  if (!have) {
    for (int j = 0; j < NU; j++) u[j] = 0.0;
    if (PFX(steady)(ws, u, zero, x) != 0) memset(x, 0, NX * sizeof(double));
    return 1;
  }
  return best > GK_REACH_TOL;
}
