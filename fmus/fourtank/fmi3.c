/*
 * FMI 3.0 glue for the four-tank plant: Co-Simulation and Model Exchange.
 *
 * Every entry point of the FMI 3.0 C API is defined here (Scheduled Execution, clocks and
 * non-Float64 types are not supported and say so). Calls that are out of order, carry bad
 * arguments or would break the model's rules return fmi3Error with a message sent through
 * the environment's logMessage callback; they never crash the importer. The model itself
 * (equations, variables, integrator) lives in model.c.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "model.h"

typedef enum {
    ST_INSTANTIATED,
    ST_INITIALIZATION,
    ST_STEP,             /* CS: step mode */
    ST_EVENT,            /* ME, or CS with eventModeUsed: event mode */
    ST_CONTINUOUS,       /* ME: continuous-time mode */
    ST_TERMINATED,
    ST_ERROR
} State;

static const char *const STATE_NAMES[] = {
    "Instantiated", "InitializationMode", "StepMode", "EventMode", "ContinuousTimeMode",
    "Terminated", "Error",
};

typedef enum { TYPE_ME, TYPE_CS } InterfaceType;

typedef struct {
    ModelData model;
    InterfaceType type;
    State state;
    bool logging;
    bool event_mode_used;
    char *name;
    fmi3InstanceEnvironment environment;
    fmi3LogMessageCallback log;
} Instance;

/* The saved FMU state (fmi3GetFMUState). */
typedef struct {
    ModelData model;
    State state;
} SavedState;

/* ---------------------------------------------------------------------------------------- */
/* Logging and argument checks                                                               */
/* ---------------------------------------------------------------------------------------- */

static void log_message(const Instance *inst, fmi3Status status, const char *category,
                        const char *fmt, ...) {
    if (!inst || !inst->log) return;
    if (status == fmi3OK && !inst->logging) return;
    char message[512];
    va_list args;
    va_start(args, fmt);
    vsnprintf(message, sizeof(message), fmt, args);
    va_end(args);
    inst->log(inst->environment, status, category, message);
}

#define LOG_ERROR(inst, ...) log_message((inst), fmi3Error, "logStatusError", __VA_ARGS__)

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
    Instance *inst = (Instance *)instance;                                                 \
    if (!inst) return fmi3Error;                                                           \
    if (!state_ok(inst, function, (allowed))) return fmi3Error;

static bool null_arg(Instance *inst, const char *function, const void *p, const char *what) {
    if (p) return false;
    LOG_ERROR(inst, "%s: argument %s must not be NULL", function, what);
    return true;
}

static bool require_type(Instance *inst, const char *function, InterfaceType type) {
    if (inst->type == type) return true;
    LOG_ERROR(inst, "%s is only available for %s instances", function,
              type == TYPE_CS ? "Co-Simulation" : "Model Exchange");
    return false;
}

/* ---------------------------------------------------------------------------------------- */
/* Version, logging, instantiation                                                           */
/* ---------------------------------------------------------------------------------------- */

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn,
                               size_t nCategories, const fmi3String categories[]) {
    BEGIN("fmi3SetDebugLogging", ANY_STATE)
    if (nCategories > 0 && null_arg(inst, "fmi3SetDebugLogging", categories, "categories"))
        return fmi3Error;
    for (size_t i = 0; i < nCategories; i++) {
        if (!categories[i] || (strcmp(categories[i], "logStatusError") != 0 &&
                               strcmp(categories[i], "logEvents") != 0)) {
            LOG_ERROR(inst, "fmi3SetDebugLogging: unknown log category '%s'",
                      categories[i] ? categories[i] : "(null)");
            return fmi3Error;
        }
    }
    inst->logging = loggingOn;
    return fmi3OK;
}

