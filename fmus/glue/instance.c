/*
 * The FMI-version-independent instance layer of every C plant model (see instance.h).
 *
 * Everything FMI 2.0 and FMI 3.0 have in common lives here: the state machine, argument
 * checks, checked get/set of Float64 variables by value reference, FMU-state save/restore/
 * serialisation, the Co-Simulation doStep with the integrator of model.c, and logging.
 * Messages name the FMI function the glue passes in, so both versions log the same text.
 */
#include "instance.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

static const char *const STATE_NAMES[] = {
    "Instantiated", "InitializationMode", "StepMode", "EventMode", "ContinuousTimeMode",
    "Terminated", "Error",
};

/* The saved FMU state (GetFMUState); its bytes are the serialised form. */
typedef struct {
    ModelData model;
    State state;
} SavedState;

/* Check instance, state machine and interface type; on failure return STATUS_ERROR. */
#define BEGIN(function, allowed, need)                                                     \
    if (!instance_check(inst, (function), (allowed), (need))) return STATUS_ERROR;

void instance_log(const Instance *inst, Status status, const char *category, const char *fmt,
                  ...) {
    if (!inst || !inst->host) return;
    if (status == STATUS_OK && !inst->logging) return;
    char message[512];
    va_list args;
    va_start(args, fmt);
    vsnprintf(message, sizeof(message), fmt, args);
    va_end(args);
    inst->host->log(inst, status, category, message);
}

bool instance_check(Instance *inst, const char *function, unsigned allowed, InterfaceType need) {
    if (!inst) return false;
    if (!(allowed & MASK(inst->state))) {
        LOG_ERROR(inst, "%s must not be called in %s", function, STATE_NAMES[inst->state]);
        return false;
    }
    if (need != TYPE_ANY && inst->type != need) {
        LOG_ERROR(inst, "%s is only available for %s instances", function,
                  need == TYPE_CS ? "Co-Simulation" : "Model Exchange");
        return false;
    }
    return true;
}

bool instance_null_arg(Instance *inst, const char *function, const void *p, const char *what) {
    if (p) return false;
    LOG_ERROR(inst, "%s: argument %s must not be NULL", function, what);
    return true;
}

Status instance_refuse(Instance *inst, const char *function, Status status, const char *reason) {
    BEGIN(function, ANY_STATE, TYPE_ANY)
    instance_log(inst, status, "logStatusError", "%s%s", function, reason);
    return status;
}

Status instance_no_such_variables(Instance *inst, const char *function, size_t nvr) {
    BEGIN(function, ANY_STATE, TYPE_ANY)
    if (nvr == 0) return STATUS_OK;
    return instance_refuse(inst, function, STATUS_ERROR,
                           ": the model has no variables of this type");
}

/* ---------------------------------------------------------------------------------------- */
/* Life cycle                                                                                */
/* ---------------------------------------------------------------------------------------- */

bool instance_check_instantiation(const Instance *tmp, const char *function, const char *name,
                                  const char *token, const char *token_label) {
    if (!name || !name[0]) {
        LOG_ERROR(tmp, "%s: missing instance name", function);
        return false;
    }
    if (!token || strcmp(token, INSTANTIATION_TOKEN) != 0) {
        LOG_ERROR(tmp, "%s: wrong %s '%s' (expected %s)", function, token_label,
                  token ? token : "(null)", INSTANTIATION_TOKEN);
        return false;
    }
    return true;
}

Instance *instance_new(const Instance *tmp, size_t size, const char *function,
                       InterfaceType type, const char *name, bool logging,
                       const char *resources) {
    Instance *inst = (Instance *)tmp->host->alloc(tmp, size);
    char *copy = (char *)tmp->host->alloc(tmp, strlen(name) + 1);
    if (!inst || !copy) {
        if (inst) tmp->host->release(tmp, inst);
        if (copy) tmp->host->release(tmp, copy);
        LOG_ERROR(tmp, "%s: out of memory", function);
        return NULL;
    }
    memcpy(inst, tmp, size);
    strcpy(copy, name);
    inst->name = copy;
    inst->type = type;
    inst->logging = logging;
    inst->event_mode_used = false;
    inst->state = ST_INSTANTIATED;
    model_set_defaults(&inst->model);
#ifdef MODEL_HAS_RESOURCES
    char msg[512];
    const char *why = model_acquire(&inst->model, resources, msg, sizeof msg);
    if (why) {
        LOG_ERROR(tmp, "%s: %s", function, why);
        tmp->host->release(tmp, copy);
        tmp->host->release(tmp, inst);
        return NULL;
    }
#else
    (void)resources;
#endif
    return inst;
}

