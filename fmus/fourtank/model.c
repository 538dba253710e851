/*
 * Four-tank plant (quadruple-tank process): equations, parameters and the Co-Simulation
 * integrator.
 *
 * Equations: section V ("Numerical example") of Schimperna & Magni, "Robust constrained
 * nonlinear MPC with a GRU model", with an extra inflow qd_i into each tank:
 *
 *   dh1/dt = (-a1 sqrt(2 g h1) + a3 sqrt(2 g h3) + gamma_a qa       + qd1) / S
 *   dh2/dt = (-a2 sqrt(2 g h2) + a4 sqrt(2 g h4) + gamma_b qb       + qd2) / S
 *   dh3/dt = (-a3 sqrt(2 g h3)                   + (1 - gamma_b) qb + qd3) / S
 *   dh4/dt = (-a4 sqrt(2 g h4)                   + (1 - gamma_a) qa + qd4) / S
 *
 * Parameters (Alvarado et al. 2011): S = 0.06 m2, a1 = 1.31e-4, a2 = 1.51e-4,
 * a3 = 9.27e-5, a4 = 8.82e-5 m2, gamma_a = 0.3, gamma_b = 0.4, g = 9.81 m/s2.
 *
 * Levels never go negative. A level is the height of water above the outlet, so an empty
 * tank has no outflow: the outflow uses max(h, 0). And an empty tank cannot lose more water:
 * at h <= 0 a negative net derivative (a leak qd_i < 0 larger than the inflow) is cut to 0.
 * Torricelli's law sqrt(h) is not Lipschitz at h = 0; the solution of a draining tank,
 * h(t) = (sqrt(h0) - c t)^2, is C1 when it reaches 0 and stays there, so an error-controlled
 * integrator takes it in its stride (the step size shrinks around the kink) and the projection
 * h <- max(h, 0) after each accepted substep removes the round-off undershoot. In Model
 * Exchange the importer's solver owns the states; model_set_states projects what it hands
 * in onto h >= 0 (the right-hand side already treats h < 0 as an empty tank).
 */
#include "model.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

/* Gravity: a constant of the model (causality="local" variability="constant"). */
static const double G = 9.81;

/* Integrator settings for doStep (Dormand-Prince 5(4), see model_do_step). */
static const double RTOL = 1e-11;          /* relative tolerance per substep */
static const double ATOL = 1e-13;          /* absolute tolerance per substep [m] */
static const unsigned long MAX_SUBSTEPS = 1000000UL; /* per doStep, guards against stalls */

/* Default operating point: h1 = h2 = 0.65 m is an equilibrium for these pump flows
 * (close to Alvarado's qa = 1.63 m3/h, qb = 2.0 m3/h); h3, h4 follow from it. */
static const double QA_EQ = 4.5472443083696316e-4;  /* [m3/s] */
static const double QB_EQ = 5.5233543431505480e-4;  /* [m3/s] */
static const double H_EQ[N_STATES] = {0.65, 0.65, 0.6514031296511584, 0.6638294000727866};

static const char *const NAMES[N_VARIABLES] = {
    "time", "h1", "h2", "h3", "h4", "der(h1)", "der(h2)", "der(h3)", "der(h4)",
    "qa", "qb", "qd1", "qd2", "qd3", "qd4", "S", "a1", "a2", "a3", "a4",
    "gamma_a", "gamma_b", "g", "h1_start", "h2_start", "h3_start", "h4_start",
};

void model_set_defaults(ModelData *m) {
    memset(m, 0, sizeof(*m));
    m->qa = QA_EQ;
    m->qb = QB_EQ;
    m->S = 0.06;
    m->a[0] = 1.31e-4;
    m->a[1] = 1.51e-4;
    m->a[2] = 9.27e-5;
    m->a[3] = 8.82e-5;
    m->gamma_a = 0.3;
    m->gamma_b = 0.4;
    for (int i = 0; i < N_STATES; i++) {
        m->h_start[i] = H_EQ[i];
        m->h[i] = H_EQ[i];
    }
}

void model_initialize(ModelData *m) {
    for (int i = 0; i < N_STATES; i++) m->h[i] = m->h_start[i];
    m->last_substep = 0.0;
}

const char *model_variable_name(unsigned vr) {
    return vr < N_VARIABLES ? NAMES[vr] : NULL;
}

VariableKind model_variable_kind(unsigned vr) {
    if (vr == VR_TIME) return KIND_INDEPENDENT;
    if (vr <= VR_H4) return KIND_STATE;
    if (vr <= VR_DER_H4) return KIND_DERIVATIVE;
    if (vr <= VR_QD4) return KIND_INPUT;
    if (vr <= VR_GAMMA_B) return KIND_TUNABLE;
    if (vr == VR_G) return KIND_CONSTANT;
    return KIND_FIXED;
}

