/*
 * FMI 2.0 glue of every C plant model: Co-Simulation and Model Exchange.
 *
 * Every entry point of the FMI 2.0 C API is defined here, as a thin adapter onto the
 * version-independent layer of instance.c (state machine, argument checks, variables, FMU
 * state, doStep, logging): this file only maps the FMI 2.0 signatures, names and callbacks.
 * Calls that are out of order, carry bad arguments or would break the model's rules return
 * fmi2Error with a message sent through the environment's logger; they never crash the
 * importer. The model itself (equations, variables, integrator) lives in model.c.
 */
#include <ctype.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "instance.h"

/* Status values are passed through unchanged: they must agree. */
typedef char status_values_agree[fmi2OK == (int)STATUS_OK && fmi2Warning == (int)STATUS_WARNING &&
                                 fmi2Discard == (int)STATUS_DISCARD &&
                                 fmi2Error == (int)STATUS_ERROR && fmi2Fatal == (int)STATUS_FATAL
                                 ? 1 : -1];

/* An FMI 2 instance: the shared instance plus a copy of the environment's callbacks. */
typedef struct {
    Instance base;
    fmi2CallbackFunctions functions;
} Fmi2Instance;

#define INST ((Instance *)c)
#define RETURN(call) return (fmi2Status)(call)

static const fmi2CallbackFunctions *callbacks(const Instance *inst) {
    return &((const Fmi2Instance *)inst)->functions;
}

static void host_log(const Instance *inst, Status status, const char *category,
                     const char *message) {
    const fmi2CallbackFunctions *f = callbacks(inst);
    if (!f->logger) return;
    /* The logger treats the message as a printf format: escape '%'. */
    char escaped[1024];
    size_t j = 0;
    for (size_t i = 0; message[i] && j + 2 < sizeof(escaped); i++) {
        if (message[i] == '%') escaped[j++] = '%';
        escaped[j++] = message[i];
    }
    escaped[j] = '\0';
    f->logger(f->componentEnvironment, inst->name, (fmi2Status)status, category, escaped);
}

static void *host_alloc(const Instance *inst, size_t size) {
    return callbacks(inst)->allocateMemory(1, size);
}

static void host_release(const Instance *inst, void *p) { callbacks(inst)->freeMemory(p); }

static const Host HOST = {host_log, host_alloc, host_release};

/* ---------------------------------------------------------------------------------------- */
/* Common functions                                                                          */
/* ---------------------------------------------------------------------------------------- */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    RETURN(instance_set_debug_logging(INST, "fmi2SetDebugLogging", loggingOn ? true : false,
                                      nCategories, categories));
}

/* The local path of an FMI 2 resource location (a file URI: file:///path, file:/path or
 * file://localhost/path, percent-encoded) in out[n]; false when it is none of these. */
static bool resource_path(const char *uri, char *out, size_t n) {
    if (!uri || strncmp(uri, "file:", 5) != 0) return false;
    const char *p = uri + 5;
    if (strncmp(p, "//localhost/", 12) == 0) p += 11;
    else if (strncmp(p, "///", 3) == 0) p += 2;
    else if (strncmp(p, "//", 2) == 0) return false; /* a file on another host */
    size_t k = 0;
    for (; *p; p++) {
        int c = (unsigned char)*p;
        if (c == '%' && isxdigit((unsigned char)p[1]) && isxdigit((unsigned char)p[2])) {
            const char hex[3] = {p[1], p[2], 0};
            c = (int)strtol(hex, NULL, 16);
            p += 2;
        }
        if (k + 1 >= n) return false;
        out[k++] = (char)c;
    }
    out[k] = 0;
    return true;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn) {
    (void)visible;
    if (!functions || !functions->allocateMemory || !functions->freeMemory) return NULL;
    Fmi2Instance tmp;
    memset(&tmp, 0, sizeof(tmp));
    tmp.functions = *functions;
    tmp.base.host = &HOST;
    tmp.base.name = (char *)(instanceName ? instanceName : "?");
    if (!instance_check_instantiation(&tmp.base, "fmi2Instantiate", instanceName, fmuGUID,
                                      "GUID"))
        return NULL;
    if (fmuType != fmi2CoSimulation && fmuType != fmi2ModelExchange) {
        LOG_ERROR(&tmp.base, "fmi2Instantiate: unknown FMU type %d", (int)fmuType);
        return NULL;
    }
    char resources[4096];
    const bool local = resource_path(fmuResourceLocation, resources, sizeof resources);
    return instance_new(&tmp.base, sizeof(tmp), "fmi2Instantiate",
                        fmuType == fmi2CoSimulation ? TYPE_CS : TYPE_ME, instanceName,
                        loggingOn ? true : false, local ? resources : NULL);
}