void instance_free(Instance *inst) {
    if (!inst) return;
    const Host *host = inst->host;
#ifdef MODEL_HAS_RESOURCES
    model_release(&inst->model);
#endif
    host->release(inst, inst->name);
    host->release(inst, inst);
}

Status instance_set_debug_logging(Instance *inst, const char *function, bool on,
                                  size_t nCategories, const char *const categories[]) {
    BEGIN(function, ANY_STATE, TYPE_ANY)
    if (nCategories > 0 && instance_null_arg(inst, function, categories, "categories"))
        return STATUS_ERROR;
    for (size_t i = 0; i < nCategories; i++) {
        if (!categories[i] || (strcmp(categories[i], "logStatusError") != 0 &&
                               strcmp(categories[i], "logEvents") != 0 &&
                               strcmp(categories[i], "logStatusWarning") != 0)) {
            LOG_ERROR(inst, "%s: unknown log category '%s'", function,
                      categories[i] ? categories[i] : "(null)");
            return STATUS_ERROR;
        }
    }
    inst->logging = on;
    return STATUS_OK;
}

Status instance_setup_experiment(Instance *inst, const char *function, double startTime,
                                 bool stopTimeDefined, double stopTime) {
    BEGIN(function, MASK(ST_INSTANTIATED), TYPE_ANY)
    if (!isfinite(startTime)) {
        LOG_ERROR(inst, "%s: startTime must be finite", function);
        return STATUS_ERROR;
    }
    if (stopTimeDefined && !(stopTime >= startTime)) {
        LOG_ERROR(inst, "%s: stopTime %g is before startTime %g", function, stopTime, startTime);
        return STATUS_ERROR;
    }
    inst->model.time = startTime;
    return STATUS_OK;
}

Status instance_transition(Instance *inst, const char *function, unsigned allowed,
                           InterfaceType need, State next) {
    BEGIN(function, allowed, need)
    inst->state = next;
    return STATUS_OK;
}

Status instance_exit_initialization(Instance *inst, const char *function) {
    BEGIN(function, MASK(ST_INITIALIZATION), TYPE_ANY)
    model_initialize(&inst->model);
    inst->state = (inst->type == TYPE_CS && !inst->event_mode_used) ? ST_STEP : ST_EVENT;
    return STATUS_OK;
}

Status instance_reset(Instance *inst, const char *function) {
    BEGIN(function, ANY_STATE, TYPE_ANY)
    model_set_defaults(&inst->model);
    inst->state = ST_INSTANTIATED;
    return STATUS_OK;
}

/* ---------------------------------------------------------------------------------------- */
/* Variables                                                                                 */
/* ---------------------------------------------------------------------------------------- */

/* NULL arrays, a count mismatch (FMI 3 nValues) or an unknown value reference -> false. */
static bool check_values(Instance *inst, const char *function, const unsigned int vr[],
                         const char *vr_name, size_t nvr, const void *values,
                         const char *values_name, size_t nValues) {
    if (instance_null_arg(inst, function, vr, vr_name) ||
        instance_null_arg(inst, function, values, values_name))
        return false;
    if (nValues != nvr) {
        LOG_ERROR(inst, "%s: nValues = %zu, expected %zu (all variables are scalars)", function,
                  nValues, nvr);
        return false;
    }
    return true;
}

/* Values one set call takes without allocating (the undo buffer of instance_set_float64). */
#define SET_STACK_VALUES 64

static bool known_vr(Instance *inst, const char *function, unsigned int vr) {
    if (vr < N_VARIABLES) return true;
    LOG_ERROR(inst, "%s: unknown value reference %u", function, vr);
    return false;
}

