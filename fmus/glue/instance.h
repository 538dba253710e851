/*
 * The FMI-version-independent layer shared by fmi2.c and fmi3.c, for every C model (the plant
 * models and the controller FMU, fmus/controller/).
 *
 * Laid out as the Modelica Reference-FMUs are: this folder (fmus/glue/) is the FMI glue every
 * model shares; a model's folder (fmus/fourtank/) holds its model.h and model.c, its model
 * descriptions and nothing about FMI. The build compiles model.c with instance.c and fmi2.c or
 * fmi3.c, the model's folder first on the include path.
 *
 * The model contract: a model's model.h defines INSTANTIATION_TOKEN,
 * N_STATES, N_EVENT_INDICATORS, N_VARIABLES (the value references are 0 .. N_VARIABLES - 1)
 * and the struct ModelData, which holds a `double time` (the model's time, written by the
 * glue) and everything else the model stores per instance (copied as plain memory for FMU
 * states); and declares the functions below, which the glue calls and the model defines:
 *
 *   void model_set_defaults(ModelData *m);              start values
 *   void model_initialize(ModelData *m);                end of initialisation
 *   const char *model_variable_name(unsigned vr);       NULL for an unknown reference
 *   double model_get(const ModelData *m, unsigned vr);
 *   const char *model_set(ModelData *m, unsigned vr, double value, bool initialized);
 *                                                       NULL or the reason of a refusal
 *   const char *model_state_name(size_t i);             name of continuous state i
 *   void model_get_states(const ModelData *m, double x[N_STATES]);
 *   void model_set_states(ModelData *m, const double x[N_STATES]);
 *   void model_get_derivatives(const ModelData *m, double dx[N_STATES]);
 *   const char *model_do_step(ModelData *m, double step, char *msg, size_t n);
 *                                                       NULL or a message (state unchanged)
 *
 * Optional parts of the contract, each switched on by a macro its model.h defines:
 *
 *   MODEL_HAS_RESOURCES   the model owns memory beyond ModelData (the controller's solver)
 *                         and may read the FMU's resources folder:
 *       const char *model_acquire(ModelData *m, const char *resources, char *msg, size_t n);
 *                                           at instantiation, after model_set_defaults;
 *                                           resources: the folder's local path (NULL when
 *                                           the environment gave none); NULL, or why it
 *                                           fails (logged; the instantiation fails)
 *       void model_release(ModelData *m);   when the instance is freed
 *     A plain copy of ModelData does not copy that memory, so such a model also defines
 *   MODEL_NO_FMU_STATE    the FMU cannot save its state (canGetAndSetFMUState="false"): the
 *                         FMU-state calls are refused with a logged reason.
 *   MODEL_HAS_WARNINGS    after each successful model_do_step the glue asks
 *       const char *model_warning(ModelData *m, char *msg, size_t n);
 *                                           until it returns NULL: each message is logged
 *                                           (logStatusWarning, one line each) and the step
 *                                           returns status Warning
 *
 * An Instance holds the model (model.h) plus the FMI bookkeeping common to FMI 2.0 and 3.0:
 * interface type, state machine, debug logging, saved FMU states. Each instance_* function
 * checks the instance (NULL), the state machine and its arguments, logs a message naming the
 * FMI function on failure, and returns a Status whose values equal fmi2Status / fmi3Status.
 * The glue files only adapt the C signatures and provide the environment's callbacks (Host).
 */
#ifndef FMU_GLUE_INSTANCE_H
#define FMU_GLUE_INSTANCE_H

#include <stdbool.h>
#include <stddef.h>

#include "model.h"

/* Numerically equal to fmi2Status and fmi3Status (checked at compile time in the glue). */
typedef enum { STATUS_OK, STATUS_WARNING, STATUS_DISCARD, STATUS_ERROR, STATUS_FATAL } Status;

typedef enum {
    ST_INSTANTIATED,
    ST_INITIALIZATION,
    ST_STEP,             /* CS: step mode (between doSteps) */
    ST_EVENT,            /* ME, or FMI 3 CS with eventModeUsed: event mode */
    ST_CONTINUOUS,       /* ME: continuous-time mode */
    ST_TERMINATED,
    ST_ERROR
} State;

#define MASK(s) (1u << (s))
#define ANY_STATE 0xFFFFu
#define SETTABLE_STATES                                                                    \
    (MASK(ST_INSTANTIATED) | MASK(ST_INITIALIZATION) | MASK(ST_STEP) | MASK(ST_EVENT) |     \
     MASK(ST_CONTINUOUS))
#define RUNNING_STATES (MASK(ST_STEP) | MASK(ST_EVENT) | MASK(ST_CONTINUOUS))

/* TYPE_ANY is only a requirement ("any interface"), never the type of an instance. */
typedef enum { TYPE_ME, TYPE_CS, TYPE_ANY } InterfaceType;

typedef struct Instance Instance;

/* The environment's services, adapted by the glue to one signature for both FMI versions. */
typedef struct {
    /* Pass a formatted message to the environment's logger (if it has one). */
    void (*log)(const Instance *inst, Status status, const char *category, const char *message);
    /* Zero-filled memory, or NULL when out of memory. */
    void *(*alloc)(const Instance *inst, size_t size);
    void (*release)(const Instance *inst, void *p);
} Host;

/*
 * The glue embeds an Instance as the FIRST member of its own struct (which adds the FMI
 * callbacks the Host functions need) and passes that struct's size to instance_new.
 */