static Instance *instantiate(InterfaceType type, fmi3String instanceName,
                             fmi3String instantiationToken, fmi3Boolean loggingOn,
                             fmi3InstanceEnvironment environment,
                             fmi3LogMessageCallback logMessage) {
    Instance tmp;
    memset(&tmp, 0, sizeof(tmp));
    tmp.environment = environment;
    tmp.log = logMessage;
    if (!instanceName || !instanceName[0]) {
        LOG_ERROR(&tmp, "fmi3Instantiate: missing instance name");
        return NULL;
    }
    if (!instantiationToken || strcmp(instantiationToken, INSTANTIATION_TOKEN) != 0) {
        LOG_ERROR(&tmp, "fmi3Instantiate: wrong instantiationToken '%s' (expected %s)",
                  instantiationToken ? instantiationToken : "(null)", INSTANTIATION_TOKEN);
        return NULL;
    }
    Instance *inst = (Instance *)calloc(1, sizeof(Instance));
    char *name = (char *)malloc(strlen(instanceName) + 1);
    if (!inst || !name) {
        free(inst);
        free(name);
        LOG_ERROR(&tmp, "fmi3Instantiate: out of memory");
        return NULL;
    }
    strcpy(name, instanceName);
    inst->name = name;
    inst->environment = environment;
    inst->log = logMessage;
    inst->type = type;
    inst->logging = loggingOn;
    inst->state = ST_INSTANTIATED;
    model_set_defaults(&inst->model);
    return inst;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName,
                                          fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible,
                                          fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)resourcePath;
    (void)visible;
    return instantiate(TYPE_ME, instanceName, instantiationToken, loggingOn,
                       instanceEnvironment, logMessage);
}

fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
    fmi3Boolean earlyReturnAllowed, const fmi3ValueReference requiredIntermediateVariables[],
    size_t nRequiredIntermediateVariables, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3IntermediateUpdateCallback intermediateUpdate) {
    (void)resourcePath;
    (void)visible;
    (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables;
    (void)intermediateUpdate;
    Instance *inst = instantiate(TYPE_CS, instanceName, instantiationToken, loggingOn,
                                 instanceEnvironment, logMessage);
    if (inst && nRequiredIntermediateVariables > 0) {
        LOG_ERROR(inst, "fmi3InstantiateCoSimulation: intermediate updates are not supported");
        free(inst->name);
        free(inst);
        return NULL;
    }
    if (inst) inst->event_mode_used = eventModeUsed;
    return inst;
}

fmi3Instance fmi3InstantiateScheduledExecution(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
    fmi3LockPreemptionCallback lockPreemption, fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName;
    (void)instantiationToken;
    (void)resourcePath;
    (void)visible;
    (void)loggingOn;
    (void)clockUpdate;
    (void)lockPreemption;
    (void)unlockPreemption;
    Instance tmp;
    memset(&tmp, 0, sizeof(tmp));
    tmp.environment = instanceEnvironment;
    tmp.log = logMessage;
    LOG_ERROR(&tmp, "fmi3InstantiateScheduledExecution: Scheduled Execution is not supported");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) {
    Instance *inst = (Instance *)instance;
    if (!inst) return;
    free(inst->name);
    free(inst);
}

/* ---------------------------------------------------------------------------------------- */
/* Initialisation, events, termination                                                       */
/* ---------------------------------------------------------------------------------------- */

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                       fmi3Float64 tolerance, fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    BEGIN("fmi3EnterInitializationMode", MASK(ST_INSTANTIATED))
    (void)toleranceDefined;
    (void)tolerance;
    if (!isfinite(startTime)) {
        LOG_ERROR(inst, "fmi3EnterInitializationMode: startTime must be finite");
        return fmi3Error;
    }
    if (stopTimeDefined && !(stopTime >= startTime)) {
        LOG_ERROR(inst, "fmi3EnterInitializationMode: stopTime %g is before startTime %g",
                  stopTime, startTime);
        return fmi3Error;
    }
    inst->model.time = startTime;
    inst->state = ST_INITIALIZATION;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    BEGIN("fmi3ExitInitializationMode", MASK(ST_INITIALIZATION))
    model_initialize(&inst->model);
    inst->state = (inst->type == TYPE_CS && !inst->event_mode_used) ? ST_STEP : ST_EVENT;
    return fmi3OK;
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    BEGIN("fmi3EnterEventMode", MASK(ST_EVENT) | MASK(ST_CONTINUOUS) | MASK(ST_STEP))
    inst->state = ST_EVENT;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    BEGIN("fmi3Terminate", MASK(ST_STEP) | MASK(ST_EVENT) | MASK(ST_CONTINUOUS))
    inst->state = ST_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    BEGIN("fmi3Reset", ANY_STATE)
    model_set_defaults(&inst->model);
    inst->state = ST_INSTANTIATED;
    return fmi3OK;
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) {
    BEGIN("fmi3EvaluateDiscreteStates", MASK(ST_EVENT) | MASK(ST_STEP))
    return fmi3OK;  /* no discrete states */
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged,
                                    fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    BEGIN("fmi3UpdateDiscreteStates", MASK(ST_EVENT))
    if (discreteStatesNeedUpdate) *discreteStatesNeedUpdate = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (nominalsOfContinuousStatesChanged) *nominalsOfContinuousStatesChanged = fmi3False;
    if (valuesOfContinuousStatesChanged) *valuesOfContinuousStatesChanged = fmi3False;
    if (nextEventTimeDefined) *nextEventTimeDefined = fmi3False;
    if (nextEventTime) *nextEventTime = 0.0;
    return fmi3OK;
}

