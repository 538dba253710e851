/* law.c of the toy law "steady" (tests/controllers/laws/steady): u = the equilibrium input of
 * the set-point yr, by the kernel's equilibrium search (PFX(equilibrium): the Python law's
 * equilibrium_for_output on the same kernel), clipped to the box. */
#if !HAS_ASS
#error "the steady law runs on a tracking FHOCP's kernel (its equilibrium search)"
#endif

enum { LAW_N_PARAMETERS = 0 };

typedef struct law_state {
  gk_ws *ws;
  int cand_feasible;
  ctl_last last;
} law_state;

static void law_reset(law_state *st, gk_ws *ws) {
  memset(st, 0, sizeof *st);
  st->ws = ws;
  st->cand_feasible = 1;
  last_reset(&st->last);
}

__attribute__((unused)) static void law_disturbance_moved(law_state *st) { (void)st; }

__attribute__((unused)) static void law_restart(law_state *st) { (void)st; }

static void law_applied(law_state *st, const double *u) { (void)st; (void)u; }

static int law_room(const law_state *st, double *slack) {
  (void)st; (void)slack;
  return 0;
}

static void law_step(law_state *st, const double *xhat, const double *xstart,
                     const ctl_prefix *prefix, const ctl_ops *ops, double e_o, const double *y,
                     const double *yr, double *u, int *warnings) {
  double x[NX];
  (void)xhat; (void)xstart; (void)prefix; (void)ops; (void)e_o; (void)y; (void)warnings;
  PFX(equilibrium)(st->ws, yr, x, u);
  for (int j = 0; j < NU; j++) u[j] = gk_clip1(u[j]);
  st->last.status = CTL_OPTIMAL;
  st->last.fallback = 0;
  st->last.iterations = 0;
}

static double *law_parameter(law_state *st, int i) {
  (void)st; (void)i;
  return 0;
}

static const char *law_refuse(const law_state *st, int i, double value) {
  (void)st; (void)i; (void)value;
  return "the steady-state law has no settings";
}
