/*
 * The robust MPC as a co-simulation model (see model.h): the FMI variables of the controller
 * step. A communication step of k sample times runs k controller steps with the inputs held
 * (k = 1 in a master that steps at the controller's sample time); a step that is not a
 * multiple of the sample time, or of more than CTL_MAX_STEPS_PER_CALL samples, is refused. A non-finite measurement or set-point holds the
 * last inputs and is logged as a warning, as is a set-point the paper's law refuses (one
 * message per step, the most serious). A tunable parameter set between steps holds from the
 * next step on.
 */
#include "model.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* warning bits of the controller step (controllers/kernel/controller.h CTL_WARN_*) */
#define WARN_NONFINITE_INPUT 1
#define WARN_UNREACHABLE_START 2
#define WARN_SETPOINT_REJECTED 4
#define WARN_NO_ADMISSIBLE_SETPOINT 8

void model_set_defaults(ModelData *m) {
    m->time = 0.0;
    m->warnings = 0;
    m->refused = 0;
    m->refusal = NULL;
    for (int a = 0; a < CTL_NY; a++) {
        m->y[a] = CTL_Y_START[a];
        m->ref[a] = CTL_Y_START[a];
    }
    for (int j = 0; j < CTL_ND; j++) m->d[j] = CTL_D_START[j];
    if (m->ctl) mpc_ctl_reset(m->ctl);
}

void model_initialize(ModelData *m) { (void)m; }

/* Read resources/CTL_DATA_FILE and hand it to the controller step (mpc_load_data): NULL, or
 * the reason in msg. */
static const char *load_data(const char *resources, char *msg, size_t n) {
    char path[4096];
    if (!resources) return "no resource location given (the controller's numbers are in "
                           "resources/" CTL_DATA_FILE ")";
    const size_t len = strlen(resources);
    const bool slash = len > 0 && (resources[len - 1] == '/' || resources[len - 1] == '\\');
    if ((size_t)snprintf(path, sizeof path, "%s%s%s", resources, slash ? "" : "/",
                         CTL_DATA_FILE) >= sizeof path)
        return "the resources folder's path is too long";
    FILE *f = fopen(path, "rb");
    if (!f) {
        snprintf(msg, n, "cannot open %s", path);
        return msg;
    }
    unsigned char *bytes = NULL;
    long size = -1;
    if (fseek(f, 0, SEEK_END) == 0 && (size = ftell(f)) >= 0 && fseek(f, 0, SEEK_SET) == 0 &&
        (bytes = (unsigned char *)malloc(size > 0 ? (size_t)size : 1)) != NULL &&
        fread(bytes, 1, (size_t)size, f) != (size_t)size)
        size = -1;
    fclose(f);
    const char *why = NULL;
    if (!bytes || size < 0) {
        snprintf(msg, n, "cannot read %s", path);
        why = msg;
    } else {
        char reason[400];
        if (mpc_load_data(bytes, (size_t)size, reason, sizeof reason)) {
            snprintf(msg, n, "%s: %s", path, reason);
            why = msg;
        }
    }
    free(bytes);
    return why;
}

const char *model_acquire(ModelData *m, const char *resources, char *msg, size_t n) {
    const char *why = load_data(resources, msg, n);
    if (why) return why;
    m->ctl = mpc_ctl_new();
    return m->ctl ? NULL : "out of memory";
}

void model_release(ModelData *m) {
    mpc_ctl_free(m->ctl);
    m->ctl = NULL;
}

const char *model_variable_name(unsigned vr) {
    return vr < N_VARIABLES ? CTL_NAMES[vr] : NULL;
}

double model_get(const ModelData *m, unsigned vr) {
    double u[CTL_NU], pred[CTL_NY], target[CTL_NY];
    int status, fallback, iterations;
    if (vr == VR_TIME) return m->time;
    if (vr >= VR_PARAM) return mpc_ctl_get_parameter(m->ctl, (int)(vr - VR_PARAM));
    if (vr < VR_REF) return m->y[vr - VR_Y];
    if (vr < VR_D) return m->ref[vr - VR_REF];
    if (vr < VR_OP) return m->d[vr - VR_D];
    if (vr < VR_U) return mpc_ctl_get_operator(m->ctl, (int)(vr - VR_OP));
    if (vr == VR_REFUSED) return m->refused;
    if (vr >= VR_COMPUTED && vr < VR_REFUSED) {
        mpc_ctl_computed(m->ctl, u);
        return u[vr - VR_COMPUTED];
    }
    mpc_ctl_outputs(m->ctl, u, &status, &fallback, &iterations, pred, target);
    if (vr < VR_STATUS) return u[vr - VR_U];
    if (vr == VR_STATUS) return status;
    if (vr == VR_FALLBACK) return fallback;
    if (vr == VR_ITERATIONS) return iterations;
    if (vr < VR_TARGET) return pred[vr - VR_PRED];
    return target[vr - VR_TARGET];
}

