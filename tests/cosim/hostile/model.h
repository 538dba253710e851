/*
 * A hostile FMU for the fault tests (tests/cosim/hostile/__init__.py builds it): native code
 * that behaves until the time `fault_time` and then does what the parameter `fault` says:
 * hangs, crashes, aborts, exits, floods its output or kills its process group.
 *
 * One model, two roles, chosen at compile time on the shared FMI glue (fmus/glue/):
 *
 *   HOSTILE_CONTROLLER  the exported four-tank controller's interface: inputs h1, h2, ref.h1,
 *                       ref.h2; outputs qa, qb, status, fallback, iterations; an integral law
 *                       h1 <- qb, h2 <- qa (the four-tank's cross pairing), sample time 25 s.
 *   otherwise           a plant with the four-tank's signals: inputs qa, qb, outputs h1, h2,
 *                       two first-order tanks (h1 <- qb, h2 <- qa).
 */
#ifndef HOSTILE_MODEL_H
#define HOSTILE_MODEL_H

#include <stdbool.h>
#include <stddef.h>

#define INSTANTIATION_TOKEN "{6b1f9a52-3c0e-4d7a-8f21-5e9d0c4b7a13}"
#define N_STATES 0
#define N_EVENT_INDICATORS 0
#define MODEL_HAS_WARNINGS 1

/* what the FMU does from fault_time on (its parameter `fault`) */
enum { FAULT_NONE, FAULT_HANG, FAULT_SEGFAULT, FAULT_ABORT, FAULT_EXIT, FAULT_FLOOD,
       FAULT_SIGNAL };

#ifdef HOSTILE_CONTROLLER
enum { VR_TIME, VR_H1, VR_H2, VR_REF1, VR_REF2, VR_QA, VR_QB, VR_STATUS, VR_FALLBACK,
       VR_ITERATIONS, VR_FAULT, VR_FAULT_TIME, N_VARIABLES };
#else
enum { VR_TIME, VR_H1, VR_H2, VR_QA, VR_QB, VR_FAULT, VR_FAULT_TIME, N_VARIABLES };
#endif

typedef struct {
    double time;
    double h[2];        /* levels [m] (the plant's state, the controller's measurements) */
    double ref[2];      /* set-points [m] (controller) */
    double q[2];        /* pump flows qa, qb [m3/s] */
    double fault;       /* what to do from fault_time on (FAULT_*) */
    double fault_time;  /* [s] */
    int flooding;       /* warnings still to log after a flooding step */
} ModelData;

void model_set_defaults(ModelData *m);
void model_initialize(ModelData *m);
const char *model_variable_name(unsigned vr);
double model_get(const ModelData *m, unsigned vr);
const char *model_set(ModelData *m, unsigned vr, double value, bool initialized);
const char *model_state_name(size_t i);
void model_get_states(const ModelData *m, double *x);
void model_set_states(ModelData *m, const double *x);
void model_get_derivatives(const ModelData *m, double *dx);
const char *model_do_step(ModelData *m, double step, char *msg, size_t n);
const char *model_warning(ModelData *m, char *msg, size_t n);

#endif /* HOSTILE_MODEL_H */