/* Four-tank right-hand side (section V), with the empty-tank rules described above. */
void model_derivatives(const ModelData *m, const double h[N_STATES], double dh[N_STATES]) {
    double out[N_STATES];  /* outflow through the bottom hole of each tank [m3/s] */
    for (int i = 0; i < N_STATES; i++) {
        const double level = h[i] > 0.0 ? h[i] : 0.0;
        out[i] = m->a[i] * sqrt(2.0 * G * level);
    }
    const double in[N_STATES] = {
        out[2] + m->gamma_a * m->qa + m->qd[0],
        out[3] + m->gamma_b * m->qb + m->qd[1],
        (1.0 - m->gamma_b) * m->qb + m->qd[2],
        (1.0 - m->gamma_a) * m->qa + m->qd[3],
    };
    for (int i = 0; i < N_STATES; i++) {
        dh[i] = (in[i] - out[i]) / m->S;
        if (h[i] <= 0.0 && dh[i] < 0.0) dh[i] = 0.0;  /* an empty tank stays empty */
    }
}

double model_get(const ModelData *m, unsigned vr) {
    switch (model_variable_kind(vr)) {
    case KIND_INDEPENDENT: return m->time;
    case KIND_STATE: return m->h[vr - VR_H1];
    case KIND_DERIVATIVE: {
        double dh[N_STATES];
        model_derivatives(m, m->h, dh);
        return dh[vr - VR_DER_H1];
    }
    case KIND_CONSTANT: return G;
    case KIND_FIXED: return m->h_start[vr - VR_H1_START];
    case KIND_INPUT:
        if (vr == VR_QA) return m->qa;
        if (vr == VR_QB) return m->qb;
        return m->qd[vr - VR_QD1];
    case KIND_TUNABLE:
        if (vr == VR_S) return m->S;
        if (vr == VR_GAMMA_A) return m->gamma_a;
        if (vr == VR_GAMMA_B) return m->gamma_b;
        return m->a[vr - VR_A1];
    }
    return NAN;
}

const char *model_set(ModelData *m, unsigned vr, double value, bool initialized) {
    switch (model_variable_kind(vr)) {
    case KIND_INDEPENDENT:
        return "is the independent variable and cannot be set";
    case KIND_STATE:
        return "is an output (a continuous state, set only through SetContinuousStates)";
    case KIND_DERIVATIVE:
        return "is a state derivative and cannot be set";
    case KIND_CONSTANT:
        return "is a constant and cannot be set";
    default:
        break;
    }
    if (!isfinite(value)) return "must be finite (got NaN or infinity)";
    switch (vr) {
    case VR_QA: m->qa = value; return NULL;
    case VR_QB: m->qb = value; return NULL;
    case VR_QD1: case VR_QD2: case VR_QD3: case VR_QD4:
        m->qd[vr - VR_QD1] = value;
        return NULL;
    case VR_S:
        if (value <= 0.0) return "must be > 0 m2";
        m->S = value;
        return NULL;
    case VR_A1: case VR_A2: case VR_A3: case VR_A4:
        if (value < 0.0) return "must be >= 0 m2";
        m->a[vr - VR_A1] = value;
        return NULL;
    case VR_GAMMA_A: case VR_GAMMA_B:
        if (value < 0.0 || value > 1.0) return "must lie in [0, 1]";
        if (vr == VR_GAMMA_A) m->gamma_a = value; else m->gamma_b = value;
        return NULL;
    default: /* KIND_FIXED: start levels */
        if (initialized)
            return "is a fixed parameter: it can be set only before initialisation ends";
        if (value < 0.0) return "must be >= 0 m (levels are never negative)";
        m->h_start[vr - VR_H1_START] = value;
        m->h[vr - VR_H1_START] = value;  /* h_i is calculated from h_i_start */
        return NULL;
    }
}

void model_set_states(ModelData *m, const double x[N_STATES]) {
    for (int i = 0; i < N_STATES; i++) m->h[i] = x[i] > 0.0 ? x[i] : 0.0;
}

void model_get_states(const ModelData *m, double x[N_STATES]) {
    for (int i = 0; i < N_STATES; i++) x[i] = m->h[i];
}

void model_get_derivatives(const ModelData *m, double dx[N_STATES]) {
    model_derivatives(m, m->h, dx);
}

const char *model_state_name(size_t i) {
    return i < N_STATES ? NAMES[VR_H1 + i] : "(no such state)";
}

/* Butcher tableau of the Dormand-Prince 5(4) pair (Dormand & Prince 1980). The nodes
 * c = (0, 1/5, 3/10, 4/5, 8/9, 1, 1) are not needed: the plant is autonomous (inputs are
 * held constant over a communication step). */
static const double A21 = 1.0 / 5;
static const double A31 = 3.0 / 40, A32 = 9.0 / 40;
static const double A41 = 44.0 / 45, A42 = -56.0 / 15, A43 = 32.0 / 9;
static const double A51 = 19372.0 / 6561, A52 = -25360.0 / 2187, A53 = 64448.0 / 6561,
                    A54 = -212.0 / 729;
static const double A61 = 9017.0 / 3168, A62 = -355.0 / 33, A63 = 46732.0 / 5247,
                    A64 = 49.0 / 176, A65 = -5103.0 / 18656;