/* ---------------------------------------------------------------------------------------- */
/* Getting and setting variables                                                             */
/* ---------------------------------------------------------------------------------------- */

static bool check_arrays(Instance *inst, const char *function, const void *vrs, size_t nvr,
                         const void *values, size_t nValues) {
    if (null_arg(inst, function, vrs, "valueReferences") ||
        null_arg(inst, function, values, "values"))
        return false;
    if (nValues != nvr) {
        LOG_ERROR(inst, "%s: nValues = %zu, expected %zu (all variables are scalars)", function,
                  nValues, nvr);
        return false;
    }
    return true;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Float64 values[], size_t nValues) {
    BEGIN("fmi3GetFloat64", ANY_STATE)
    if (nValueReferences == 0) return fmi3OK;
    if (!check_arrays(inst, "fmi3GetFloat64", valueReferences, nValueReferences, values,
                      nValues))
        return fmi3Error;
    for (size_t i = 0; i < nValueReferences; i++) {
        if (valueReferences[i] >= N_VARIABLES) {
            LOG_ERROR(inst, "fmi3GetFloat64: unknown value reference %u",
                      (unsigned)valueReferences[i]);
            return fmi3Error;
        }
        values[i] = model_get(&inst->model, valueReferences[i]);
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Float64 values[], size_t nValues) {
    BEGIN("fmi3SetFloat64", SETTABLE_STATES)
    if (nValueReferences == 0) return fmi3OK;
    if (!check_arrays(inst, "fmi3SetFloat64", valueReferences, nValueReferences, values,
                      nValues))
        return fmi3Error;
    const bool initialized = inst->state != ST_INSTANTIATED && inst->state != ST_INITIALIZATION;
    for (size_t i = 0; i < nValueReferences; i++) {
        const unsigned vr = valueReferences[i];
        if (vr >= N_VARIABLES) {
            LOG_ERROR(inst, "fmi3SetFloat64: unknown value reference %u", vr);
            return fmi3Error;
        }
        const char *why = model_set(&inst->model, vr, values[i], initialized);
        if (why) {
            LOG_ERROR(inst, "fmi3SetFloat64: cannot set %s = %.17g: %s",
                      model_variable_name(vr), values[i], why);
            return fmi3Error;
        }
    }
    return fmi3OK;
}

/* The model has Float64 variables only: any other type is an unknown value reference. */
static fmi3Status no_such_variables(fmi3Instance instance, const char *function, size_t nvr) {
    BEGIN(function, ANY_STATE)
    if (nvr == 0) return fmi3OK;
    LOG_ERROR(inst, "%s: the model has no variables of this type", function);
    return fmi3Error;
}

#define UNSUPPORTED_GETTER(NAME, TYPE)                                                     \
    fmi3Status fmi3Get##NAME(fmi3Instance instance, const fmi3ValueReference vrs[],        \
                             size_t nvr, TYPE values[], size_t nValues) {                  \
        (void)vrs;                                                                         \
        (void)values;                                                                      \
        (void)nValues;                                                                     \
        return no_such_variables(instance, "fmi3Get" #NAME, nvr);                          \
    }
#define UNSUPPORTED_SETTER(NAME, TYPE)                                                     \
    fmi3Status fmi3Set##NAME(fmi3Instance instance, const fmi3ValueReference vrs[],        \
                             size_t nvr, const TYPE values[], size_t nValues) {            \
        (void)vrs;                                                                         \
        (void)values;                                                                      \
        (void)nValues;                                                                     \
        return no_such_variables(instance, "fmi3Set" #NAME, nvr);                          \
    }

UNSUPPORTED_GETTER(Float32, fmi3Float32)
UNSUPPORTED_GETTER(Int8, fmi3Int8)
UNSUPPORTED_GETTER(UInt8, fmi3UInt8)
UNSUPPORTED_GETTER(Int16, fmi3Int16)
UNSUPPORTED_GETTER(UInt16, fmi3UInt16)
UNSUPPORTED_GETTER(Int32, fmi3Int32)
UNSUPPORTED_GETTER(UInt32, fmi3UInt32)
UNSUPPORTED_GETTER(Int64, fmi3Int64)
UNSUPPORTED_GETTER(UInt64, fmi3UInt64)
UNSUPPORTED_GETTER(Boolean, fmi3Boolean)
UNSUPPORTED_GETTER(String, fmi3String)
UNSUPPORTED_SETTER(Float32, fmi3Float32)
UNSUPPORTED_SETTER(Int8, fmi3Int8)
UNSUPPORTED_SETTER(UInt8, fmi3UInt8)
UNSUPPORTED_SETTER(Int16, fmi3Int16)
UNSUPPORTED_SETTER(UInt16, fmi3UInt16)
UNSUPPORTED_SETTER(Int32, fmi3Int32)
UNSUPPORTED_SETTER(UInt32, fmi3UInt32)
UNSUPPORTED_SETTER(Int64, fmi3Int64)
UNSUPPORTED_SETTER(UInt64, fmi3UInt64)
UNSUPPORTED_SETTER(Boolean, fmi3Boolean)
UNSUPPORTED_SETTER(String, fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, size_t valueSizes[], fmi3Binary values[],
                         size_t nValues) {
    (void)valueReferences;
    (void)valueSizes;
    (void)values;
    (void)nValues;
    return no_such_variables(instance, "fmi3GetBinary", nValueReferences);
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues) {
    (void)valueReferences;
    (void)valueSizes;
    (void)values;
    (void)nValues;
    return no_such_variables(instance, "fmi3SetBinary", nValueReferences);
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Clock values[]) {
    (void)valueReferences;
    (void)values;
    return no_such_variables(instance, "fmi3GetClock", nValueReferences);
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, const fmi3Clock values[]) {
    (void)valueReferences;
    (void)values;
    return no_such_variables(instance, "fmi3SetClock", nValueReferences);
}

/* ---------------------------------------------------------------------------------------- */
/* Dependencies, FMU state, derivatives                                                      */
/* ---------------------------------------------------------------------------------------- */

static fmi3Status not_provided(fmi3Instance instance, const char *function) {
    BEGIN(function, ANY_STATE)
    LOG_ERROR(inst, "%s is not provided by this FMU", function);
    return fmi3Error;
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance,
                                               fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
    (void)valueReference;
    (void)nDependencies;
    return not_provided(instance, "fmi3GetNumberOfVariableDependencies");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[],
                                       fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
    (void)dependent;
    (void)elementIndicesOfDependent;
    (void)independents;
    (void)elementIndicesOfIndependents;
    (void)dependencyKinds;
    (void)nDependencies;
    return not_provided(instance, "fmi3GetVariableDependencies");
}

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    BEGIN("fmi3GetFMUState", ANY_STATE)
    if (null_arg(inst, "fmi3GetFMUState", FMUState, "FMUState")) return fmi3Error;
    SavedState *s = (SavedState *)*FMUState;
    if (!s) {
        s = (SavedState *)calloc(1, sizeof(SavedState));
        if (!s) {
            LOG_ERROR(inst, "fmi3GetFMUState: out of memory");
            return fmi3Error;
        }
    }
    s->model = inst->model;
    s->state = inst->state;
    *FMUState = s;
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    BEGIN("fmi3SetFMUState", ANY_STATE)
    if (null_arg(inst, "fmi3SetFMUState", FMUState, "FMUState")) return fmi3Error;
    const SavedState *s = (const SavedState *)FMUState;
    inst->model = s->model;
    inst->state = s->state;
    return fmi3OK;
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    BEGIN("fmi3FreeFMUState", ANY_STATE)
    if (null_arg(inst, "fmi3FreeFMUState", FMUState, "FMUState")) return fmi3Error;
    free(*FMUState);
    *FMUState = NULL;
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState,
                                      size_t *size) {
    BEGIN("fmi3SerializedFMUStateSize", ANY_STATE)
    (void)FMUState;
    if (null_arg(inst, "fmi3SerializedFMUStateSize", size, "size")) return fmi3Error;
    *size = sizeof(SavedState);
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState,
                                 fmi3Byte serializedState[], size_t size) {
    BEGIN("fmi3SerializeFMUState", ANY_STATE)
    if (null_arg(inst, "fmi3SerializeFMUState", FMUState, "FMUState") ||
        null_arg(inst, "fmi3SerializeFMUState", serializedState, "serializedState"))
        return fmi3Error;
    if (size != sizeof(SavedState)) {
        LOG_ERROR(inst, "fmi3SerializeFMUState: size must be %zu, got %zu", sizeof(SavedState),
                  size);
        return fmi3Error;
    }
    memcpy(serializedState, FMUState, sizeof(SavedState));
    return fmi3OK;
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[],
                                   size_t size, fmi3FMUState *FMUState) {
    BEGIN("fmi3DeserializeFMUState", ANY_STATE)
    if (null_arg(inst, "fmi3DeserializeFMUState", serializedState, "serializedState") ||
        null_arg(inst, "fmi3DeserializeFMUState", FMUState, "FMUState"))
        return fmi3Error;
    if (size != sizeof(SavedState)) {
        LOG_ERROR(inst, "fmi3DeserializeFMUState: size must be %zu, got %zu",
                  sizeof(SavedState), size);
        return fmi3Error;
    }
    SavedState s;
    memcpy(&s, serializedState, sizeof(s));
    if ((unsigned)s.state > ST_ERROR) {
        LOG_ERROR(inst, "fmi3DeserializeFMUState: corrupt state");
        return fmi3Error;
    }
    if (!*FMUState) {
        *FMUState = calloc(1, sizeof(SavedState));
        if (!*FMUState) {
            LOG_ERROR(inst, "fmi3DeserializeFMUState: out of memory");
            return fmi3Error;
        }
    }
    memcpy(*FMUState, &s, sizeof(s));
    return fmi3OK;
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance,
                                        const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns,
                                        const fmi3Float64 seed[], size_t nSeed,
                                        fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns;
    (void)nUnknowns;
    (void)knowns;
    (void)nKnowns;
    (void)seed;
    (void)nSeed;
    (void)sensitivity;
    (void)nSensitivity;
    return not_provided(instance, "fmi3GetDirectionalDerivative");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                    size_t nUnknowns, const fmi3ValueReference knowns[],
                                    size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                    fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns;
    (void)nUnknowns;
    (void)knowns;
    (void)nKnowns;
    (void)seed;
    (void)nSeed;
    (void)sensitivity;
    (void)nSensitivity;
    return not_provided(instance, "fmi3GetAdjointDerivative");
}

