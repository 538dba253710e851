/*
 * The robust MPC as a co-simulation model: the controller FMU's side of the FMI glue
 * (fmus/glue/instance.h) every C model shares.
 *
 * One source for every exported controller: what differs between them is in two generated
 * files beside this one (cosim/core/controller_fmu.py) and one data file. controller_step.c
 * is the whole controller step in C (controllers/kernel/controller.c on the compiled FHOCP
 * kernel) for given dimensions; controller_names.h holds the instantiation
 * token, the numbers of signals, their names, the start values and the sample time. The
 * numbers -- the model's weights, the problem's weights and boxes, the certificate's
 * tightening, the observer's gains -- are data: resources/controller.dat (CTL_DATA_FILE),
 * read at instantiation, so that one binary serves every design of its dimensions and
 * signals. The controller's state lives in its instance (ctl_state, allocated at
 * instantiation), so that instances in one process are independent.
 *
 * Value references: 0 time; then the measured outputs (inputs of the FMU, named as the
 * plant's outputs), their set-points ref.<output>, the measured disturbances dist.<name>
 * (CTL_ND of them, none for most designs), the operator's settings (CTL_NOP inputs, op.mode,
 * op.service.<input>, op.manual.<input>, op.min.<signal>, op.max.<signal>: controllers/
 * kernel/operator.c), the inputs to apply (outputs of the FMU, named as the plant's inputs),
 * status, fallback, iterations, the predicted outputs pred.<output>, the steady outputs
 * target.<output>, what the law computed computed.<input> (in manual: in shadow), the
 * number of operator settings refused op.refused, and the tunable parameters (the law
 * file's LAW_P_*: offset_filter, the diagonal of R, du_weight, offset_weight by signal, as
 * the law has them). An operator setting the controller refuses is kept as it was (the
 * FMI call succeeds; op.refused counts it, the next step logs why).
 */
#ifndef CONTROLLER_MODEL_H
#define CONTROLLER_MODEL_H

#include <stdbool.h>
#include <stddef.h>

#include "controller_names.h"

#define N_STATES 0
#define N_EVENT_INDICATORS 0
#define MODEL_HAS_RESOURCES 1
#define MODEL_NO_FMU_STATE 1
#define MODEL_HAS_WARNINGS 1

/* the controller's numbers, in the FMU's resources folder (controllers/kernel/constants.py) */
#define CTL_DATA_FILE "controller.dat"

/* the most controller steps one doStep runs: a communication step of more sample times is
 * refused (one call stays bounded in time; a master steps at one sample time) */
#define CTL_MAX_STEPS_PER_CALL 1000

#define VR_TIME 0
#define VR_Y 1                              /* CTL_NY measured outputs */
#define VR_REF (VR_Y + CTL_NY)              /* CTL_NY set-points */
#define VR_D (VR_REF + CTL_NY)              /* CTL_ND measured disturbances */
#define VR_OP (VR_D + CTL_ND)               /* CTL_NOP operator settings */
#define VR_U (VR_OP + CTL_NOP)              /* CTL_NU inputs to apply */
#define VR_STATUS (VR_U + CTL_NU)
#define VR_FALLBACK (VR_STATUS + 1)
#define VR_ITERATIONS (VR_FALLBACK + 1)
#define VR_PRED (VR_ITERATIONS + 1)         /* CTL_NY predicted outputs */
#define VR_TARGET (VR_PRED + CTL_NY)        /* CTL_NY steady outputs the FHOCP steers to */
#define VR_COMPUTED (VR_TARGET + CTL_NY)    /* CTL_NU inputs the law computed */
#define VR_REFUSED (VR_COMPUTED + CTL_NU)   /* operator settings refused so far */
#define VR_PARAM (VR_REFUSED + 1)           /* CTL_NPARAM tunable parameters */
#define N_VARIABLES (VR_PARAM + CTL_NPARAM)

/* the controller step (controller_step.c: controllers/kernel/controller.c, loader.c) */
typedef struct ctl_state ctl_state;
const char *mpc_load_data(const unsigned char *bytes, size_t size, char *msg, size_t n);
ctl_state *mpc_ctl_new(void);
void mpc_ctl_free(ctl_state *st);
void mpc_ctl_reset(ctl_state *st);
int mpc_ctl_step(ctl_state *st, const double *y_phys, const double *r_phys,
                 const double *d_phys);
int mpc_ctl_take_warnings(ctl_state *st);
double mpc_ctl_get_parameter(const ctl_state *st, int i);
const char *mpc_ctl_set_parameter(ctl_state *st, int i, double value);
const char *mpc_ctl_set_operator(ctl_state *st, int i, double value);
double mpc_ctl_get_operator(const ctl_state *st, int i);
void mpc_ctl_computed(const ctl_state *st, double *u_phys);
void mpc_ctl_outputs(const ctl_state *st, double *u_phys, int *status, int *fallback,
                    int *iterations, double *y_pred, double *y_target);

typedef struct {
    double time;              /* [s] */
    double y[CTL_NY];         /* the measured outputs (the problem's units) */
    double ref[CTL_NY];       /* their set-points */
    double d[CTL_ND > 0 ? CTL_ND : 1];   /* the measured disturbances */
    ctl_state *ctl;           /* the controller (model_acquire) */
    int warnings;             /* raised by the last step, not yet logged (model_warning) */
    int refused;              /* operator settings refused so far */
    const char *refusal;      /* why the last one was, not yet logged (model_warning) */
} ModelData;

void model_set_defaults(ModelData *m);
void model_initialize(ModelData *m);
const char *model_acquire(ModelData *m, const char *resources, char *msg, size_t n);
void model_release(ModelData *m);
const char *model_variable_name(unsigned vr);
double model_get(const ModelData *m, unsigned vr);
const char *model_set(ModelData *m, unsigned vr, double value, bool initialized);
const char *model_state_name(size_t i);
void model_get_states(const ModelData *m, double *x);
void model_set_states(ModelData *m, const double *x);
void model_get_derivatives(const ModelData *m, double *dx);
const char *model_do_step(ModelData *m, double step, char *msg, size_t n);
const char *model_warning(ModelData *m, char *msg, size_t n);

#endif /* CONTROLLER_MODEL_H */