const char *model_set(ModelData *m, unsigned vr, double value, bool initialized) {
    (void)initialized;
    if (vr >= VR_Y && vr < VR_REF) {
        m->y[vr - VR_Y] = value;
        return NULL;
    }
    if (vr >= VR_REF && vr < VR_D) {
        m->ref[vr - VR_REF] = value;
        return NULL;
    }
    if (vr >= VR_D && vr < VR_OP) {
        m->d[vr - VR_D] = value;
        return NULL;
    }
    if (vr >= VR_OP && vr < VR_U) {   /* refused: kept as it was, counted, logged */
        const char *why = mpc_ctl_set_operator(m->ctl, (int)(vr - VR_OP), value);
        if (why) {
            m->refused++;
            m->refusal = why;
        }
        return NULL;
    }
    if (vr >= VR_PARAM && vr < N_VARIABLES)
        return mpc_ctl_set_parameter(m->ctl, (int)(vr - VR_PARAM), value);
    return "is not an input or parameter of the controller";
}

const char *model_state_name(size_t i) {
    (void)i;
    return "";
}

void model_get_states(const ModelData *m, double *x) { (void)m, (void)x; }
void model_set_states(ModelData *m, const double *x) { (void)m, (void)x; }
void model_get_derivatives(const ModelData *m, double *dx) { (void)m, (void)dx; }

const char *model_do_step(ModelData *m, double step, char *msg, size_t n) {
    const double k = floor(step / CTL_TS + 0.5);
    if (k < 1.0 || fabs(step - k * CTL_TS) > 1e-9 * CTL_TS) {
        snprintf(msg, n, "communicationStepSize %.17g s is not a multiple of the controller's "
                 "sample time %.17g s", step, CTL_TS);
        return msg;
    }
    if (k > CTL_MAX_STEPS_PER_CALL) {
        snprintf(msg, n, "communicationStepSize %.17g s is %.17g sample times: at most %d "
                 "controller steps per doStep", step, k, CTL_MAX_STEPS_PER_CALL);
        return msg;
    }
    for (double i = 0.0; i < k; i += 1.0) mpc_ctl_step(m->ctl, m->y, m->ref, m->d);
    m->time += step;
    m->warnings |= mpc_ctl_take_warnings(m->ctl);
    return NULL;
}

/* the warnings the step raised, one per call (the glue logs each until NULL), the most
 * serious first; a refused operator setting's reason before them */
const char *model_warning(ModelData *m, char *msg, size_t n) {
    if (m->refusal) {
        snprintf(msg, n, "an operator setting was refused (kept as it was): %s", m->refusal);
        m->refusal = NULL;
        return msg;
    }
    const int w = m->warnings;
    const int bit = w & WARN_NONFINITE_INPUT         ? WARN_NONFINITE_INPUT
                    : w & WARN_NO_ADMISSIBLE_SETPOINT ? WARN_NO_ADMISSIBLE_SETPOINT
                    : w & WARN_SETPOINT_REJECTED      ? WARN_SETPOINT_REJECTED
                                                      : w & WARN_UNREACHABLE_START;
    m->warnings &= ~bit;
    if (bit == WARN_NONFINITE_INPUT) {
        snprintf(msg, n, "a measured output, set-point or disturbance is not finite at t = "
                 "%.17g s: the last inputs are held and the observer is not advanced",
                 m->time);
        return msg;
    }
    if (bit == WARN_NO_ADMISSIBLE_SETPOINT) {
        snprintf(msg, n, "no admissible set-point at t = %.17g s (the paper's law: the "
                 "set-points and the closest admissible ones fail the certificate's "
                 "hypotheses or are not reachable): the inputs are held", m->time);
        return msg;
    }
    if (bit == WARN_SETPOINT_REJECTED) {
        snprintf(msg, n, "set-point refused at t = %.17g s (the paper's law: it fails a "
                 "hypothesis of th:feasibility-stability, or no input in the box reaches "
                 "it): the last admissible set-point is kept", m->time);
        return msg;
    }
    if (bit == WARN_UNREACHABLE_START) {
        snprintf(msg, n, "the first measured outputs are no equilibrium output the inputs' box "
                 "reaches: the observer starts at the closest reachable equilibrium");
        return msg;
    }
    return NULL;
}
