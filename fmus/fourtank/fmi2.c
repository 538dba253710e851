/*
 * FMI 2.0 glue for the four-tank plant: Co-Simulation and Model Exchange.
 *
 * Every entry point of the FMI 2.0 C API is defined here. Calls that are out of order, carry
 * bad arguments or would break the model's rules return fmi2Error with a message sent through
 * the environment's logger; they never crash the importer. The model itself (equations,
 * variables, integrator) lives in model.c.
 */
#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "model.h"

typedef enum {
    ST_INSTANTIATED,
    ST_INITIALIZATION,
    ST_STEP,             /* CS: between doSteps */
    ST_EVENT,            /* ME: event mode */
    ST_CONTINUOUS,       /* ME: continuous-time mode */
    ST_TERMINATED,
    ST_ERROR
} State;

static const char *const STATE_NAMES[] = {
    "Instantiated", "InitializationMode", "StepMode", "EventMode", "ContinuousTimeMode",
    "Terminated", "Error",
};

typedef struct {
    ModelData model;
    fmi2Type type;
    State state;
    bool logging;
    char *name;
    fmi2CallbackFunctions functions;
} Instance;

/* The saved FMU state (fmi2GetFMUstate). */
typedef struct {
    ModelData model;
    State state;
} SavedState;

/* ---------------------------------------------------------------------------------------- */
/* Logging and argument checks                                                               */
/* ---------------------------------------------------------------------------------------- */

static void log_message(const Instance *inst, fmi2Status status, const char *category,
                        const char *fmt, ...) {
    if (!inst || !inst->functions.logger) return;
    if (status == fmi2OK && !inst->logging) return;
    char raw[512], escaped[1024];
    va_list args;
    va_start(args, fmt);
    vsnprintf(raw, sizeof(raw), fmt, args);
    va_end(args);
    /* The logger treats the message as a printf format: escape '%'. */
    size_t j = 0;
    for (size_t i = 0; raw[i] && j + 2 < sizeof(escaped); i++) {
        if (raw[i] == '%') escaped[j++] = '%';
        escaped[j++] = raw[i];
    }
    escaped[j] = '\0';
    inst->functions.logger(inst->functions.componentEnvironment, inst->name, status, category,
                           escaped);
}

#define LOG_ERROR(inst, ...) log_message((inst), fmi2Error, "logStatusError", __VA_ARGS__)

/* Return fmi2Error (and log) unless the instance is in one of the allowed states. */
static bool state_ok(Instance *inst, const char *function, unsigned allowed) {
    if (allowed & (1u << inst->state)) return true;
    LOG_ERROR(inst, "%s must not be called in %s", function, STATE_NAMES[inst->state]);
    return false;
}

#define MASK(s) (1u << (s))
#define ANY_STATE 0xFFFFu
#define SETTABLE_STATES                                                                    \
    (MASK(ST_INSTANTIATED) | MASK(ST_INITIALIZATION) | MASK(ST_STEP) | MASK(ST_EVENT) |     \
     MASK(ST_CONTINUOUS))

#define BEGIN(function, allowed)                                                           \
    Instance *inst = (Instance *)c;                                                        \
    if (!inst) return fmi2Error;                                                           \
    if (!state_ok(inst, function, (allowed))) return fmi2Error;

static bool null_arg(Instance *inst, const char *function, const void *p, const char *what) {
    if (p) return false;
    LOG_ERROR(inst, "%s: argument %s must not be NULL", function, what);
    return true;
}

static bool require_type(Instance *inst, const char *function, fmi2Type type) {
    if (inst->type == type) return true;
    LOG_ERROR(inst, "%s is only available for %s instances", function,
              type == fmi2CoSimulation ? "Co-Simulation" : "Model Exchange");
    return false;
}

