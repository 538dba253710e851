/*
 * FMI 3.0 glue of every C plant model: Co-Simulation and Model Exchange.
 *
 * Every entry point of the FMI 3.0 C API is defined here, as a thin adapter onto the
 * version-independent layer of instance.c (state machine, argument checks, variables, FMU
 * state, doStep, logging): this file only maps the FMI 3.0 signatures, names and callbacks
 * (Scheduled Execution, clocks and non-Float64 types are not supported and say so). Calls that
 * are out of order, carry bad arguments or would break the model's rules return fmi3Error
 * with a message sent through the environment's logMessage callback; they never crash the
 * importer. The model itself (equations, variables, integrator) lives in model.c.
 */
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "instance.h"

/* Status values are passed through unchanged: they must agree. */
typedef char status_values_agree[fmi3OK == (int)STATUS_OK && fmi3Warning == (int)STATUS_WARNING &&
                                 fmi3Discard == (int)STATUS_DISCARD &&
                                 fmi3Error == (int)STATUS_ERROR && fmi3Fatal == (int)STATUS_FATAL
                                 ? 1 : -1];

/* An FMI 3 instance: the shared instance plus the environment's logger. */
typedef struct {
    Instance base;
    fmi3InstanceEnvironment environment;
    fmi3LogMessageCallback log;
} Fmi3Instance;

#define INST ((Instance *)instance)
#define RETURN(call) return (fmi3Status)(call)

static void host_log(const Instance *inst, Status status, const char *category,
                     const char *message) {
    const Fmi3Instance *f = (const Fmi3Instance *)inst;
    if (f->log) f->log(f->environment, (fmi3Status)status, category, message);
}

static void *host_alloc(const Instance *inst, size_t size) {
    (void)inst;
    return calloc(1, size);
}

static void host_release(const Instance *inst, void *p) {
    (void)inst;
    free(p);
}

static const Host HOST = {host_log, host_alloc, host_release};

/* A zeroed instance that can only log (before or instead of instantiation). */
static void log_only(Fmi3Instance *tmp, fmi3InstanceEnvironment environment,
                     fmi3LogMessageCallback logMessage) {
    memset(tmp, 0, sizeof(*tmp));
    tmp->base.host = &HOST;
    tmp->environment = environment;
    tmp->log = logMessage;
}

static fmi3Status not_provided(fmi3Instance instance, const char *function) {
    RETURN(instance_refuse(INST, function, STATUS_ERROR, " is not provided by this FMU"));
}

/* The model has Float64 variables only: any other type is an unknown value reference. */
static fmi3Status no_such_variables(fmi3Instance instance, const char *function, size_t nvr) {
    RETURN(instance_no_such_variables(INST, function, nvr));
}

/*
 * Refused calls. PARAMS: the parameter list after `instance` (after the value references for
 * NO_SUCH_VARIABLES), in parentheses; ARGS: the names of those parameters, which are unused.
 */
#define NOT_PROVIDED(NAME, PARAMS, ARGS)                                                   \
    fmi3Status fmi3##NAME(fmi3Instance instance, UNPAREN PARAMS) {                         \
        ignore_args(0, UNPAREN ARGS);                                                      \
        return not_provided(instance, "fmi3" #NAME);                                       \
    }
#define NO_SUCH_VARIABLES(NAME, PARAMS, ARGS)                                              \
    fmi3Status fmi3##NAME(fmi3Instance instance, const fmi3ValueReference valueReferences[], \
                          size_t nValueReferences, UNPAREN PARAMS) {                       \
        ignore_args(0, valueReferences, UNPAREN ARGS);                                     \
        return no_such_variables(instance, "fmi3" #NAME, nValueReferences);                \
    }

/* ---------------------------------------------------------------------------------------- */
/* Version, logging, instantiation                                                           */
/* ---------------------------------------------------------------------------------------- */

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn,
                               size_t nCategories, const fmi3String categories[]) {
    RETURN(instance_set_debug_logging(INST, "fmi3SetDebugLogging", loggingOn, nCategories,
                                      categories));
}

