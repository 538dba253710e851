/* operator.c: the operator's settings of the exported controller, the C twin of
 * controllers/operator.py (Operator) and of what controllers/mpc_operating.py (Operating)
 * does with them each step; joined after the law's files, before controller.c (which owns
 * the instance).
 *
 * The settings, by index (controller_source.py operator_names() names them, the controller
 * FMU's inputs of those names): 0 op.mode (1 auto, 0 manual), then op.service.<input> and
 * op.manual.<input> (NaN: the plant's value), then op.min.<signal> and op.max.<signal> for the
 * inputs, then the outputs (CT_OUT_LIMITS: a law that takes operator limits on its outputs).
 * Each step, in Python's order: the active limits ramp (an input's by max_move, an output's by
 * limit_rate and the room the law's last plan leaves: law_room), the set-points are taken
 * inside the active output limits, the FHOCP's terms are built (ctl_ops), the law steps, and
 * the plant gets the operator's, held or limited inputs (op_applied), never more than
 * max_move from the last in every mode the controller writes.
 */
#define OP_NSIG (NU + CT_OUT_LIMITS * NY)        /* signals with operator limits */
#define OP_I_SERVICE 1
#define OP_I_MANUAL (1 + NU)
#define OP_I_MIN (1 + 2 * NU)
#define OP_I_MAX (OP_I_MIN + OP_NSIG)
#define CT_NOPS (OP_I_MAX + OP_NSIG)

typedef struct ctl_operator {
  double mode, manual[NU];
  int service[NU];
  /* the limits asked for (targets) and in force (active), problem units: [signal][0 lo, 1 hi] */
  double target[OP_NSIG][2], active[OP_NSIG][2];
  /* the inputs the plant got last (problem units), the plant at rest before any */
  int has_last, has_start;
  double last[NU], start[NU];
  ctl_ops ops;   /* this step's terms */
} ctl_operator;

static double op_box(int k, int side) {
  if (k < NU) return side ? CT_U_HI[k] : CT_U_LO[k];
  return side ? CT_Y_HI[k - NU] : CT_Y_LO[k - NU];
}

static void op_reset(ctl_operator *o) {
  memset(o, 0, sizeof *o);
  o->mode = 1.0;
  for (int j = 0; j < NU; j++) {
    o->service[j] = 1;
    o->manual[j] = NAN;
  }
  for (int k = 0; k < OP_NSIG; k++)
    for (int s = 0; s < 2; s++) o->target[k][s] = o->active[k][s] = op_box(k, s);
}

/* Operator.engaged: anything but the defaults, or a declared move limit */
static int op_engaged(const ctl_operator *o) {
  if (CT_MOVES || o->mode != 1.0) return 1;
  for (int j = 0; j < NU; j++)
    if (!o->service[j]) return 1;
  for (int k = 0; k < OP_NSIG; k++)
    for (int s = 0; s < 2; s++)
      if (o->target[k][s] != op_box(k, s) || o->active[k][s] != op_box(k, s)) return 1;
  return 0;
}

static double op_value(const ctl_operator *o, int i) {
  if (i == 0) return o->mode;
  if (i < OP_I_MANUAL) return o->service[i - OP_I_SERVICE];
  if (i < OP_I_MIN) return o->manual[i - OP_I_MANUAL];
  if (i < OP_I_MAX) return o->target[i - OP_I_MIN][0];
  if (i < CT_NOPS) return o->target[i - OP_I_MAX][1];
  return NAN;
}

/* the tracking law's admissible steady outputs Y_s (CT_YS_BASE) narrowed by the limits box
 * (outputs' rows) leave nothing for output a (Operating._uncovered) */
static int op_uncovered(const double box[][2], int a);

/* Operator.refuse and Operating._uncovered: why setting i cannot take value (NULL: it can) */
static const char *op_refuse(const ctl_operator *o, int i, double value) {
  if (i < 0 || i >= CT_NOPS) return "is not an operator setting of the controller";
  if (i < OP_I_MANUAL) {
    if (!(value == 0.0 || value == 1.0))
      return i == 0 ? "expected auto or manual (1 or 0)" : "expected 1 (in) or 0 (out)";
    return 0;
  }
  const int k = i < OP_I_MIN ? i - OP_I_MANUAL : (i < OP_I_MAX ? i - OP_I_MIN : i - OP_I_MAX);
  if (i < OP_I_MIN && isnan(value)) return 0;
  if (!(isfinite(value) && op_box(k, 0) <= value && value <= op_box(k, 1)))
    return "outside the engineer's box";
  if (i >= OP_I_MIN) {
    const int side = i >= OP_I_MAX;
    const double low = side ? o->target[k][0] : value, high = side ? value : o->target[k][1];
    if (!(low < high)) return "the operator limits would leave nothing: low not below high";
    if (k >= NU) {
      double box[OP_NSIG][2];
      memcpy(box, o->target, sizeof box);
      box[k][side] = value;
      if (op_uncovered((const double(*)[2])box, k - NU))
        return "no admissible steady output is left inside the operator limits: the "
               "previous limits are kept";
    }
  }
  return 0;
}