void fmi2FreeInstance(fmi2Component c) { instance_free(INST); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined,
                               fmi2Real tolerance, fmi2Real startTime,
                               fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    (void)toleranceDefined;
    (void)tolerance;
    RETURN(instance_setup_experiment(INST, "fmi2SetupExperiment", startTime,
                                     stopTimeDefined ? true : false, stopTime));
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    RETURN(instance_transition(INST, "fmi2EnterInitializationMode", MASK(ST_INSTANTIATED),
                               TYPE_ANY, ST_INITIALIZATION));
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    RETURN(instance_exit_initialization(INST, "fmi2ExitInitializationMode"));
}

fmi2Status fmi2Terminate(fmi2Component c) {
    RETURN(instance_transition(INST, "fmi2Terminate", RUNNING_STATES, TYPE_ANY, ST_TERMINATED));
}

fmi2Status fmi2Reset(fmi2Component c) { RETURN(instance_reset(INST, "fmi2Reset")); }

/* ---------------------------------------------------------------------------------------- */
/* Getting and setting variables                                                             */
/* ---------------------------------------------------------------------------------------- */

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       fmi2Real value[]) {
    RETURN(instance_get_float64(INST, "fmi2GetReal", vr, "vr", nvr, value, "value", nvr));
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[]) {
    RETURN(instance_set_float64(INST, "fmi2SetReal", vr, "vr", nvr, value, "value", nvr));
}