Status instance_get_float64(Instance *inst, const char *function, const unsigned int vr[],
                            const char *vr_name, size_t nvr, double values[],
                            const char *values_name, size_t nValues) {
    BEGIN(function, ANY_STATE, TYPE_ANY)
    if (nvr == 0) return STATUS_OK;
    if (!check_values(inst, function, vr, vr_name, nvr, values, values_name, nValues))
        return STATUS_ERROR;
    for (size_t i = 0; i < nvr; i++) {
        if (!known_vr(inst, function, vr[i])) return STATUS_ERROR;
        values[i] = model_get(&inst->model, vr[i]);
    }
    return STATUS_OK;
}

Status instance_set_float64(Instance *inst, const char *function, const unsigned int vr[],
                            const char *vr_name, size_t nvr, const double values[],
                            const char *values_name, size_t nValues) {
    BEGIN(function, SETTABLE_STATES, TYPE_ANY)
    if (nvr == 0) return STATUS_OK;
    if (!check_values(inst, function, vr, vr_name, nvr, values, values_name, nValues))
        return STATUS_ERROR;
    const bool initialized = inst->state != ST_INSTANTIATED && inst->state != ST_INITIALIZATION;
    for (size_t i = 0; i < nvr; i++)
        if (!known_vr(inst, function, vr[i])) return STATUS_ERROR;
    /* all or nothing: a value the model refuses puts back the ones set before it, last
     * first (each was accepted once, from the state it is put back into) */
    double stack[SET_STACK_VALUES];
    double *previous = nvr <= SET_STACK_VALUES
                           ? stack
                           : (double *)inst->host->alloc(inst, nvr * sizeof(double));
    if (!previous) {
        LOG_ERROR(inst, "%s: out of memory", function);
        return STATUS_ERROR;
    }
    Status status = STATUS_OK;
    for (size_t i = 0; i < nvr; i++) {
        previous[i] = model_get(&inst->model, vr[i]);
        const char *why = model_set(&inst->model, vr[i], values[i], initialized);
        if (why) {
            LOG_ERROR(inst, "%s: cannot set %s = %.17g: %s (no value of this call is set)",
                      function, model_variable_name(vr[i]), values[i], why);
            while (i-- > 0) (void)model_set(&inst->model, vr[i], previous[i], initialized);
            status = STATUS_ERROR;
            break;
        }
    }
    if (previous != stack) inst->host->release(inst, previous);
    return status;
}

/* ---------------------------------------------------------------------------------------- */
/* FMU state                                                                                 */
/* ---------------------------------------------------------------------------------------- */

#ifdef MODEL_NO_FMU_STATE
/* A model that owns memory beyond ModelData (MODEL_HAS_RESOURCES) cannot save its state. */
#define NO_FMU_STATE(function)                                                             \
    return instance_refuse(inst, (function), STATUS_ERROR,                                 \
                           ": this FMU cannot save its state (canGetAndSetFMUState is false)");
#else
#define NO_FMU_STATE(function)
#endif

Status instance_get_fmu_state(Instance *inst, const char *function, void **state,
                              const char *state_name) {
    BEGIN(function, ANY_STATE, TYPE_ANY)
    NO_FMU_STATE(function)
    if (instance_null_arg(inst, function, state, state_name)) return STATUS_ERROR;
    SavedState *s = (SavedState *)*state;
    if (!s) {
        s = (SavedState *)inst->host->alloc(inst, sizeof(SavedState));
        if (!s) {
            LOG_ERROR(inst, "%s: out of memory", function);
            return STATUS_ERROR;
        }
    }
    s->model = inst->model;
    s->state = inst->state;
    *state = s;
    return STATUS_OK;
}

Status instance_set_fmu_state(Instance *inst, const char *function, const void *state,
                              const char *state_name) {
    BEGIN(function, ANY_STATE, TYPE_ANY)
    NO_FMU_STATE(function)
    if (instance_null_arg(inst, function, state, state_name)) return STATUS_ERROR;
    const SavedState *s = (const SavedState *)state;
    inst->model = s->model;
    inst->state = s->state;
    return STATUS_OK;
}

