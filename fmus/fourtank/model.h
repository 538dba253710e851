/*
 * Four-tank plant (quadruple-tank process) -- model interface.
 *
 * The equations are those of section V of Schimperna & Magni, "Robust constrained nonlinear
 * MPC with a GRU model" (parameters from Alvarado et al. 2011); see model.c.
 *
 * This header is the model's side of the contract with the FMI glue every C plant model
 * shares (fmus/glue/instance.h: the FMI-version-independent layer, under the thin FMI 2.0
 * and 3.0 adapters fmi2.c and fmi3.c): the model knows nothing about FMI, the glue knows
 * nothing about the equations.
 */
#ifndef FOURTANK_MODEL_H
#define FOURTANK_MODEL_H

#include <stdbool.h>
#include <stddef.h>

#define MODEL_IDENTIFIER "FourTank"
/* Must match instantiationToken (FMI 3) / guid (FMI 2) in the model descriptions. */
#define INSTANTIATION_TOKEN "{5f0c2a8e-4d1b-4b7e-9a63-2e4f1c0d7a91}"

#define N_STATES 4
#define N_EVENT_INDICATORS 0

/* Value references: identical in modelDescription2.xml and modelDescription3.xml. */
typedef enum {
    VR_TIME = 0,  /* independent variable [s] (declared in the FMI 3 description only) */
    VR_H1 = 1, VR_H2 = 2, VR_H3 = 3, VR_H4 = 4,      /* outputs = continuous states [m] */
    VR_DER_H1 = 5, VR_DER_H2 = 6, VR_DER_H3 = 7, VR_DER_H4 = 8, /* derivatives [m/s] */
    VR_QA = 9, VR_QB = 10,                           /* pump flows (inputs) [m3/s] */
    VR_QD1 = 11, VR_QD2 = 12, VR_QD3 = 13, VR_QD4 = 14, /* extra inflows (inputs) [m3/s] */
    VR_S = 15,                                       /* tank cross-section (tunable) [m2] */
    VR_A1 = 16, VR_A2 = 17, VR_A3 = 18, VR_A4 = 19,  /* outlet areas (tunable) [m2] */
    VR_GAMMA_A = 20, VR_GAMMA_B = 21,                /* valve splits (tunable) [1] */
    VR_G = 22,                                       /* gravity (constant) [m/s2] */
    VR_H1_START = 23, VR_H2_START = 24, VR_H3_START = 25, VR_H4_START = 26, /* fixed [m] */
    N_VARIABLES = 27
} ValueReference;

/* How a variable may be accessed (mirrors causality/variability in the descriptions). */
typedef enum {
    KIND_INDEPENDENT,   /* time: read-only */
    KIND_STATE,         /* h1..h4: outputs; changed only through the (ME) state vector */
    KIND_DERIVATIVE,    /* der(h1)..der(h4): read-only */
    KIND_INPUT,         /* qa, qb, qd1..qd4: settable at any time */
    KIND_TUNABLE,       /* S, a1..a4, gamma_a, gamma_b: settable at any time */
    KIND_CONSTANT,      /* g: never settable */
    KIND_FIXED          /* h1_start..h4_start: settable only before initialisation ends */
} VariableKind;

/* The whole model: everything the glue stores per instance apart from FMI bookkeeping. */
typedef struct {
    double time;            /* [s] */
    double h[N_STATES];     /* levels [m], never negative */
    double qa, qb;          /* pump flows [m3/s] */
    double qd[N_STATES];    /* extra inflow into each tank [m3/s], negative = leak */
    double S;               /* cross-section of every tank [m2] */
    double a[N_STATES];     /* outlet hole areas [m2] */
    double gamma_a, gamma_b;/* valve split ratios [1] */
    double h_start[N_STATES]; /* start levels [m] */
    double last_substep;    /* integrator's last accepted substep [s] (0 = none yet) */
    unsigned long n_rhs;    /* right-hand side evaluations so far (statistics) */
} ModelData;

/* Set every variable to its start value from the model descriptions. */
void model_set_defaults(ModelData *m);

/* End of initialisation: the levels take their start values. */
void model_initialize(ModelData *m);

/* Name of a variable, or NULL for an unknown value reference. */
const char *model_variable_name(unsigned vr);

/* Kind of a known variable (vr < N_VARIABLES). */
VariableKind model_variable_kind(unsigned vr);

/* Read a variable (vr < N_VARIABLES). Derivatives are evaluated at the current state. */
double model_get(const ModelData *m, unsigned vr);

/*
 * Write a variable. `initialized` is true once initialisation has ended.
 * Returns NULL on success, otherwise a static message explaining the refusal (the value is
 * then left unchanged).
 */
const char *model_set(ModelData *m, unsigned vr, double value, bool initialized);

/* Right-hand side dh/dt of eq. (four-tank, section V) at levels h; writes dh[N_STATES]. */
void model_derivatives(const ModelData *m, const double h[N_STATES], double dh[N_STATES]);

/* Clamp a state vector to the physical domain (levels >= 0) and store it. */
void model_set_states(ModelData *m, const double x[N_STATES]);

/* The levels, and their derivatives at the current state (Model Exchange). */
void model_get_states(const ModelData *m, double x[N_STATES]);
void model_get_derivatives(const ModelData *m, double dx[N_STATES]);

/* Name of continuous state i ("h1" .. "h4"), for the glue's messages. */
const char *model_state_name(size_t i);

/*
 * Advance the levels from m->time to m->time + step with the embedded Dormand-Prince 5(4)
 * method under tight error control (the Co-Simulation doStep). Returns NULL on success, or a
 * message written into msg (of size n) on failure, in which case the state is unchanged.
 */
const char *model_do_step(ModelData *m, double step, char *msg, size_t n);

#endif /* FOURTANK_MODEL_H */