struct Instance {
    ModelData model;
    InterfaceType type;
    State state;
    bool logging;
    bool event_mode_used;  /* FMI 3 Co-Simulation only */
    char *name;
    const Host *host;
};

/* Log a printf-style message (status OK only with debug logging on). */
void instance_log(const Instance *inst, Status status, const char *category, const char *fmt,
                  ...)
#ifdef __GNUC__
    __attribute__((format(printf, 4, 5)))
#endif
    ;

#define LOG_ERROR(inst, ...) instance_log((inst), STATUS_ERROR, "logStatusError", __VA_ARGS__)

/* True when inst is not NULL, its state is in `allowed` and its type satisfies `need`;
 * otherwise logs and returns false. */
bool instance_check(Instance *inst, const char *function, unsigned allowed, InterfaceType need);

/* True (after logging) when p is NULL. */
bool instance_null_arg(Instance *inst, const char *function, const void *p, const char *what);

/* A call this FMU refuses: logs "<function><reason>" with `status` and returns it. */
Status instance_refuse(Instance *inst, const char *function, Status status, const char *reason);

/* Any call on a variable type the model does not have (only Float64/Real exist). */
Status instance_no_such_variables(Instance *inst, const char *function, size_t nvr);

/* For the glue's refused calls: strip the parentheses of a list, mark arguments used. */
#define UNPAREN(...) __VA_ARGS__
static inline void ignore_args(int dummy, ...) { (void)dummy; }

/* ---- Life cycle ---- */

/* Check the instance name and token of an instantiate call; `tmp` only logs. */
bool instance_check_instantiation(const Instance *tmp, const char *function, const char *name,
                                  const char *token, const char *token_label);

/* Allocate `size` bytes (>= sizeof(Instance)) through tmp's host, copy `tmp` (with the glue's
 * extra fields) into it and set up a fresh instance; `resources`: the local path of the
 * FMU's resources folder, or NULL. NULL (logged) when out of memory or the model refuses. */
Instance *instance_new(const Instance *tmp, size_t size, const char *function,
                       InterfaceType type, const char *name, bool logging,
                       const char *resources);

void instance_free(Instance *inst);

Status instance_set_debug_logging(Instance *inst, const char *function, bool on,
                                  size_t nCategories, const char *const categories[]);

/* Start and stop time (FMI 2 SetupExperiment, FMI 3 EnterInitializationMode). */
Status instance_setup_experiment(Instance *inst, const char *function, double startTime,
                                 bool stopTimeDefined, double stopTime);

/* A plain state change: checks `allowed` and `need`, then moves to `next`. */
Status instance_transition(Instance *inst, const char *function, unsigned allowed,
                           InterfaceType need, State next);

Status instance_exit_initialization(Instance *inst, const char *function);

Status instance_reset(Instance *inst, const char *function);

/* ---- Variables (value references of model.h) ---- */

Status instance_get_float64(Instance *inst, const char *function, const unsigned int vr[],
                            const char *vr_name, size_t nvr, double values[],
                            const char *values_name, size_t nValues);

Status instance_set_float64(Instance *inst, const char *function, const unsigned int vr[],
                            const char *vr_name, size_t nvr, const double values[],
                            const char *values_name, size_t nValues);

/* ---- FMU state ---- */

/* state_name is the FMI argument's name (FMUstate in FMI 2, FMUState in FMI 3). */
Status instance_get_fmu_state(Instance *inst, const char *function, void **state,
                              const char *state_name);
Status instance_set_fmu_state(Instance *inst, const char *function, const void *state,
                              const char *state_name);
Status instance_free_fmu_state(Instance *inst, const char *function, void **state,
                               const char *state_name);
Status instance_serialized_size(Instance *inst, const char *function, size_t *size);
Status instance_serialize(Instance *inst, const char *function, const void *state,
                          const char *state_name, unsigned char bytes[], size_t size);
Status instance_deserialize(Instance *inst, const char *function, const unsigned char bytes[],
                            size_t size, void **state, const char *state_name);

/* ---- Model Exchange (nx_label prefixes the count in the wrong-size message) ---- */

/* Checks only: on STATUS_OK the glue sets both (non-NULL) flags to false. */
Status instance_completed_integrator_step(Instance *inst, const char *function,
                                          const void *enterEventMode,
                                          const void *terminateSimulation);
Status instance_set_time(Instance *inst, const char *function, double time);
Status instance_set_continuous_states(Instance *inst, const char *function, const double x[],
                                      const char *x_name, size_t nx, const char *nx_label);
Status instance_get_continuous_states(Instance *inst, const char *function, double x[],
                                      const char *x_name, size_t nx, const char *nx_label);
Status instance_get_derivatives(Instance *inst, const char *function, double dx[],
                                const char *dx_name, size_t nx, const char *nx_label);
Status instance_get_nominals(Instance *inst, const char *function, double nominals[],
                             const char *name, size_t nx, const char *nx_label);
Status instance_get_event_indicators(Instance *inst, const char *function, size_t ni);

/* ---- Co-Simulation ---- */

/* Check and perform a communication step with the integrator of model.c; an integrator
 * failure puts the instance in ST_ERROR. */
Status instance_do_step(Instance *inst, const char *function, double currentCommunicationPoint,
                        double communicationStepSize);

#endif /* FMU_GLUE_INSTANCE_H */