/* ---------------------------------------------------------------------------------------- */
/* Configuration mode and clocks (not supported: no structural parameters, no clocks)        */
/* ---------------------------------------------------------------------------------------- */

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) {
    return not_provided(instance, "fmi3EnterConfigurationMode");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) {
    return not_provided(instance, "fmi3ExitConfigurationMode");
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance,
                                  const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[]) {
    (void)valueReferences;
    (void)intervals;
    (void)qualifiers;
    return no_such_variables(instance, "fmi3GetIntervalDecimal", nValueReferences);
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance,
                                   const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3UInt64 counters[],
                                   fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[]) {
    (void)valueReferences;
    (void)counters;
    (void)resolutions;
    (void)qualifiers;
    return no_such_variables(instance, "fmi3GetIntervalFraction", nValueReferences);
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, fmi3Float64 shifts[]) {
    (void)valueReferences;
    (void)shifts;
    return no_such_variables(instance, "fmi3GetShiftDecimal", nValueReferences);
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance,
                                const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, fmi3UInt64 counters[],
                                fmi3UInt64 resolutions[]) {
    (void)valueReferences;
    (void)counters;
    (void)resolutions;
    return no_such_variables(instance, "fmi3GetShiftFraction", nValueReferences);
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance,
                                  const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Float64 intervals[]) {
    (void)valueReferences;
    (void)intervals;
    return no_such_variables(instance, "fmi3SetIntervalDecimal", nValueReferences);
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance,
                                   const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[]) {
    (void)valueReferences;
    (void)counters;
    (void)resolutions;
    return no_such_variables(instance, "fmi3SetIntervalFraction", nValueReferences);
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, const fmi3Float64 shifts[]) {
    (void)valueReferences;
    (void)shifts;
    return no_such_variables(instance, "fmi3SetShiftDecimal", nValueReferences);
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance,
                                const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, const fmi3UInt64 counters[],
                                const fmi3UInt64 resolutions[]) {
    (void)valueReferences;
    (void)counters;
    (void)resolutions;
    return no_such_variables(instance, "fmi3SetShiftFraction", nValueReferences);
}