/* ---------------------------------------------------------------------------------------- */
/* Common functions                                                                          */
/* ---------------------------------------------------------------------------------------- */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    BEGIN("fmi2SetDebugLogging", ANY_STATE)
    if (nCategories > 0 && null_arg(inst, "fmi2SetDebugLogging", categories, "categories"))
        return fmi2Error;
    for (size_t i = 0; i < nCategories; i++) {
        if (!categories[i] || (strcmp(categories[i], "logStatusError") != 0 &&
                               strcmp(categories[i], "logEvents") != 0)) {
            LOG_ERROR(inst, "fmi2SetDebugLogging: unknown log category '%s'",
                      categories[i] ? categories[i] : "(null)");
            return fmi2Error;
        }
    }
    inst->logging = loggingOn ? true : false;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn) {
    (void)fmuResourceLocation;
    (void)visible;
    if (!functions || !functions->allocateMemory || !functions->freeMemory) return NULL;
    Instance tmp;
    memset(&tmp, 0, sizeof(tmp));
    tmp.functions = *functions;
    tmp.name = (char *)(instanceName ? instanceName : "?");
    if (!instanceName || !instanceName[0]) {
        LOG_ERROR(&tmp, "fmi2Instantiate: missing instance name");
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, INSTANTIATION_TOKEN) != 0) {
        LOG_ERROR(&tmp, "fmi2Instantiate: wrong GUID '%s' (expected %s)",
                  fmuGUID ? fmuGUID : "(null)", INSTANTIATION_TOKEN);
        return NULL;
    }
    if (fmuType != fmi2CoSimulation && fmuType != fmi2ModelExchange) {
        LOG_ERROR(&tmp, "fmi2Instantiate: unknown FMU type %d", (int)fmuType);
        return NULL;
    }
    Instance *inst = (Instance *)functions->allocateMemory(1, sizeof(Instance));
    char *name = (char *)functions->allocateMemory(strlen(instanceName) + 1, 1);
    if (!inst || !name) {
        if (inst) functions->freeMemory(inst);
        if (name) functions->freeMemory(name);
        LOG_ERROR(&tmp, "fmi2Instantiate: out of memory");
        return NULL;
    }
    strcpy(name, instanceName);
    inst->name = name;
    inst->functions = *functions;
    inst->type = fmuType;
    inst->logging = loggingOn ? true : false;
    inst->state = ST_INSTANTIATED;
    model_set_defaults(&inst->model);
    return inst;
}

void fmi2FreeInstance(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (!inst) return;
    fmi2CallbackFreeMemory freeMemory = inst->functions.freeMemory;
    freeMemory(inst->name);
    freeMemory(inst);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined,
                               fmi2Real tolerance, fmi2Real startTime,
                               fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    BEGIN("fmi2SetupExperiment", MASK(ST_INSTANTIATED))
    (void)toleranceDefined;
    (void)tolerance;
    if (!isfinite(startTime)) {
        LOG_ERROR(inst, "fmi2SetupExperiment: startTime must be finite");
        return fmi2Error;
    }
    if (stopTimeDefined && !(stopTime >= startTime)) {
        LOG_ERROR(inst, "fmi2SetupExperiment: stopTime %g is before startTime %g", stopTime,
                  startTime);
        return fmi2Error;
    }
    inst->model.time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    BEGIN("fmi2EnterInitializationMode", MASK(ST_INSTANTIATED))
    inst->state = ST_INITIALIZATION;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    BEGIN("fmi2ExitInitializationMode", MASK(ST_INITIALIZATION))
    model_initialize(&inst->model);
    inst->state = inst->type == fmi2CoSimulation ? ST_STEP : ST_EVENT;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    BEGIN("fmi2Terminate", MASK(ST_STEP) | MASK(ST_EVENT) | MASK(ST_CONTINUOUS))
    inst->state = ST_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    BEGIN("fmi2Reset", ANY_STATE)
    model_set_defaults(&inst->model);
    inst->state = ST_INSTANTIATED;
    return fmi2OK;
}

/* ---------------------------------------------------------------------------------------- */
/* Getting and setting variables                                                             */
/* ---------------------------------------------------------------------------------------- */

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       fmi2Real value[]) {
    BEGIN("fmi2GetReal", ANY_STATE)
    if (nvr == 0) return fmi2OK;
    if (null_arg(inst, "fmi2GetReal", vr, "vr") || null_arg(inst, "fmi2GetReal", value, "value"))
        return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= N_VARIABLES) {
            LOG_ERROR(inst, "fmi2GetReal: unknown value reference %u", (unsigned)vr[i]);
            return fmi2Error;
        }
        value[i] = model_get(&inst->model, vr[i]);
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[]) {
    BEGIN("fmi2SetReal", SETTABLE_STATES)
    if (nvr == 0) return fmi2OK;
    if (null_arg(inst, "fmi2SetReal", vr, "vr") || null_arg(inst, "fmi2SetReal", value, "value"))
        return fmi2Error;
    const bool initialized = inst->state != ST_INSTANTIATED && inst->state != ST_INITIALIZATION;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= N_VARIABLES) {
            LOG_ERROR(inst, "fmi2SetReal: unknown value reference %u", (unsigned)vr[i]);
            return fmi2Error;
        }
        const char *why = model_set(&inst->model, vr[i], value[i], initialized);
        if (why) {
            LOG_ERROR(inst, "fmi2SetReal: cannot set %s = %.17g: %s",
                      model_variable_name(vr[i]), value[i], why);
            return fmi2Error;
        }
    }
    return fmi2OK;
}