/* Operator.set (op_refuse found nothing): a wider limit holds at once, a narrower one ramps */
static void op_set(ctl_operator *o, int i, double value) {
  if (i == 0) o->mode = value;
  else if (i < OP_I_MANUAL) o->service[i - OP_I_SERVICE] = value != 0.0;
  else if (i < OP_I_MIN) o->manual[i - OP_I_MANUAL] = value;
  else {
    const int side = i >= OP_I_MAX, k = side ? i - OP_I_MAX : i - OP_I_MIN;
    o->target[k][side] = value;
    const int wider = side ? value < o->active[k][1] : value > o->active[k][0];
    if (!wider) o->active[k][side] = value;
  }
}

/* Operator.writing: in auto and in service */
static int op_writing(const ctl_operator *o, int j) { return o->service[j] && o->mode == 1.0; }

/* the value an input not written is held at (Operator.held) */
static double op_held(const ctl_operator *o, int j) {
  const double base = o->has_last ? o->last[j] : o->start[j];
  return isfinite(o->manual[j]) && o->mode != 1.0 ? o->manual[j] : base;
}

/* _towards: the active limit moved towards a narrower target by at most step */
static void op_towards(ctl_operator *o, int k, double step_lo, double step_hi) {
  double *a = o->active[k];
  const double *t = o->target[k];
  a[0] = t[0] > a[0] ? fmin(t[0], a[0] + step_lo) : t[0];
  a[1] = t[1] < a[1] ? fmax(t[1], a[1] - step_hi) : t[1];
}

/* Operator.ramp with Operating.room: slack (NL rows' room, normalised) or NULL (none) */
static void op_ramp(ctl_operator *o, const double *slack) {
  for (int j = 0; j < NU; j++) op_towards(o, j, CT_MAX_MOVE[j], CT_MAX_MOVE[j]);
#if CT_OUT_LIMITS
  double room[NY][2];
  for (int a = 0; a < NY; a++) room[a][0] = room[a][1] = slack ? INFINITY : 0.0;
  if (slack && o->mode == 1.0)   /* Operating._room_phys */
    for (int r = 0; r < NL; r++) {
      int j = -1, nz = 0;
      for (int a = 0; a < NY; a++)
        if (CT_L[r * NY + a] != 0.0) j = a, nz++;
      if (nz != 1) continue;
      const double c = CT_L[r * NY + j];
      const int side = (c > 0.0) == (CT_Y_SCALE[j] > 0.0) ? 1 : 0;
      room[j][side] = fmin(room[j][side], slack[r] / fabs(c) * fabs(CT_Y_SCALE[j]));
    }
  for (int a = 0; a < NY; a++)
    op_towards(o, NU + a, fmin(CT_LIMIT_RATE[a], room[a][0]),
               fmin(CT_LIMIT_RATE[a], room[a][1]));
#else
  (void)slack;
#endif
}

/* row_narrowing of the active output limits into dh (NL; controllers/operator.py) */
static void op_narrowing(const double box[][2], double *dh) {
  for (int r = 0; r < NL; r++) {
    dh[r] = 0.0;
#if CT_OUT_LIMITS
    int j = -1, nz = 0;
    for (int a = 0; a < NY; a++)
      if (CT_L[r * NY + a] != 0.0) j = a, nz++;
    if (nz != 1) continue;
    const double c = CT_L[r * NY + j];
    const double v0 = (box[NU + j][0] - CT_Y_OFFSET[j]) / CT_Y_SCALE[j];
    const double v1 = (box[NU + j][1] - CT_Y_OFFSET[j]) / CT_Y_SCALE[j];
    const double lo = fmin(v0, v1), hi = fmax(v0, v1);
    const double bound = c * (c > 0.0 ? hi : lo);
    if (isfinite(bound)) dh[r] = fmax(0.0, CT_H[r] - bound);
#else
    (void)box;
#endif
  }
}

__attribute__((unused)) static void op_steady_box(const double box[][2], double *lo, double *hi);

static int op_uncovered(const double box[][2], int a) {
#if CT_OUT_LIMITS
  double lo[NY], hi[NY];
  op_steady_box(box, lo, hi);
  return !(lo[a] <= hi[a]);
#else
  (void)box; (void)a;
  return 0;
#endif
}