/* ---------------------------------------------------------------------------------------- */
/* Model Exchange                                                                            */
/* ---------------------------------------------------------------------------------------- */

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    BEGIN("fmi3EnterContinuousTimeMode", MASK(ST_EVENT))
    if (!require_type(inst, "fmi3EnterContinuousTimeMode", TYPE_ME)) return fmi3Error;
    inst->state = ST_CONTINUOUS;
    return fmi3OK;
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance,
                                       fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode,
                                       fmi3Boolean *terminateSimulation) {
    BEGIN("fmi3CompletedIntegratorStep", MASK(ST_CONTINUOUS))
    (void)noSetFMUStatePriorToCurrentPoint;
    if (null_arg(inst, "fmi3CompletedIntegratorStep", enterEventMode, "enterEventMode") ||
        null_arg(inst, "fmi3CompletedIntegratorStep", terminateSimulation,
                 "terminateSimulation"))
        return fmi3Error;
    *enterEventMode = fmi3False;
    *terminateSimulation = fmi3False;
    return fmi3OK;
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    BEGIN("fmi3SetTime", MASK(ST_EVENT) | MASK(ST_CONTINUOUS))
    if (!require_type(inst, "fmi3SetTime", TYPE_ME)) return fmi3Error;
    if (!isfinite(time)) {
        LOG_ERROR(inst, "fmi3SetTime: time must be finite");
        return fmi3Error;
    }
    inst->model.time = time;
    return fmi3OK;
}