/* 5th-order weights (also the last stage: first same as last). */
static const double B1 = 35.0 / 384, B3 = 500.0 / 1113, B4 = 125.0 / 192,
                    B5 = -2187.0 / 6784, B6 = 11.0 / 84;
/* Error weights: 5th-order minus embedded 4th-order solution. */
static const double E1 = 71.0 / 57600, E3 = -71.0 / 16695, E4 = 71.0 / 1920,
                    E5 = -17253.0 / 339200, E6 = 22.0 / 525, E7 = -1.0 / 40;

/* Initial substep guess: the time for the fastest level to move by ~1e-3 of its scale. */
static double initial_substep(const double y[N_STATES], const double f[N_STATES]) {
    double rate = 0.0;
    for (int i = 0; i < N_STATES; i++) {
        const double r = fabs(f[i]) / (ATOL + RTOL * fabs(y[i]) + 1e-3 * (fabs(y[i]) + 0.1));
        if (r > rate) rate = r;
    }
    return rate > 0.0 ? 1.0 / rate : 1.0;
}

const char *model_do_step(ModelData *m, double step, char *msg, size_t n) {
    double y[N_STATES], k1[N_STATES], k2[N_STATES], k3[N_STATES], k4[N_STATES];
    double k5[N_STATES], k6[N_STATES], k7[N_STATES], yt[N_STATES], y5[N_STATES];
    const double t_end = m->time + step;
    double t = m->time;
    memcpy(y, m->h, sizeof(y));
    model_derivatives(m, y, k1);
    double hs = m->last_substep > 0.0 ? m->last_substep : initial_substep(y, k1);
    unsigned long count = 0;

    while (t < t_end) {
        if (++count > MAX_SUBSTEPS) {
            snprintf(msg, n, "integrator stalled at t = %.17g s (over %lu substeps)", t,
                     MAX_SUBSTEPS);
            return msg;
        }
        const double remaining = t_end - t;
        const bool last = hs >= remaining * (1.0 - 1e-12);
        const double hh = last ? remaining : hs;
        int i;
        for (i = 0; i < N_STATES; i++) yt[i] = y[i] + hh * A21 * k1[i];
        model_derivatives(m, yt, k2);
        for (i = 0; i < N_STATES; i++) yt[i] = y[i] + hh * (A31 * k1[i] + A32 * k2[i]);
        model_derivatives(m, yt, k3);
        for (i = 0; i < N_STATES; i++)
            yt[i] = y[i] + hh * (A41 * k1[i] + A42 * k2[i] + A43 * k3[i]);
        model_derivatives(m, yt, k4);
        for (i = 0; i < N_STATES; i++)
            yt[i] = y[i] + hh * (A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i]);
        model_derivatives(m, yt, k5);
        for (i = 0; i < N_STATES; i++)
            yt[i] = y[i] + hh * (A61 * k1[i] + A62 * k2[i] + A63 * k3[i] + A64 * k4[i] +
                                 A65 * k5[i]);
        model_derivatives(m, yt, k6);
        for (i = 0; i < N_STATES; i++)
            y5[i] = y[i] + hh * (B1 * k1[i] + B3 * k3[i] + B4 * k4[i] + B5 * k5[i] +
                                 B6 * k6[i]);
        model_derivatives(m, y5, k7);
        m->n_rhs += 6;

        /* Scaled RMS error estimate. */
        double err = 0.0;
        for (i = 0; i < N_STATES; i++) {
            const double e = hh * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] +
                                   E6 * k6[i] + E7 * k7[i]);
            const double scale = ATOL + RTOL * fmax(fabs(y[i]), fabs(y5[i]));
            err += (e / scale) * (e / scale);
        }
        err = sqrt(err / N_STATES);
        if (!isfinite(err)) {
            snprintf(msg, n, "non-finite levels at t = %.17g s (check parameters and inputs)",
                     t);
            return msg;
        }

        /* Step-size controller (safety 0.9, growth limited to [0.2, 5]). */
        double factor = err > 0.0 ? 0.9 * pow(err, -0.2) : 5.0;
        factor = fmin(5.0, fmax(0.2, factor));
        if (err <= 1.0) {
            t = last ? t_end : t + hh;
            for (i = 0; i < N_STATES; i++) y[i] = y5[i] > 0.0 ? y5[i] : 0.0;
            /* First same as last: k7 is f(y5); re-evaluate only if the projection moved y. */
            bool projected = false;
            for (i = 0; i < N_STATES; i++) projected |= (y[i] != y5[i]);
            if (projected) {
                model_derivatives(m, y, k1);
                m->n_rhs += 1;
            } else {
                memcpy(k1, k7, sizeof(k1));
            }
            /* Keep the controller's proposal, not the truncated last substep. */
            if (!last || hh >= hs) hs = hh * factor;
        } else {
            hs = hh * fmax(0.2, factor);
            if (hs < 1e-14 * (fabs(t) + 1.0)) {
                snprintf(msg, n, "integrator step size underflow at t = %.17g s", t);
                return msg;
            }
        }
    }
    memcpy(m->h, y, sizeof(y));
    m->time = t_end;
    m->last_substep = hs;
    return NULL;
}