/* The model has Real variables only: any other type is an unknown value reference. */
static fmi2Status no_such_variables(fmi2Component c, const char *function, size_t nvr) {
    BEGIN(function, ANY_STATE)
    if (nvr == 0) return fmi2OK;
    LOG_ERROR(inst, "%s: the model has no variables of this type", function);
    return fmi2Error;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer value[]) {
    (void)vr;
    (void)value;
    return no_such_variables(c, "fmi2GetInteger", nvr);
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Boolean value[]) {
    (void)vr;
    (void)value;
    return no_such_variables(c, "fmi2GetBoolean", nvr);
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String value[]) {
    (void)vr;
    (void)value;
    return no_such_variables(c, "fmi2GetString", nvr);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[]) {
    (void)vr;
    (void)value;
    return no_such_variables(c, "fmi2SetInteger", nvr);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[]) {
    (void)vr;
    (void)value;
    return no_such_variables(c, "fmi2SetBoolean", nvr);
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[]) {
    (void)vr;
    (void)value;
    return no_such_variables(c, "fmi2SetString", nvr);
}

/* ---------------------------------------------------------------------------------------- */
/* FMU state                                                                                 */
/* ---------------------------------------------------------------------------------------- */

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    BEGIN("fmi2GetFMUstate", ANY_STATE)
    if (null_arg(inst, "fmi2GetFMUstate", FMUstate, "FMUstate")) return fmi2Error;
    SavedState *s = (SavedState *)*FMUstate;
    if (!s) {
        s = (SavedState *)inst->functions.allocateMemory(1, sizeof(SavedState));
        if (!s) {
            LOG_ERROR(inst, "fmi2GetFMUstate: out of memory");
            return fmi2Error;
        }
    }
    s->model = inst->model;
    s->state = inst->state;
    *FMUstate = s;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    BEGIN("fmi2SetFMUstate", ANY_STATE)
    if (null_arg(inst, "fmi2SetFMUstate", FMUstate, "FMUstate")) return fmi2Error;
    const SavedState *s = (const SavedState *)FMUstate;
    inst->model = s->model;
    inst->state = s->state;
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    BEGIN("fmi2FreeFMUstate", ANY_STATE)
    if (null_arg(inst, "fmi2FreeFMUstate", FMUstate, "FMUstate")) return fmi2Error;
    if (*FMUstate) inst->functions.freeMemory(*FMUstate);
    *FMUstate = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
    BEGIN("fmi2SerializedFMUstateSize", ANY_STATE)
    (void)FMUstate;
    if (null_arg(inst, "fmi2SerializedFMUstateSize", size, "size")) return fmi2Error;
    *size = sizeof(SavedState);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate,
                                 fmi2Byte serializedState[], size_t size) {
    BEGIN("fmi2SerializeFMUstate", ANY_STATE)
    if (null_arg(inst, "fmi2SerializeFMUstate", FMUstate, "FMUstate") ||
        null_arg(inst, "fmi2SerializeFMUstate", serializedState, "serializedState"))
        return fmi2Error;
    if (size != sizeof(SavedState)) {
        LOG_ERROR(inst, "fmi2SerializeFMUstate: size must be %zu, got %zu", sizeof(SavedState),
                  size);
        return fmi2Error;
    }
    memcpy(serializedState, FMUstate, sizeof(SavedState));
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[],
                                   size_t size, fmi2FMUstate *FMUstate) {
    BEGIN("fmi2DeSerializeFMUstate", ANY_STATE)
    if (null_arg(inst, "fmi2DeSerializeFMUstate", serializedState, "serializedState") ||
        null_arg(inst, "fmi2DeSerializeFMUstate", FMUstate, "FMUstate"))
        return fmi2Error;
    if (size != sizeof(SavedState)) {
        LOG_ERROR(inst, "fmi2DeSerializeFMUstate: size must be %zu, got %zu",
                  sizeof(SavedState), size);
        return fmi2Error;
    }
    SavedState s;
    memcpy(&s, serializedState, sizeof(s));
    if ((unsigned)s.state > ST_ERROR) {
        LOG_ERROR(inst, "fmi2DeSerializeFMUstate: corrupt state");
        return fmi2Error;
    }
    if (!*FMUstate) {
        *FMUstate = inst->functions.allocateMemory(1, sizeof(SavedState));
        if (!*FMUstate) {
            LOG_ERROR(inst, "fmi2DeSerializeFMUstate: out of memory");
            return fmi2Error;
        }
    }
    memcpy(*FMUstate, &s, sizeof(s));
    return fmi2OK;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[],
                                        size_t nUnknown, const fmi2ValueReference vKnown_ref[],
                                        size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
    BEGIN("fmi2GetDirectionalDerivative", ANY_STATE)
    (void)vUnknown_ref;
    (void)nUnknown;
    (void)vKnown_ref;
    (void)nKnown;
    (void)dvKnown;
    (void)dvUnknown;
    LOG_ERROR(inst, "fmi2GetDirectionalDerivative is not provided by this FMU");
    return fmi2Error;
}