static bool check_nx(Instance *inst, const char *function, size_t nx) {
    if (nx == N_STATES) return true;
    LOG_ERROR(inst, "%s: the model has %d continuous states, got %zu", function, N_STATES, nx);
    return false;
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    BEGIN("fmi3SetContinuousStates", MASK(ST_EVENT) | MASK(ST_CONTINUOUS))
    if (!require_type(inst, "fmi3SetContinuousStates", TYPE_ME) ||
        !check_nx(inst, "fmi3SetContinuousStates", nContinuousStates) ||
        null_arg(inst, "fmi3SetContinuousStates", continuousStates, "continuousStates"))
        return fmi3Error;
    for (size_t i = 0; i < nContinuousStates; i++) {
        if (!isfinite(continuousStates[i])) {
            LOG_ERROR(inst, "fmi3SetContinuousStates: h%zu must be finite", i + 1);
            return fmi3Error;
        }
    }
    model_set_states(&inst->model, continuousStates);
    return fmi3OK;
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
    BEGIN("fmi3GetContinuousStateDerivatives", ANY_STATE)
    if (!require_type(inst, "fmi3GetContinuousStateDerivatives", TYPE_ME) ||
        !check_nx(inst, "fmi3GetContinuousStateDerivatives", nContinuousStates) ||
        null_arg(inst, "fmi3GetContinuousStateDerivatives", derivatives, "derivatives"))
        return fmi3Error;
    model_derivatives(&inst->model, inst->model.h, derivatives);
    return fmi3OK;
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[],
                                  size_t nEventIndicators) {
    BEGIN("fmi3GetEventIndicators", ANY_STATE)
    (void)eventIndicators;
    if (nEventIndicators != N_EVENT_INDICATORS) {
        LOG_ERROR(inst, "fmi3GetEventIndicators: the model has no event indicators, got %zu",
                  nEventIndicators);
        return fmi3Error;
    }
    return fmi3OK;
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    BEGIN("fmi3GetContinuousStates", ANY_STATE)
    if (!require_type(inst, "fmi3GetContinuousStates", TYPE_ME) ||
        !check_nx(inst, "fmi3GetContinuousStates", nContinuousStates) ||
        null_arg(inst, "fmi3GetContinuousStates", continuousStates, "continuousStates"))
        return fmi3Error;
    memcpy(continuousStates, inst->model.h, sizeof(inst->model.h));
    return fmi3OK;
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates) {
    BEGIN("fmi3GetNominalsOfContinuousStates", ANY_STATE)
    if (!require_type(inst, "fmi3GetNominalsOfContinuousStates", TYPE_ME) ||
        !check_nx(inst, "fmi3GetNominalsOfContinuousStates", nContinuousStates) ||
        null_arg(inst, "fmi3GetNominalsOfContinuousStates", nominals, "nominals"))
        return fmi3Error;
    for (size_t i = 0; i < nContinuousStates; i++) nominals[i] = 1.0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    BEGIN("fmi3GetNumberOfEventIndicators", ANY_STATE)
    if (null_arg(inst, "fmi3GetNumberOfEventIndicators", nEventIndicators, "nEventIndicators"))
        return fmi3Error;
    *nEventIndicators = N_EVENT_INDICATORS;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    BEGIN("fmi3GetNumberOfContinuousStates", ANY_STATE)
    if (null_arg(inst, "fmi3GetNumberOfContinuousStates", nContinuousStates,
                 "nContinuousStates"))
        return fmi3Error;
    *nContinuousStates = N_STATES;
    return fmi3OK;
}

