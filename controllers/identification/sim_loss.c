/* The simulation error of the GRU of the paper (eq:gru) and its gradient by backpropagation
 * through time, for identification (controllers/identification/sim_loss.py loads this file;
 * torch's autograd of the same rollout is the reference it is tested against).
 *
 *   z_t = sigmoid(W_z u_t + U_z x_t + b_z),  r_t = sigmoid(W_r u_t + U_r x_t + b_r)
 *   h_t = tanh(W_h u_t + U_h (r_t o x_t) + b_h),  x_{t+1} = z_t o x_t + (1 - z_t) o h_t
 *   xi_t = U_o x_t + b_o
 *
 *   loss = sum_{b, t, j} w_btj e_btj^2,  e = xi - y, except at a sensor limit: where the
 *   measured y sits at its upper limit (sat = +1) an xi above it is no error (e = 0), at its
 *   lower limit (sat = -1) an xi below it.
 *
 * Every dimension is a run-time argument: one library for every model. The weights are packed
 * in the model file's order (W_z U_z b_z W_r U_r b_r W_h U_h b_h U_o b_o, row-major). No
 * state between calls; a call allocates its own scratch (4 T n + T p doubles). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define EXPORT __attribute__((visibility("default")))

typedef struct {
  const double *Wz, *Uz, *bz, *Wr, *Ur, *br, *Wh, *Uh, *bh, *Uo, *bo;
} sl_weights;

typedef struct {
  double *Wz, *Uz, *bz, *Wr, *Ur, *br, *Wh, *Uh, *bh, *Uo, *bo;
} sl_grads;

/* the number of doubles of the packed weights */
EXPORT long sl_size(int n, int m, int p) {
  return 3L * (n * m + n * n + n) + (long)p * n + p;
}

static void sl_unpack(const double *P, int n, int m, int p, sl_weights *w) {
  const double *c = P;
  w->Wz = c; c += n * m; w->Uz = c; c += n * n; w->bz = c; c += n;
  w->Wr = c; c += n * m; w->Ur = c; c += n * n; w->br = c; c += n;
  w->Wh = c; c += n * m; w->Uh = c; c += n * n; w->bh = c; c += n;
  w->Uo = c; c += p * n; w->bo = c;
}

static void sl_unpack_grads(double *G, int n, int m, int p, sl_grads *g) {
  double *c = G;
  g->Wz = c; c += n * m; g->Uz = c; c += n * n; g->bz = c; c += n;
  g->Wr = c; c += n * m; g->Ur = c; c += n * n; g->br = c; c += n;
  g->Wh = c; c += n * m; g->Uh = c; c += n * n; g->bh = c; c += n;
  g->Uo = c; c += p * n; g->bo = c;
}

static double sl_sigmoid(double v) { return 1.0 / (1.0 + exp(-v)); }

/* a = W u + U v + b for one gate (n rows) */
static void sl_gate(int n, int m, const double *W, const double *U, const double *b,
                    const double *u, const double *v, double *a) {
  for (int i = 0; i < n; i++) {
    double s = b[i];
    const double *wi = W + (long)i * m, *ui = U + (long)i * n;
    for (int k = 0; k < m; k++) s += wi[k] * u[k];
    for (int k = 0; k < n; k++) s += ui[k] * v[k];
    a[i] = s;
  }
}

/* One sequence: the forward rollout from x0 (keeping x, z, r, h of every step in X, Z, R, H),
 * its loss, and dL/dxi in D (T x p). Returns the loss. */
static double sl_forward(int n, int m, int p, int T, const sl_weights *w, const double *x0,
                         const double *u, const double *y, const double *wt,
                         const signed char *sat, double *X, double *Z, double *R, double *H,
                         double *D, double *xi_out) {
  double loss = 0.0;
  memcpy(X, x0, sizeof(double) * n);
  for (int t = 0; t < T; t++) {
    const double *x = X + (long)t * n, *ut = u + (long)t * m;
    for (int j = 0; j < p; j++) {
      double s = w->bo[j];
      const double *oj = w->Uo + (long)j * n;
      for (int k = 0; k < n; k++) s += oj[k] * x[k];
      const long o = (long)t * p + j;
      if (xi_out) xi_out[o] = s;
      double e = s - y[o];
      if (sat && ((sat[o] > 0 && e > 0.0) || (sat[o] < 0 && e < 0.0))) e = 0.0;
      const double we = wt ? wt[o] : 1.0;
      loss += we * e * e;
      D[o] = 2.0 * we * e;
    }
    if (t == T - 1) break;            /* x_T enters no output of the window */
    double *z = Z + (long)t * n, *r = R + (long)t * n, *h = H + (long)t * n;
    double *xn = X + (long)(t + 1) * n;
    sl_gate(n, m, w->Wz, w->Uz, w->bz, ut, x, z);
    sl_gate(n, m, w->Wr, w->Ur, w->br, ut, x, r);
    for (int i = 0; i < n; i++) { z[i] = sl_sigmoid(z[i]); r[i] = sl_sigmoid(r[i]); }
    for (int i = 0; i < n; i++) xn[i] = r[i] * x[i];   /* r o x, kept in x_{t+1}'s slot */
    sl_gate(n, m, w->Wh, w->Uh, w->bh, ut, xn, h);
    for (int i = 0; i < n; i++) {
      h[i] = tanh(h[i]);
      xn[i] = z[i] * x[i] + (1.0 - z[i]) * h[i];
    }
  }
  return loss;
}