Status instance_free_fmu_state(Instance *inst, const char *function, void **state,
                               const char *state_name) {
    BEGIN(function, ANY_STATE, TYPE_ANY)
    NO_FMU_STATE(function)
    if (instance_null_arg(inst, function, state, state_name)) return STATUS_ERROR;
    if (*state) inst->host->release(inst, *state);
    *state = NULL;
    return STATUS_OK;
}

Status instance_serialized_size(Instance *inst, const char *function, size_t *size) {
    BEGIN(function, ANY_STATE, TYPE_ANY)
    NO_FMU_STATE(function)
    if (instance_null_arg(inst, function, size, "size")) return STATUS_ERROR;
    *size = sizeof(SavedState);
    return STATUS_OK;
}

static bool check_size(Instance *inst, const char *function, size_t size) {
    if (size == sizeof(SavedState)) return true;
    LOG_ERROR(inst, "%s: size must be %zu, got %zu", function, sizeof(SavedState), size);
    return false;
}

Status instance_serialize(Instance *inst, const char *function, const void *state,
                          const char *state_name, unsigned char bytes[], size_t size) {
    BEGIN(function, ANY_STATE, TYPE_ANY)
    NO_FMU_STATE(function)
    if (instance_null_arg(inst, function, state, state_name) ||
        instance_null_arg(inst, function, bytes, "serializedState") ||
        !check_size(inst, function, size))
        return STATUS_ERROR;
    memcpy(bytes, state, sizeof(SavedState));
    return STATUS_OK;
}

Status instance_deserialize(Instance *inst, const char *function, const unsigned char bytes[],
                            size_t size, void **state, const char *state_name) {
    BEGIN(function, ANY_STATE, TYPE_ANY)
    NO_FMU_STATE(function)
    if (instance_null_arg(inst, function, bytes, "serializedState") ||
        instance_null_arg(inst, function, state, state_name) ||
        !check_size(inst, function, size))
        return STATUS_ERROR;
    SavedState s;
    memcpy(&s, bytes, sizeof(s));
    if ((unsigned)s.state > ST_ERROR) {
        LOG_ERROR(inst, "%s: corrupt state", function);
        return STATUS_ERROR;
    }
    if (!*state) {
        *state = inst->host->alloc(inst, sizeof(SavedState));
        if (!*state) {
            LOG_ERROR(inst, "%s: out of memory", function);
            return STATUS_ERROR;
        }
    }
    memcpy(*state, &s, sizeof(s));
    return STATUS_OK;
}

/* ---------------------------------------------------------------------------------------- */
/* Model Exchange                                                                            */
/* ---------------------------------------------------------------------------------------- */

Status instance_set_time(Instance *inst, const char *function, double time) {
    BEGIN(function, MASK(ST_EVENT) | MASK(ST_CONTINUOUS), TYPE_ME)
    if (!isfinite(time)) {
        LOG_ERROR(inst, "%s: time must be finite", function);
        return STATUS_ERROR;
    }
    inst->model.time = time;
    return STATUS_OK;
}

Status instance_completed_integrator_step(Instance *inst, const char *function,
                                          const void *enterEventMode,
                                          const void *terminateSimulation) {
    BEGIN(function, MASK(ST_CONTINUOUS), TYPE_ANY)
    if (instance_null_arg(inst, function, enterEventMode, "enterEventMode") ||
        instance_null_arg(inst, function, terminateSimulation, "terminateSimulation"))
        return STATUS_ERROR;
    return STATUS_OK;
}

/* Checks shared by the state-vector calls: ME instance, nx = N_STATES, array not NULL. */
static bool check_vector(Instance *inst, const char *function, unsigned allowed,
                         const void *x, const char *x_name, size_t nx, const char *nx_label) {
    if (!instance_check(inst, function, allowed, TYPE_ME)) return false;
    if (nx != N_STATES) {
        LOG_ERROR(inst, "%s: the model has %d continuous states, got %s%zu", function, N_STATES,
                  nx_label, nx);
        return false;
    }
    return !instance_null_arg(inst, function, x, x_name);
}