/* ---------------------------------------------------------------------------------------- */
/* Model Exchange                                                                            */
/* ---------------------------------------------------------------------------------------- */

fmi2Status fmi2EnterEventMode(fmi2Component c) {
    BEGIN("fmi2EnterEventMode", MASK(ST_EVENT) | MASK(ST_CONTINUOUS))
    if (!require_type(inst, "fmi2EnterEventMode", fmi2ModelExchange)) return fmi2Error;
    inst->state = ST_EVENT;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo) {
    BEGIN("fmi2NewDiscreteStates", MASK(ST_EVENT))
    if (!require_type(inst, "fmi2NewDiscreteStates", fmi2ModelExchange)) return fmi2Error;
    if (null_arg(inst, "fmi2NewDiscreteStates", eventInfo, "eventInfo")) return fmi2Error;
    eventInfo->newDiscreteStatesNeeded = fmi2False;
    eventInfo->terminateSimulation = fmi2False;
    eventInfo->nominalsOfContinuousStatesChanged = fmi2False;
    eventInfo->valuesOfContinuousStatesChanged = fmi2False;
    eventInfo->nextEventTimeDefined = fmi2False;
    eventInfo->nextEventTime = 0.0;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
    BEGIN("fmi2EnterContinuousTimeMode", MASK(ST_EVENT))
    if (!require_type(inst, "fmi2EnterContinuousTimeMode", fmi2ModelExchange)) return fmi2Error;
    inst->state = ST_CONTINUOUS;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c,
                                       fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode,
                                       fmi2Boolean *terminateSimulation) {
    BEGIN("fmi2CompletedIntegratorStep", MASK(ST_CONTINUOUS))
    (void)noSetFMUStatePriorToCurrentPoint;
    if (null_arg(inst, "fmi2CompletedIntegratorStep", enterEventMode, "enterEventMode") ||
        null_arg(inst, "fmi2CompletedIntegratorStep", terminateSimulation,
                 "terminateSimulation"))
        return fmi2Error;
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    BEGIN("fmi2SetTime", MASK(ST_EVENT) | MASK(ST_CONTINUOUS))
    if (!require_type(inst, "fmi2SetTime", fmi2ModelExchange)) return fmi2Error;
    if (!isfinite(time)) {
        LOG_ERROR(inst, "fmi2SetTime: time must be finite");
        return fmi2Error;
    }
    inst->model.time = time;
    return fmi2OK;
}

static bool check_nx(Instance *inst, const char *function, size_t nx) {
    if (nx == N_STATES) return true;
    LOG_ERROR(inst, "%s: the model has %d continuous states, got nx = %zu", function, N_STATES,
              nx);
    return false;
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    BEGIN("fmi2SetContinuousStates", MASK(ST_EVENT) | MASK(ST_CONTINUOUS))
    if (!require_type(inst, "fmi2SetContinuousStates", fmi2ModelExchange) ||
        !check_nx(inst, "fmi2SetContinuousStates", nx) ||
        null_arg(inst, "fmi2SetContinuousStates", x, "x"))
        return fmi2Error;
    for (size_t i = 0; i < nx; i++) {
        if (!isfinite(x[i])) {
            LOG_ERROR(inst, "fmi2SetContinuousStates: h%zu must be finite", i + 1);
            return fmi2Error;
        }
    }
    model_set_states(&inst->model, x);
    return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    BEGIN("fmi2GetDerivatives", ANY_STATE)
    if (!require_type(inst, "fmi2GetDerivatives", fmi2ModelExchange) ||
        !check_nx(inst, "fmi2GetDerivatives", nx) ||
        null_arg(inst, "fmi2GetDerivatives", derivatives, "derivatives"))
        return fmi2Error;
    model_derivatives(&inst->model, inst->model.h, derivatives);
    return fmi2OK;
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    BEGIN("fmi2GetEventIndicators", ANY_STATE)
    (void)eventIndicators;
    if (ni != N_EVENT_INDICATORS) {
        LOG_ERROR(inst, "fmi2GetEventIndicators: the model has no event indicators, got %zu",
                  ni);
        return fmi2Error;
    }
    return fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    BEGIN("fmi2GetContinuousStates", ANY_STATE)
    if (!require_type(inst, "fmi2GetContinuousStates", fmi2ModelExchange) ||
        !check_nx(inst, "fmi2GetContinuousStates", nx) ||
        null_arg(inst, "fmi2GetContinuousStates", x, "x"))
        return fmi2Error;
    memcpy(x, inst->model.h, sizeof(inst->model.h));
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    BEGIN("fmi2GetNominalsOfContinuousStates", ANY_STATE)
    if (!require_type(inst, "fmi2GetNominalsOfContinuousStates", fmi2ModelExchange) ||
        !check_nx(inst, "fmi2GetNominalsOfContinuousStates", nx) ||
        null_arg(inst, "fmi2GetNominalsOfContinuousStates", x_nominal, "x_nominal"))
        return fmi2Error;
    for (size_t i = 0; i < nx; i++) x_nominal[i] = 1.0;
    return fmi2OK;
}