static Instance *instantiate(InterfaceType type, fmi3String instanceName,
                             fmi3String instantiationToken, fmi3String resourcePath,
                             fmi3Boolean loggingOn,
                             fmi3InstanceEnvironment environment,
                             fmi3LogMessageCallback logMessage) {
    Fmi3Instance tmp;
    log_only(&tmp, environment, logMessage);
    if (!instance_check_instantiation(&tmp.base, "fmi3Instantiate", instanceName,
                                      instantiationToken, "instantiationToken"))
        return NULL;
    return instance_new(&tmp.base, sizeof(tmp), "fmi3Instantiate", type, instanceName,
                        loggingOn, resourcePath);
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName,
                                          fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible,
                                          fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)visible;
    return instantiate(TYPE_ME, instanceName, instantiationToken, resourcePath, loggingOn,
                       instanceEnvironment, logMessage);
}

fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
    fmi3Boolean earlyReturnAllowed, const fmi3ValueReference requiredIntermediateVariables[],
    size_t nRequiredIntermediateVariables, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3IntermediateUpdateCallback intermediateUpdate) {
    (void)visible;
    (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables;
    (void)intermediateUpdate;
    Instance *inst = instantiate(TYPE_CS, instanceName, instantiationToken, resourcePath,
                                 loggingOn, instanceEnvironment, logMessage);
    if (inst && nRequiredIntermediateVariables > 0) {
        LOG_ERROR(inst, "fmi3InstantiateCoSimulation: intermediate updates are not supported");
        instance_free(inst);
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
    Fmi3Instance tmp;
    log_only(&tmp, instanceEnvironment, logMessage);
    LOG_ERROR(&tmp.base, "fmi3InstantiateScheduledExecution: Scheduled Execution is not supported");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) { instance_free(INST); }

/* ---------------------------------------------------------------------------------------- */
/* Initialisation, events, termination                                                       */
/* ---------------------------------------------------------------------------------------- */

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                       fmi3Float64 tolerance, fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    const char *f = "fmi3EnterInitializationMode";
    (void)toleranceDefined;
    (void)tolerance;
    const Status status = instance_setup_experiment(INST, f, startTime, stopTimeDefined, stopTime);
    if (status != STATUS_OK) RETURN(status);
    RETURN(instance_transition(INST, f, MASK(ST_INSTANTIATED), TYPE_ANY, ST_INITIALIZATION));
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    RETURN(instance_exit_initialization(INST, "fmi3ExitInitializationMode"));
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    RETURN(instance_transition(INST, "fmi3EnterEventMode", RUNNING_STATES, TYPE_ANY, ST_EVENT));
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    RETURN(instance_transition(INST, "fmi3Terminate", RUNNING_STATES, TYPE_ANY, ST_TERMINATED));
}

fmi3Status fmi3Reset(fmi3Instance instance) { RETURN(instance_reset(INST, "fmi3Reset")); }

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) {
    /* No discrete states: a state check only. */
    return instance_check(INST, "fmi3EvaluateDiscreteStates", MASK(ST_EVENT) | MASK(ST_STEP),
                          TYPE_ANY)
               ? fmi3OK
               : fmi3Error;
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged,
                                    fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    if (!instance_check(INST, "fmi3UpdateDiscreteStates", MASK(ST_EVENT), TYPE_ANY))
        return fmi3Error;
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

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Float64 values[], size_t nValues) {
    RETURN(instance_get_float64(INST, "fmi3GetFloat64", valueReferences, "valueReferences",
                                nValueReferences, values, "values", nValues));
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Float64 values[], size_t nValues) {
    RETURN(instance_set_float64(INST, "fmi3SetFloat64", valueReferences, "valueReferences",
                                nValueReferences, values, "values", nValues));
}