/* The model has Real variables only: any other type is an unknown value reference. */
#define NO_SUCH_VARIABLES(NAME, TYPE, CONST)                                               \
    fmi2Status fmi2##NAME(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,      \
                          CONST TYPE value[]) {                                            \
        (void)vr;                                                                          \
        (void)value;                                                                       \
        RETURN(instance_no_such_variables(INST, "fmi2" #NAME, nvr));                       \
    }

NO_SUCH_VARIABLES(GetInteger, fmi2Integer, )
NO_SUCH_VARIABLES(GetBoolean, fmi2Boolean, )
NO_SUCH_VARIABLES(GetString, fmi2String, )
NO_SUCH_VARIABLES(SetInteger, fmi2Integer, const)
NO_SUCH_VARIABLES(SetBoolean, fmi2Boolean, const)
NO_SUCH_VARIABLES(SetString, fmi2String, const)

/* ---------------------------------------------------------------------------------------- */
/* FMU state                                                                                 */
/* ---------------------------------------------------------------------------------------- */

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    RETURN(instance_get_fmu_state(INST, "fmi2GetFMUstate", FMUstate, "FMUstate"));
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    RETURN(instance_set_fmu_state(INST, "fmi2SetFMUstate", FMUstate, "FMUstate"));
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    RETURN(instance_free_fmu_state(INST, "fmi2FreeFMUstate", FMUstate, "FMUstate"));
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
    (void)FMUstate;
    RETURN(instance_serialized_size(INST, "fmi2SerializedFMUstateSize", size));
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate,
                                 fmi2Byte serializedState[], size_t size) {
    RETURN(instance_serialize(INST, "fmi2SerializeFMUstate", FMUstate, "FMUstate",
                              (unsigned char *)serializedState, size));
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[],
                                   size_t size, fmi2FMUstate *FMUstate) {
    RETURN(instance_deserialize(INST, "fmi2DeSerializeFMUstate",
                                (const unsigned char *)serializedState, size, FMUstate,
                                "FMUstate"));
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[],
                                        size_t nUnknown, const fmi2ValueReference vKnown_ref[],
                                        size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
    (void)vUnknown_ref;
    (void)nUnknown;
    (void)vKnown_ref;
    (void)nKnown;
    (void)dvKnown;
    (void)dvUnknown;
    RETURN(instance_refuse(INST, "fmi2GetDirectionalDerivative", STATUS_ERROR,
                           " is not provided by this FMU"));
}

/* ---------------------------------------------------------------------------------------- */
/* Model Exchange                                                                            */
/* ---------------------------------------------------------------------------------------- */

fmi2Status fmi2EnterEventMode(fmi2Component c) {
    RETURN(instance_transition(INST, "fmi2EnterEventMode", MASK(ST_EVENT) | MASK(ST_CONTINUOUS),
                               TYPE_ME, ST_EVENT));
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo) {
    if (!instance_check(INST, "fmi2NewDiscreteStates", MASK(ST_EVENT), TYPE_ME) ||
        instance_null_arg(INST, "fmi2NewDiscreteStates", eventInfo, "eventInfo"))
        return fmi2Error;
    eventInfo->newDiscreteStatesNeeded = fmi2False;
    eventInfo->terminateSimulation = fmi2False;
    eventInfo->nominalsOfContinuousStatesChanged = fmi2False;
    eventInfo->valuesOfContinuousStatesChanged = fmi2False;
    eventInfo->nextEventTimeDefined = fmi2False;
    eventInfo->nextEventTime = 0.0;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
    RETURN(instance_transition(INST, "fmi2EnterContinuousTimeMode", MASK(ST_EVENT), TYPE_ME,
                               ST_CONTINUOUS));
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c,
                                       fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode,
                                       fmi2Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint;
    const Status status = instance_completed_integrator_step(
        INST, "fmi2CompletedIntegratorStep", enterEventMode, terminateSimulation);
    if (status == STATUS_OK) *enterEventMode = *terminateSimulation = fmi2False;
    RETURN(status);
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    RETURN(instance_set_time(INST, "fmi2SetTime", time));
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    RETURN(instance_set_continuous_states(INST, "fmi2SetContinuousStates", x, "x", nx, "nx = "));
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    RETURN(instance_get_derivatives(INST, "fmi2GetDerivatives", derivatives, "derivatives", nx,
                                    "nx = "));
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    (void)eventIndicators;
    RETURN(instance_get_event_indicators(INST, "fmi2GetEventIndicators", ni));
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    RETURN(instance_get_continuous_states(INST, "fmi2GetContinuousStates", x, "x", nx, "nx = "));
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    RETURN(instance_get_nominals(INST, "fmi2GetNominalsOfContinuousStates", x_nominal,
                                 "x_nominal", nx, "nx = "));
}

/* ---------------------------------------------------------------------------------------- */
/* Co-Simulation                                                                             */
/* ---------------------------------------------------------------------------------------- */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                       size_t nvr, const fmi2Integer order[],
                                       const fmi2Real value[]) {
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    RETURN(instance_refuse(INST, "fmi2SetRealInputDerivatives", STATUS_ERROR,
                           ": canInterpolateInputs is false"));
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2Integer order[],
                                        fmi2Real value[]) {
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    RETURN(instance_refuse(INST, "fmi2GetRealOutputDerivatives", STATUS_ERROR,
                           ": maxOutputDerivativeOrder is 0"));
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentCommunicationPoint) {
    (void)noSetFMUStatePriorToCurrentCommunicationPoint;
    RETURN(instance_do_step(INST, "fmi2DoStep", currentCommunicationPoint,
                            communicationStepSize));
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    RETURN(instance_refuse(INST, "fmi2CancelStep", STATUS_ERROR,
                           ": doStep never returns fmi2Pending"));
}

/* The status queries: only the last successful time and "not terminated" exist. */
static fmi2Status no_status(fmi2Component c, const char *function) {
    RETURN(instance_refuse(INST, function, STATUS_DISCARD,
                           ": no such status (doStep is synchronous)"));
}

/* A status query with no answer at all. */
#define NO_STATUS(NAME, TYPE)                                                              \
    fmi2Status fmi2##NAME(fmi2Component c, const fmi2StatusKind s, TYPE *value) {          \
        ignore_args(0, s, value);                                                          \
        return no_status(c, "fmi2" #NAME);                                                 \
    }

NO_STATUS(GetStatus, fmi2Status)

/* A status query that has an answer when `known` (the caller then writes it). */
static fmi2Status status_query(fmi2Component c, const char *function, bool known) {
    if (!instance_check(INST, function, ANY_STATE, TYPE_ANY)) return fmi2Error;
    return known ? fmi2OK : no_status(c, function);
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    const fmi2Status status =
        status_query(c, "fmi2GetRealStatus", s == fmi2LastSuccessfulTime && value);
    if (status == fmi2OK) *value = INST->model.time;
    return status;
}

NO_STATUS(GetIntegerStatus, fmi2Integer)

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    const fmi2Status status = status_query(c, "fmi2GetBooleanStatus", s == fmi2Terminated && value);
    if (status == fmi2OK) *value = fmi2False;
    return status;
}

NO_STATUS(GetStringStatus, fmi2String)