/* ---------------------------------------------------------------------------------------- */
/* Co-Simulation                                                                             */
/* ---------------------------------------------------------------------------------------- */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                       size_t nvr, const fmi2Integer order[],
                                       const fmi2Real value[]) {
    BEGIN("fmi2SetRealInputDerivatives", ANY_STATE)
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    LOG_ERROR(inst, "fmi2SetRealInputDerivatives: canInterpolateInputs is false");
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2Integer order[],
                                        fmi2Real value[]) {
    BEGIN("fmi2GetRealOutputDerivatives", ANY_STATE)
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    LOG_ERROR(inst, "fmi2GetRealOutputDerivatives: maxOutputDerivativeOrder is 0");
    return fmi2Error;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentCommunicationPoint) {
    BEGIN("fmi2DoStep", MASK(ST_STEP))
    (void)noSetFMUStatePriorToCurrentCommunicationPoint;
    if (!require_type(inst, "fmi2DoStep", fmi2CoSimulation)) return fmi2Error;
    if (!isfinite(communicationStepSize) || communicationStepSize < 0.0) {
        LOG_ERROR(inst, "fmi2DoStep: communicationStepSize must be finite and >= 0, got %g",
                  communicationStepSize);
        return fmi2Error;
    }
    const double t = inst->model.time;
    if (!isfinite(currentCommunicationPoint) ||
        fabs(currentCommunicationPoint - t) > 1e-9 * (1.0 + fabs(t))) {
        LOG_ERROR(inst, "fmi2DoStep: currentCommunicationPoint = %.17g, expected %.17g",
                  currentCommunicationPoint, t);
        return fmi2Error;
    }
    inst->model.time = currentCommunicationPoint; /* absorb the master's round-off */
    if (communicationStepSize == 0.0) return fmi2OK;
    char msg[256];
    if (model_do_step(&inst->model, communicationStepSize, msg, sizeof(msg))) {
        LOG_ERROR(inst, "fmi2DoStep: %s", msg);
        inst->state = ST_ERROR;
        return fmi2Error;
    }
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    BEGIN("fmi2CancelStep", ANY_STATE)
    LOG_ERROR(inst, "fmi2CancelStep: doStep never returns fmi2Pending");
    return fmi2Error;
}

static fmi2Status no_status(fmi2Component c, const char *function) {
    BEGIN(function, ANY_STATE)
    log_message(inst, fmi2Discard, "logStatusError", "%s: no such status (doStep is synchronous)",
                function);
    return fmi2Discard;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    (void)s;
    (void)value;
    return no_status(c, "fmi2GetStatus");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    BEGIN("fmi2GetRealStatus", ANY_STATE)
    if (s == fmi2LastSuccessfulTime && value) {
        *value = inst->model.time;
        return fmi2OK;
    }
    return no_status(c, "fmi2GetRealStatus");
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    (void)s;
    (void)value;
    return no_status(c, "fmi2GetIntegerStatus");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    BEGIN("fmi2GetBooleanStatus", ANY_STATE)
    if (s == fmi2Terminated && value) {
        *value = fmi2False;
        return fmi2OK;
    }
    return no_status(c, "fmi2GetBooleanStatus");
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    (void)s;
    (void)value;
    return no_status(c, "fmi2GetStringStatus");
}