#define UNSUPPORTED_GETTER(NAME, TYPE)                                                     \
    NO_SUCH_VARIABLES(Get##NAME, (TYPE values[], size_t nValues), (values, nValues))
#define UNSUPPORTED_SETTER(NAME, TYPE)                                                     \
    NO_SUCH_VARIABLES(Set##NAME, (const TYPE values[], size_t nValues), (values, nValues))

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
NO_SUCH_VARIABLES(GetBinary, (size_t valueSizes[], fmi3Binary values[], size_t nValues),
                  (valueSizes, values, nValues))
NO_SUCH_VARIABLES(SetBinary,
                  (const size_t valueSizes[], const fmi3Binary values[], size_t nValues),
                  (valueSizes, values, nValues))
NO_SUCH_VARIABLES(GetClock, (fmi3Clock values[]), (values))
NO_SUCH_VARIABLES(SetClock, (const fmi3Clock values[]), (values))

/* ---------------------------------------------------------------------------------------- */
/* Dependencies, FMU state, derivatives                                                      */
/* ---------------------------------------------------------------------------------------- */

NOT_PROVIDED(GetNumberOfVariableDependencies,
             (fmi3ValueReference valueReference, size_t *nDependencies),
             (valueReference, nDependencies))
NOT_PROVIDED(GetVariableDependencies,
             (fmi3ValueReference dependent, size_t elementIndicesOfDependent[],
              fmi3ValueReference independents[], size_t elementIndicesOfIndependents[],
              fmi3DependencyKind dependencyKinds[], size_t nDependencies),
             (dependent, elementIndicesOfDependent, independents, elementIndicesOfIndependents,
              dependencyKinds, nDependencies))

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    RETURN(instance_get_fmu_state(INST, "fmi3GetFMUState", FMUState, "FMUState"));
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    RETURN(instance_set_fmu_state(INST, "fmi3SetFMUState", FMUState, "FMUState"));
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    RETURN(instance_free_fmu_state(INST, "fmi3FreeFMUState", FMUState, "FMUState"));
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState,
                                      size_t *size) {
    (void)FMUState;
    RETURN(instance_serialized_size(INST, "fmi3SerializedFMUStateSize", size));
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState,
                                 fmi3Byte serializedState[], size_t size) {
    RETURN(instance_serialize(INST, "fmi3SerializeFMUState", FMUState, "FMUState",
                              serializedState, size));
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[],
                                   size_t size, fmi3FMUState *FMUState) {
    RETURN(instance_deserialize(INST, "fmi3DeserializeFMUState", serializedState, size,
                                FMUState, "FMUState"));
}

#define DERIVATIVE_PARAMS                                                                  \
    (const fmi3ValueReference unknowns[], size_t nUnknowns, const fmi3ValueReference knowns[], \
     size_t nKnowns, const fmi3Float64 seed[], size_t nSeed, fmi3Float64 sensitivity[],       \
     size_t nSensitivity)
#define DERIVATIVE_ARGS                                                                    \
    (unknowns, nUnknowns, knowns, nKnowns, seed, nSeed, sensitivity, nSensitivity)
NOT_PROVIDED(GetDirectionalDerivative, DERIVATIVE_PARAMS, DERIVATIVE_ARGS)
NOT_PROVIDED(GetAdjointDerivative, DERIVATIVE_PARAMS, DERIVATIVE_ARGS)

/* ---------------------------------------------------------------------------------------- */
/* Configuration mode and clocks (not supported: no structural parameters, no clocks)        */
/* ---------------------------------------------------------------------------------------- */

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) {
    return not_provided(instance, "fmi3EnterConfigurationMode");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) {
    return not_provided(instance, "fmi3ExitConfigurationMode");
}

NO_SUCH_VARIABLES(GetIntervalDecimal,
                  (fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[]),
                  (intervals, qualifiers))
NO_SUCH_VARIABLES(GetIntervalFraction,
                  (fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                   fmi3IntervalQualifier qualifiers[]),
                  (counters, resolutions, qualifiers))
NO_SUCH_VARIABLES(GetShiftDecimal, (fmi3Float64 shifts[]), (shifts))
NO_SUCH_VARIABLES(GetShiftFraction, (fmi3UInt64 counters[], fmi3UInt64 resolutions[]),
                  (counters, resolutions))
NO_SUCH_VARIABLES(SetIntervalDecimal, (const fmi3Float64 intervals[]), (intervals))
NO_SUCH_VARIABLES(SetIntervalFraction,
                  (const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]),
                  (counters, resolutions))