/* ---------------------------------------------------------------------------------------- */
/* Co-Simulation                                                                             */
/* ---------------------------------------------------------------------------------------- */

fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
    BEGIN("fmi3EnterStepMode", MASK(ST_EVENT) | MASK(ST_STEP))
    if (!require_type(inst, "fmi3EnterStepMode", TYPE_CS)) return fmi3Error;
    inst->state = ST_STEP;
    return fmi3OK;
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance,
                                    const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[],
                                    fmi3Float64 values[], size_t nValues) {
    (void)valueReferences;
    (void)nValueReferences;
    (void)orders;
    (void)values;
    (void)nValues;
    return not_provided(instance, "fmi3GetOutputDerivatives");
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                      fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    BEGIN("fmi3DoStep", MASK(ST_STEP))
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!require_type(inst, "fmi3DoStep", TYPE_CS)) return fmi3Error;
    if (null_arg(inst, "fmi3DoStep", eventHandlingNeeded, "eventHandlingNeeded") ||
        null_arg(inst, "fmi3DoStep", terminateSimulation, "terminateSimulation") ||
        null_arg(inst, "fmi3DoStep", earlyReturn, "earlyReturn") ||
        null_arg(inst, "fmi3DoStep", lastSuccessfulTime, "lastSuccessfulTime"))
        return fmi3Error;
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    *lastSuccessfulTime = inst->model.time;
    if (!isfinite(communicationStepSize) || communicationStepSize < 0.0) {
        LOG_ERROR(inst, "fmi3DoStep: communicationStepSize must be finite and >= 0, got %g",
                  communicationStepSize);
        return fmi3Error;
    }
    const double t = inst->model.time;
    if (!isfinite(currentCommunicationPoint) ||
        fabs(currentCommunicationPoint - t) > 1e-9 * (1.0 + fabs(t))) {
        LOG_ERROR(inst, "fmi3DoStep: currentCommunicationPoint = %.17g, expected %.17g",
                  currentCommunicationPoint, t);
        return fmi3Error;
    }
    inst->model.time = currentCommunicationPoint; /* absorb the master's round-off */
    if (communicationStepSize > 0.0) {
        char msg[256];
        if (model_do_step(&inst->model, communicationStepSize, msg, sizeof(msg))) {
            LOG_ERROR(inst, "fmi3DoStep: %s", msg);
            inst->state = ST_ERROR;
            return fmi3Error;
        }
    }
    *lastSuccessfulTime = inst->model.time;
    return fmi3OK;
}

/* ---------------------------------------------------------------------------------------- */
/* Scheduled Execution (not supported)                                                       */
/* ---------------------------------------------------------------------------------------- */

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    (void)clockReference;
    (void)activationTime;
    return not_provided(instance, "fmi3ActivateModelPartition");
}