/* Operator.input_box: each input's range (the active limits; fixed: the held value) */
static void op_input_box(const ctl_operator *o, int fixed_by_service, double box[][2]) {
  for (int j = 0; j < NU; j++) {
    box[j][0] = o->active[j][0];
    box[j][1] = o->active[j][1];
    const int fixed = fixed_by_service ? !o->service[j] : !op_writing(o, j);
    if (fixed) {
      const double h = fmin(fmax(op_held(o, j), CT_U_LO[j]), CT_U_HI[j]);
      box[j][0] = box[j][1] = h;
    }
  }
}

/* Operator.terms: this step's ctl_ops (normalised) */
static void op_terms(ctl_operator *o) {
  double box[NU][2];
  ctl_ops *t = &o->ops;
  op_input_box(o, 1, box);
  for (int j = 0; j < NU; j++) {
    const double a = (box[j][0] - CT_U_OFFSET[j]) / CT_U_SCALE[j];
    const double b = (box[j][1] - CT_U_OFFSET[j]) / CT_U_SCALE[j];
    t->lo[j] = t->lo0[j] = fmin(a, b);
    t->hi[j] = t->hi0[j] = fmax(a, b);
    if (CT_MOVES && o->has_last && o->service[j]) {
      const double last = (o->last[j] - CT_U_OFFSET[j]) / CT_U_SCALE[j];
      const double step = CT_MAX_MOVE[j] / fabs(CT_U_SCALE[j]);
      t->lo0[j] = fmax(t->lo0[j], last - step);
      t->hi0[j] = fmin(t->hi0[j], last + step);
    }
  }
  op_narrowing((const double(*)[2])o->active, t->dh);
  t->active = 1;
}

/* Operating._steady_box: per output (lo, hi) (problem units) of Y_s narrowed by the operator's
 * output box (the targets) */
__attribute__((unused)) static void op_steady_box(const double box[][2], double *lo, double *hi) {
#if CT_OUT_LIMITS
  double dh[NL], lo_n[NY], hi_n[NY];
  op_narrowing(box, dh);
  for (int a = 0; a < NY; a++) lo_n[a] = -INFINITY, hi_n[a] = INFINITY;
  for (int r = 0; r < NL; r++) {
    int j = -1, nz = 0;
    for (int a = 0; a < NY; a++)
      if (CT_L[r * NY + a] != 0.0) j = a, nz++;
    if (nz != 1) continue;
    const double c = CT_L[r * NY + j], v = (CT_YS_BASE[r] - dh[r]) / c;
    if (c > 0.0) hi_n[j] = fmin(hi_n[j], v);
    else lo_n[j] = fmax(lo_n[j], v);
  }
  for (int a = 0; a < NY; a++) {
    const double p = (lo_n[a] + BO[a]) * CT_Y_SCALE[a] + CT_Y_OFFSET[a];
    const double q = (hi_n[a] + BO[a]) * CT_Y_SCALE[a] + CT_Y_OFFSET[a];
    lo[a] = CT_Y_SCALE[a] > 0.0 ? p : q;   /* lo > hi: empty */
    hi[a] = CT_Y_SCALE[a] > 0.0 ? q : p;
  }
#else
  (void)box; (void)lo; (void)hi;
#endif
}

/* Operator.setpoint and Operating._admissible: the set-points (problem units) inside the
 * operator's output limits (targets), and, for an output whose limits are narrowed, inside
 * the admissible steady outputs under them */
static void op_setpoint(const ctl_operator *o, double *r_phys) {
#if CT_OUT_LIMITS
  int narrowed = 0;
  for (int a = 0; a < NY; a++) {
    r_phys[a] = fmin(fmax(r_phys[a], o->target[NU + a][0]), o->target[NU + a][1]);
    narrowed |= o->target[NU + a][0] != CT_Y_LO[a] || o->target[NU + a][1] != CT_Y_HI[a];
  }
  if (!narrowed) return;
  double lo[NY], hi[NY];
  op_steady_box((const double(*)[2])o->target, lo, hi);
  for (int a = 0; a < NY; a++)
    if (o->target[NU + a][0] != CT_Y_LO[a] || o->target[NU + a][1] != CT_Y_HI[a])
      r_phys[a] = fmin(fmax(r_phys[a], lo[a]), hi[a]);
#else
  (void)o; (void)r_phys;
#endif
}

/* Operator.applied: the inputs the plant gets (problem units) for the computed ones */
static void op_applied(ctl_operator *o, const double *computed, double *u) {
  double box[NU][2];
  op_input_box(o, 0, box);
  for (int j = 0; j < NU; j++) {
    double v = op_writing(o, j) ? computed[j] : box[j][0];
    v = fmin(fmax(v, box[j][0]), box[j][1]);
    if (CT_MOVES && o->has_last && op_writing(o, j))
      v = fmin(fmax(v, o->last[j] - CT_MAX_MOVE[j]), o->last[j] + CT_MAX_MOVE[j]);
    u[j] = v;
  }
  memcpy(o->last, u, sizeof o->last);
  o->has_last = 1;
}