NO_SUCH_VARIABLES(SetShiftDecimal, (const fmi3Float64 shifts[]), (shifts))
NO_SUCH_VARIABLES(SetShiftFraction,
                  (const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]),
                  (counters, resolutions))

/* ---------------------------------------------------------------------------------------- */
/* Model Exchange                                                                            */
/* ---------------------------------------------------------------------------------------- */

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    RETURN(instance_transition(INST, "fmi3EnterContinuousTimeMode", MASK(ST_EVENT), TYPE_ME,
                               ST_CONTINUOUS));
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance,
                                       fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode,
                                       fmi3Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint;
    const Status status = instance_completed_integrator_step(
        INST, "fmi3CompletedIntegratorStep", enterEventMode, terminateSimulation);
    if (status == STATUS_OK) *enterEventMode = *terminateSimulation = fmi3False;
    RETURN(status);
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    RETURN(instance_set_time(INST, "fmi3SetTime", time));
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    RETURN(instance_set_continuous_states(INST, "fmi3SetContinuousStates", continuousStates,
                                          "continuousStates", nContinuousStates, ""));
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
    RETURN(instance_get_derivatives(INST, "fmi3GetContinuousStateDerivatives", derivatives,
                                    "derivatives", nContinuousStates, ""));
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[],
                                  size_t nEventIndicators) {
    (void)eventIndicators;
    RETURN(instance_get_event_indicators(INST, "fmi3GetEventIndicators", nEventIndicators));
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    RETURN(instance_get_continuous_states(INST, "fmi3GetContinuousStates", continuousStates,
                                          "continuousStates", nContinuousStates, ""));
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates) {
    RETURN(instance_get_nominals(INST, "fmi3GetNominalsOfContinuousStates", nominals,
                                 "nominals", nContinuousStates, ""));
}

/* The number of event indicators or continuous states (constants of the model). */
static fmi3Status get_count(fmi3Instance instance, const char *function, size_t *n,
                            const char *n_name, size_t value) {
    if (!instance_check(INST, function, ANY_STATE, TYPE_ANY) ||
        instance_null_arg(INST, function, n, n_name))
        return fmi3Error;
    *n = value;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    return get_count(instance, "fmi3GetNumberOfEventIndicators", nEventIndicators,
                     "nEventIndicators", N_EVENT_INDICATORS);
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    return get_count(instance, "fmi3GetNumberOfContinuousStates", nContinuousStates,
                     "nContinuousStates", N_STATES);
}

/* ---------------------------------------------------------------------------------------- */
/* Co-Simulation                                                                             */
/* ---------------------------------------------------------------------------------------- */

fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
    RETURN(instance_transition(INST, "fmi3EnterStepMode", MASK(ST_EVENT) | MASK(ST_STEP),
                               TYPE_CS, ST_STEP));
}

NOT_PROVIDED(GetOutputDerivatives,
             (const fmi3ValueReference valueReferences[], size_t nValueReferences,
              const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues),
             (valueReferences, nValueReferences, orders, values, nValues))

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                      fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    const char *f = "fmi3DoStep";
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!instance_check(INST, f, MASK(ST_STEP), TYPE_CS) ||
        instance_null_arg(INST, f, eventHandlingNeeded, "eventHandlingNeeded") ||
        instance_null_arg(INST, f, terminateSimulation, "terminateSimulation") ||
        instance_null_arg(INST, f, earlyReturn, "earlyReturn") ||
        instance_null_arg(INST, f, lastSuccessfulTime, "lastSuccessfulTime"))
        return fmi3Error;
    *eventHandlingNeeded = *terminateSimulation = *earlyReturn = fmi3False;
    *lastSuccessfulTime = INST->model.time;
    const Status status = instance_do_step(INST, f, currentCommunicationPoint,
                                           communicationStepSize);
    if (status <= STATUS_WARNING) *lastSuccessfulTime = INST->model.time;
    RETURN(status);
}

/* ---------------------------------------------------------------------------------------- */
/* Scheduled Execution (not supported)                                                       */
/* ---------------------------------------------------------------------------------------- */

NOT_PROVIDED(ActivateModelPartition,
             (fmi3ValueReference clockReference, fmi3Float64 activationTime),
             (clockReference, activationTime))