/* The backward sweep of one sequence: adds its gradient to g, writes dL/dx0 to gx0. */
static void sl_backward(int n, int m, int p, int T, const sl_weights *w, sl_grads *g,
                        const double *u, const double *X, const double *Z, const double *R,
                        const double *H, const double *D, double *lam, double *gx,
                        double *tmp, double *gx0) {
  double *daz = tmp, *dar = tmp + n, *dah = tmp + 2 * n, *drx = tmp + 3 * n;
  memset(lam, 0, sizeof(double) * n);          /* dL/dx_{t+1} */
  for (int t = T - 1; t >= 0; t--) {
    const double *x = X + (long)t * n, *ut = u + (long)t * m, *d = D + (long)t * p;
    memset(gx, 0, sizeof(double) * n);
    if (t < T - 1) {
      const double *z = Z + (long)t * n, *r = R + (long)t * n, *h = H + (long)t * n;
      for (int i = 0; i < n; i++) {
        const double dz = lam[i] * (x[i] - h[i]), dh = lam[i] * (1.0 - z[i]);
        gx[i] += lam[i] * z[i];
        daz[i] = dz * z[i] * (1.0 - z[i]);
        dah[i] = dh * (1.0 - h[i] * h[i]);
      }
      for (int k = 0; k < n; k++) drx[k] = 0.0;
      for (int i = 0; i < n; i++) {             /* drx = U_h' dah */
        const double a = dah[i];
        const double *hi = w->Uh + (long)i * n;
        for (int k = 0; k < n; k++) drx[k] += hi[k] * a;
      }
      for (int i = 0; i < n; i++) {
        gx[i] += drx[i] * r[i];
        dar[i] = drx[i] * x[i] * r[i] * (1.0 - r[i]);
      }
      for (int i = 0; i < n; i++) {             /* + U_z' daz + U_r' dar, and the weights' */
        const double az = daz[i], ar = dar[i], ah = dah[i];
        const double *zi = w->Uz + (long)i * n, *ri = w->Ur + (long)i * n;
        double *gzi = g->Uz + (long)i * n, *gri = g->Ur + (long)i * n, *ghi = g->Uh + (long)i * n;
        for (int k = 0; k < n; k++) {
          gx[k] += zi[k] * az + ri[k] * ar;
          gzi[k] += az * x[k];
          gri[k] += ar * x[k];
          ghi[k] += ah * r[k] * x[k];
        }
        double *wzi = g->Wz + (long)i * m, *wri = g->Wr + (long)i * m, *whi = g->Wh + (long)i * m;
        for (int k = 0; k < m; k++) {
          wzi[k] += az * ut[k];
          wri[k] += ar * ut[k];
          whi[k] += ah * ut[k];
        }
        g->bz[i] += az;
        g->br[i] += ar;
        g->bh[i] += ah;
      }
    }
    for (int j = 0; j < p; j++) {               /* the output xi_t = U_o x_t + b_o */
      const double dj = d[j];
      if (dj == 0.0) continue;
      const double *oj = w->Uo + (long)j * n;
      double *goj = g->Uo + (long)j * n;
      for (int k = 0; k < n; k++) {
        gx[k] += oj[k] * dj;
        goj[k] += dj * x[k];
      }
      g->bo[j] += dj;
    }
    memcpy(lam, gx, sizeof(double) * n);
  }
  memcpy(gx0, lam, sizeof(double) * n);
}

/* The loss of B windows of T steps (inputs u: B x T x m, outputs y: B x T x p, weights wt and
 * sensor-limit flags sat: B x T x p or NULL for ones and none), each from its initial state
 * x0 (B x n), at the packed weights P; with gP (the packed weights' size) and gx0 (B x n)
 * non-NULL, their gradients (overwritten); with xi non-NULL, the outputs (B x T x p).
 * Returns the loss, or NAN when out of memory. */
EXPORT double sl_loss(int n, int m, int p, int T, int B, const double *P, const double *x0,
                      const double *u, const double *y, const double *wt,
                      const signed char *sat, double *gP, double *gx0, double *xi) {
  sl_weights w;
  sl_unpack(P, n, m, p, &w);
  sl_grads g;
  if (gP) {
    memset(gP, 0, sizeof(double) * sl_size(n, m, p));
    sl_unpack_grads(gP, n, m, p, &g);
  }
  const long per = 4L * T * n + (long)T * p + 6L * n;
  double *buf = malloc(sizeof(double) * per);
  if (!buf) return NAN;
  double *X = buf, *Z = X + (long)T * n, *R = Z + (long)T * n, *H = R + (long)T * n;
  double *D = H + (long)T * n, *lam = D + (long)T * p, *gx = lam + n, *tmp = gx + n;
  double loss = 0.0;
  for (int b = 0; b < B; b++) {
    const long io = (long)b * T;
    loss += sl_forward(n, m, p, T, &w, x0 + (long)b * n, u + io * m, y + io * p,
                       wt ? wt + io * p : 0, sat ? sat + io * p : 0, X, Z, R, H, D,
                       xi ? xi + io * p : 0);
    if (gP && gx0)
      sl_backward(n, m, p, T, &w, &g, u + io * m, X, Z, R, H, D, lam, gx, tmp,
                  gx0 + (long)b * n);
  }
  free(buf);
  return loss;
}