Status instance_set_continuous_states(Instance *inst, const char *function, const double x[],
                                      const char *x_name, size_t nx, const char *nx_label) {
    if (!check_vector(inst, function, MASK(ST_EVENT) | MASK(ST_CONTINUOUS), x, x_name, nx,
                      nx_label))
        return STATUS_ERROR;
    for (size_t i = 0; i < nx; i++) {
        if (!isfinite(x[i])) {
            LOG_ERROR(inst, "%s: %s must be finite", function, model_state_name(i));
            return STATUS_ERROR;
        }
    }
    model_set_states(&inst->model, x);
    return STATUS_OK;
}

/* A vector of N_STATES values the model gives in any state (its states, their derivatives):
 * checked as check_vector does, then filled by get. */
static Status get_vector(Instance *inst, const char *function, double v[], const char *v_name,
                         size_t nx, const char *nx_label,
                         void (*get)(const ModelData *m, double *v)) {
    if (!check_vector(inst, function, ANY_STATE, v, v_name, nx, nx_label)) return STATUS_ERROR;
    get(&inst->model, v);
    return STATUS_OK;
}

Status instance_get_continuous_states(Instance *inst, const char *function, double x[],
                                      const char *x_name, size_t nx, const char *nx_label) {
    return get_vector(inst, function, x, x_name, nx, nx_label, model_get_states);
}

Status instance_get_derivatives(Instance *inst, const char *function, double dx[],
                                const char *dx_name, size_t nx, const char *nx_label) {
    return get_vector(inst, function, dx, dx_name, nx, nx_label, model_get_derivatives);
}

Status instance_get_nominals(Instance *inst, const char *function, double nominals[],
                             const char *name, size_t nx, const char *nx_label) {
    if (!check_vector(inst, function, ANY_STATE, nominals, name, nx, nx_label))
        return STATUS_ERROR;
    for (size_t i = 0; i < nx; i++) nominals[i] = 1.0;
    return STATUS_OK;
}

Status instance_get_event_indicators(Instance *inst, const char *function, size_t ni) {
    BEGIN(function, ANY_STATE, TYPE_ANY)
    if (ni != N_EVENT_INDICATORS) {
        LOG_ERROR(inst, "%s: the model has no event indicators, got %zu", function, ni);
        return STATUS_ERROR;
    }
    return STATUS_OK;
}

/* ---------------------------------------------------------------------------------------- */
/* Co-Simulation                                                                             */
/* ---------------------------------------------------------------------------------------- */

Status instance_do_step(Instance *inst, const char *function, double currentCommunicationPoint,
                        double communicationStepSize) {
    BEGIN(function, MASK(ST_STEP), TYPE_CS)
    if (!isfinite(communicationStepSize) || communicationStepSize < 0.0) {
        LOG_ERROR(inst, "%s: communicationStepSize must be finite and >= 0, got %g", function,
                  communicationStepSize);
        return STATUS_ERROR;
    }
    const double t = inst->model.time;
    if (!isfinite(currentCommunicationPoint) ||
        fabs(currentCommunicationPoint - t) > 1e-9 * (1.0 + fabs(t))) {
        LOG_ERROR(inst, "%s: currentCommunicationPoint = %.17g, expected %.17g", function,
                  currentCommunicationPoint, t);
        return STATUS_ERROR;
    }
    inst->model.time = currentCommunicationPoint; /* absorb the master's round-off */
    if (communicationStepSize == 0.0) return STATUS_OK;
    char msg[256];
    if (model_do_step(&inst->model, communicationStepSize, msg, sizeof(msg))) {
        LOG_ERROR(inst, "%s: %s", function, msg);
        inst->state = ST_ERROR;
        return STATUS_ERROR;
    }
#ifdef MODEL_HAS_WARNINGS
    Status status = STATUS_OK;
    while (model_warning(&inst->model, msg, sizeof(msg))) {   /* one line per warning */
        instance_log(inst, STATUS_WARNING, "logStatusWarning", "%s: %s", function, msg);
        status = STATUS_WARNING;
    }
    return status;
#else
    return STATUS_OK;
#endif
}
