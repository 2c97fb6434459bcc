/* The FMI-version-neutral part of every TAPMP FMU: one instance's values, the
 * state machine, error reporting and the FMU state (the runtime's files by concern:
 * runtime.h). fmi2_api.c and fmi3_api.c map the FMI 2.0 and 3.0 functions onto it. The model operations declared at
 * the end are supplied by the model file: in C for the native FMUs (plant.c, controller.c
 * or trajectory.c), by calling into Python for the pythonfmu FMUs
 * (fmu_common/pyfront/python_model.c), so both families follow the same rules.
 *
 * The variable table (names, causality, variability, type, start, min, max; the value
 * reference is the index) is generated from tapmp/interface.py into model_vars.h at
 * build time, so every family of FMUs has the same interface. */
#ifndef TAPMP_INSTANCE_H
#define TAPMP_INSTANCE_H

#include <stddef.h>

typedef struct {
    const char *name;
    char causality;    /* 'i' input, 'o' output, 'p' parameter */
    char variability;  /* 'f' fixed, 't' tunable, 'c' continuous, 'd' discrete */
    char type;         /* 'R' Real / Float64, 'I' Integer / Int32 */
    double start, min, max;
} tapmp_var;

/* Generated per FMU: the model's header (ModelData, MODEL_N_HIDDEN, MODEL_N_OUT,
 * MODEL_OUT_FIRST), N_VARS, the VR_<name> value references, MODEL_VARS_INIT,
 * MODEL_IDENTIFIER_STRING and INSTANTIATION_TOKEN. */
#include "model_vars.h"

/* MODE_EVENT: FMI 3.0's Event Mode (a co-simulation instance with eventModeUsed); it comes last so
 * that the modes of FMU states saved before it existed keep their numbers. */
typedef enum { MODE_INSTANTIATED, MODE_INITIALIZATION, MODE_STEP, MODE_TERMINATED, MODE_EVENT } tapmp_mode;
#define MODE_LAST MODE_EVENT
/* Step Mode or Event Mode: the model is running (fixed parameters are fixed, tunable ones retune). */
#define MODE_RUNNING(mode) ((mode) == MODE_STEP || (mode) == MODE_EVENT)

/* Status codes shared by FMI 2.0 and 3.0 (OK, Warning, Discard, Error, Fatal). */
enum { ST_OK = 0, ST_WARNING = 1, ST_DISCARD = 2, ST_ERROR = 3, ST_FATAL = 4 };

/* Where log messages go; set by the FMI layer. */
typedef void (*tapmp_logger)(void *instance, int status, const char *category, const char *message);

#define TAPMP_MESSAGE_MAX 1024

typedef struct tapmp_instance {
    /* identity and callbacks: never part of an FMU state */
    char *name;
    const char *fmi;        /* "fmi2" or "fmi3": prefix of call names in messages */
    tapmp_logger log;
    void *env;              /* the FMI layer's callback data */
    int logging_on;
    unsigned magic;         /* INSTANCE_MAGIC while alive (double free detection) */
    struct tapmp_state **states;  /* the FMU states this instance handed out and has not freed */
    void *backend;          /* the model's resources outside the instance (the Python object), or NULL */
    size_t n_states, max_states;
    int event_mode_used;       /* FMI 3.0 co-simulation: the host handles the model's events in Event Mode */
    int early_return_allowed;  /* FMI 3.0 co-simulation: doStep may return early at an event */
    int model_exchange;        /* instantiated for Model Exchange (the host integrates the state) */
    int interval_reported;     /* MODEL_CLOCK: fmi3GetInterval* has reported the interval once */
    /* everything below is the FMU state */
    tapmp_mode mode;
    int me_continuous;         /* Model Exchange after initialization: Continuous-Time Mode (1) or Event Mode (0) */
    double me_floor;           /* Model Exchange: the last accepted time [s] (initialization, an event or a
                                * completed integrator step); fmi*SetTime refuses a time before it */
    int clock_active;          /* MODEL_CLOCK: the input clock was activated in this Event Mode (fmi3SetClock) */
    double time;            /* current communication point [s] */
    int failed;             /* an error was reported: doStep is refused from then on */
    int retune;             /* a tunable parameter changed in Step Mode */
    int has_model;          /* the model has been set up */
    int dirty;              /* a value was set in Initialization Mode since the outputs were computed */
    double reals[N_VARS];
    int ints[N_VARS];
    ModelData m;
    char error[TAPMP_MESSAGE_MAX];  /* the first error */
} tapmp_instance;

TAPMP_LINKAGE const tapmp_var VARS[N_VARS];

/* Python's repr() of a float ("0.1", "1e-05", "inf") into buf (>= 32 bytes); returns buf. */
TAPMP_LINKAGE char *tapmp_repr(double x, char *buf);

/* Life cycle */
TAPMP_LINKAGE tapmp_instance *tapmp_new(const char *name, const char *fmi, tapmp_logger log, void *env,
                          int logging_on, const char *token);
TAPMP_LINKAGE void tapmp_free(tapmp_instance *inst);
TAPMP_LINKAGE int tapmp_alive(const tapmp_instance *inst);

/* Logging: an error is always passed on and recorded (the first one) in inst->error. */
TAPMP_LINKAGE void tapmp_log(tapmp_instance *inst, int status, const char *category, const char *fmt, ...);
TAPMP_LINKAGE int tapmp_fail(tapmp_instance *inst, const char *fmt, ...);
/* "NAME = VALUE[ at t = T s] is invalid: allowed is ALLOWED[ (at t = T s)]" as
 * tapmp.errors.ModelInputError and fmu_common/slave.py write it; returns ST_ERROR. */
TAPMP_LINKAGE int tapmp_invalid(tapmp_instance *inst, const char *name, const char *value, const char *allowed,
                  int time_in_value);
/* The same with the message only written to buf (no logging); returns 0. */
TAPMP_LINKAGE int tapmp_invalid_text(char *buf, size_t size, const char *name, const char *value,
                       const char *allowed, int has_time, double time);
/* The result of one of the C model's range checks (tapmp_*_check): 1 if it found nothing
 * (`kind` 0), else 0 with its message in msg (the value of an integer, kind 2, as an integer;
 * kind 3, outside the kinematic domain, as a real). */
TAPMP_LINKAGE int tapmp_range_text(int kind, const char *name, double value, const char *allowed, char *msg,
                                   size_t size);

/* FMI operations, version neutral; each returns a status. */
TAPMP_LINKAGE int tapmp_setup_experiment(tapmp_instance *inst, double start_time);
TAPMP_LINKAGE int tapmp_enter_initialization(tapmp_instance *inst);
TAPMP_LINKAGE int tapmp_exit_initialization(tapmp_instance *inst);
TAPMP_LINKAGE int tapmp_do_step(tapmp_instance *inst, double t, double h);
TAPMP_LINKAGE int tapmp_terminate(tapmp_instance *inst);
TAPMP_LINKAGE int tapmp_reset(tapmp_instance *inst);
/* Events (FMI 3.0 Event Mode; model-neutral: the model supplies model_next_event and
 * model_event_update). Enter Event Mode from Step Mode (co-simulation with eventModeUsed); the
 * discrete update at the current time, publishing the outputs and saying when the next time event
 * is (*next_defined, *next_time [s]); back to Step Mode. */
TAPMP_LINKAGE int tapmp_enter_event_mode(tapmp_instance *inst);
TAPMP_LINKAGE int tapmp_update_discrete_states(tapmp_instance *inst, int *values_changed, int *next_defined,
                                               double *next_time);
TAPMP_LINKAGE int tapmp_enter_step_mode(tapmp_instance *inst);
/* doStep(t, h) of an instance with eventModeUsed: a step that would pass the model's next time
 * event ends there (*early_return = 1 if earlyReturnAllowed, an error otherwise), and one that reaches
 * it asks for event handling; *last_time [s] is the time reached. Without eventModeUsed: tapmp_do_step. */
TAPMP_LINKAGE int tapmp_do_step_events(tapmp_instance *inst, double t, double h, int *event_needed,
                                       int *early_return, double *last_time);
/* The model's periodic input clock (FMI 3.0; MODEL_CLOCK defined in the model's header: the clocked
 * controller). Its value reference is MODEL_CLOCK_VR, its interval model_clock_interval() [s] (a fixed
 * parameter), its shift 0 (ticks at t0 + k interval). Set: only in Event Mode, and only the clock; an
 * activation holds until fmi3UpdateDiscreteStates, where the model samples (model_event_update sees
 * inst->clock_active), and ends there; fmi3EnterStepMode with an activation not handled is an error
 * (tapmp_enter_step_mode), so no tick outlives its event. Interval: read any time after instantiation; set only before
 * Step Mode and only to the interval the model has. Shift: 0, settable only to 0. */
#ifdef MODEL_CLOCK
TAPMP_LINKAGE int tapmp_set_clock(tapmp_instance *inst, const unsigned vr[], size_t n, const int v[]);
TAPMP_LINKAGE int tapmp_get_clock(tapmp_instance *inst, const unsigned vr[], size_t n, int v[]);
/* qualifier[i]: 2 (changed: first report), 1 (unchanged since the last report) */
TAPMP_LINKAGE int tapmp_get_interval(tapmp_instance *inst, const unsigned vr[], size_t n, double interval[],
                                     int qualifier[]);
TAPMP_LINKAGE int tapmp_set_interval(tapmp_instance *inst, const unsigned vr[], size_t n, const double interval[]);
TAPMP_LINKAGE int tapmp_get_shift(tapmp_instance *inst, const unsigned vr[], size_t n, double shift[]);
TAPMP_LINKAGE int tapmp_set_shift(tapmp_instance *inst, const unsigned vr[], size_t n, const double shift[]);
TAPMP_LINKAGE double model_clock_interval(const tapmp_instance *inst);
#endif
/* Get and set: `nv` is the number of values in v (FMI 3.0's nValues; FMI 2.0 passes n).
 * Every variable is a scalar, so nv must equal n; vr and v may be NULL only for n = 0. */
TAPMP_LINKAGE int tapmp_get_real(tapmp_instance *inst, const unsigned vr[], size_t n, double v[], size_t nv);
TAPMP_LINKAGE int tapmp_get_integer(tapmp_instance *inst, const unsigned vr[], size_t n, int v[], size_t nv);
TAPMP_LINKAGE int tapmp_set_real(tapmp_instance *inst, const unsigned vr[], size_t n, const double v[], size_t nv);
TAPMP_LINKAGE int tapmp_set_integer(tapmp_instance *inst, const unsigned vr[], size_t n, const int v[], size_t nv);
/* An output pointer argument (size, value) of `call` that must not be NULL; ST_OK or the error. */
TAPMP_LINKAGE int tapmp_require_pointer(tapmp_instance *inst, const void *p, const char *call, const char *what);

/* FMU state: a copy of the instance from `mode` on. A state belongs to the instance that
 * made it (GetFMUstate, DeSerializeFMUstate): every call with a state checks that it is one
 * this instance holds, without reading it, so a state of another instance, a freed state or
 * a stray pointer is refused; FreeInstance frees the states still held. */
typedef struct tapmp_state tapmp_state;
TAPMP_LINKAGE int tapmp_get_state(tapmp_instance *inst, tapmp_state **state);
TAPMP_LINKAGE int tapmp_set_state(tapmp_instance *inst, const tapmp_state *state);
TAPMP_LINKAGE int tapmp_free_state(tapmp_instance *inst, tapmp_state **state);
TAPMP_LINKAGE int tapmp_serialized_size(tapmp_instance *inst, const tapmp_state *state, size_t *size);
TAPMP_LINKAGE int tapmp_serialize(tapmp_instance *inst, const tapmp_state *state, char *bytes, size_t size);
TAPMP_LINKAGE int tapmp_deserialize(tapmp_instance *inst, const char *bytes, size_t size, tapmp_state **state);

/* --- hooks of the model file ------------------------------------------------------ */
/* Check the parameters as the Python model's validated() does, in the same order; on
 * failure write the message (tapmp_invalid_text) to msg and return 0. */
TAPMP_LINKAGE int model_validate(const tapmp_instance *inst, char *msg, size_t size);
/* Build the model from the parameters (after model_validate) and publish the outputs
 * that do not depend on inputs. */
TAPMP_LINKAGE void model_setup(tapmp_instance *inst);
/* Outputs that depend on inputs at the end of initialization (controller); 0 + msg on error. */
TAPMP_LINKAGE int model_initial_outputs(tapmp_instance *inst, char *msg, size_t size);
/* Advance from t to t + h [s]; compute the outputs into out (MODEL_N_OUT values, in the
 * order of the output block) without publishing; 1, or 0 + msg on error, or -status for a
 * status the model answers with itself (nothing published or logged: a Python model may). */
TAPMP_LINKAGE int model_step(tapmp_instance *inst, double t, double h, double out[], char *msg, size_t size);
/* Hidden state (not a variable) as MODEL_N_HIDDEN doubles, and back. model_set_hidden also
 * builds a deserialized state's model data; it must not touch any live instance's model. */
TAPMP_LINKAGE void model_get_hidden(const tapmp_instance *inst, double hidden[]);
TAPMP_LINKAGE void model_set_hidden(tapmp_instance *inst, const double hidden[]);
/* Check the hidden values of an FMU state (hidden, in model_get_hidden's layout; finite) against
 * the state's settings (already checked), outputs and time in `state`, without changing anything:
 * inside the model's domain and the bounds the settings allow. 1, or 0 + msg naming the value. */
TAPMP_LINKAGE int model_check_hidden(const tapmp_instance *state, const double hidden[], char *msg, size_t size);

/* A model with time events (MODEL_HAS_EVENTS defined in its header: the controller's sample
 * instants) supplies these; for the others there are none. model_next_event: 1 and the time [s] of
 * the next event after the ones handled, or 0 if none is scheduled. model_event_update: the model's
 * discrete update at inst->time in Event Mode, the outputs into out (as model_step); 1, or 0 + msg. */
#ifdef MODEL_HAS_EVENTS
TAPMP_LINKAGE int model_next_event(const tapmp_instance *inst, double *time);
TAPMP_LINKAGE int model_event_update(tapmp_instance *inst, double out[], char *msg, size_t size);
#else
#define model_next_event(inst, time) ((void)(inst), (void)(time), 0)
#define model_event_update(inst, out, msg, size) \
    ((void)(msg), (void)(size), memcpy((out), (inst)->reals + MODEL_OUT_FIRST, MODEL_N_OUT * sizeof(double)), 1)
#endif

/* Model Exchange, for a model that defines MODEL_N_STATES (the plant): its continuous state
 * (MODEL_N_STATES values), set by the host's integrator (1, or 0 + msg if it is outside the
 * model's domain; the outputs follow it), its derivatives at inst->time for the inputs set now,
 * the time of its next time event (INFINITY: none), and whether the settings suit Model
 * Exchange (1, or 0 + msg). The tapmp_me_* operations below build the FMI 2.0 and 3.0 Model
 * Exchange functions (fmi2_api.c, fmi3_api.c) on them. */
#ifdef MODEL_N_STATES
TAPMP_LINKAGE void model_me_get_states(const tapmp_instance *inst, double x[]);
TAPMP_LINKAGE int model_me_set_states(tapmp_instance *inst, const double x[], char *msg, size_t size);
TAPMP_LINKAGE void model_me_derivatives(const tapmp_instance *inst, double dx[]);
TAPMP_LINKAGE double model_me_next_event_time(const tapmp_instance *inst);
TAPMP_LINKAGE int model_me_check(const tapmp_instance *inst, char *msg, size_t size);

/* Model Exchange operations, FMI version neutral; each returns a status. The modes each is
 * allowed in (Initialization Mode, Event Mode, Continuous-Time Mode) are its row of the
 * allowed-call table (instance.c). No event indicators: the right-hand side is smooth in the state
 * (the Coulomb friction is tanh-smoothed; the force saturation acts on the inputs, which the host
 * sets); the one discontinuity in time, the external force step at disturbance_time, is a time
 * event. */
/* ExitInitializationMode of a Model Exchange instance: as tapmp_exit_initialization, then the
 * settings checked for Model Exchange (model_me_check); it leaves into Event Mode. */
TAPMP_LINKAGE int tapmp_me_exit_initialization(tapmp_instance *inst);
/* SetTime [s]: Event Mode and Continuous-Time Mode; finite and never before inst->me_floor, the last
 * accepted time (the end of initialization, an event, EnterContinuousTimeMode or CompletedIntegratorStep
 * sets it): an integrator may go back over a step it rejects, not before the last point it accepted. */
TAPMP_LINKAGE int tapmp_me_set_time(tapmp_instance *inst, double time);
/* The continuous state (nx = MODEL_N_STATES values): set (after initialization), get (from
 * Initialization Mode on); their derivatives at the instance's time for the inputs set now. */
TAPMP_LINKAGE int tapmp_me_set_states(tapmp_instance *inst, const double x[], size_t nx);
TAPMP_LINKAGE int tapmp_me_get_states(tapmp_instance *inst, double x[], size_t nx);
TAPMP_LINKAGE int tapmp_me_get_derivatives(tapmp_instance *inst, double dx[], size_t nx);
/* GetReal / GetFloat64 when a value reference is one of the state derivatives: those are the
 * variables first, first + 1, ... (MODEL_N_STATES of them), the others are got as usual. */
TAPMP_LINKAGE int tapmp_me_get_real(tapmp_instance *inst, unsigned first, const unsigned vr[], size_t n,
                                    double v[], size_t nv);
/* The event indicators (ni must be 0) and the states' nominal values (1, as declared). */
TAPMP_LINKAGE int tapmp_me_event_indicators(tapmp_instance *inst, double z[], size_t ni);
TAPMP_LINKAGE int tapmp_me_nominals(tapmp_instance *inst, double nominals[], size_t nx);
/* EnterEventMode, EnterContinuousTimeMode, CompletedIntegratorStep (*enter_event_mode,
 * *terminate: never), and the event update in Event Mode (no discrete state changes; the next
 * time event: *next_defined, *next_time [s]). */
TAPMP_LINKAGE int tapmp_me_enter_event_mode(tapmp_instance *inst);
TAPMP_LINKAGE int tapmp_me_enter_continuous_time_mode(tapmp_instance *inst);
TAPMP_LINKAGE int tapmp_me_completed_integrator_step(tapmp_instance *inst, int *enter_event_mode, int *terminate);
TAPMP_LINKAGE int tapmp_me_update(tapmp_instance *inst, int *next_defined, double *next_time);
#endif

/* A model whose instances hold resources outside the instance (the pythonfmu family: a
 * Python object) defines MODEL_OWN_RESOURCES in its header and these; for the others they
 * do nothing. model_prepare runs before the instance exists (0 + why on failure: logged as
 * the fmi2Instantiate error); model_instantiate sets inst->backend (0 on failure, logged);
 * model_capture brings the hidden state into inst->m before an FMU state copies it. */
#ifdef MODEL_OWN_RESOURCES
TAPMP_LINKAGE int model_prepare(const char *resource_location, char *why, size_t size);
TAPMP_LINKAGE int model_instantiate(tapmp_instance *inst, const char *resource_location, int visible);
TAPMP_LINKAGE void model_capture(tapmp_instance *inst);
TAPMP_LINKAGE void model_free(tapmp_instance *inst);
/* A non-finite value for input vr: -1 (refused with the error), or a status the model answers with. */
TAPMP_LINKAGE int model_input_status(tapmp_instance *inst, unsigned vr, double value);
#else
#define model_input_status(inst, vr, value) ((void)(inst), (void)(vr), (void)(value), -1)
#define model_prepare(resource_location, why, size) ((void)(resource_location), (void)(why), (void)(size), 1)
#define model_instantiate(inst, resource_location, visible) ((void)(resource_location), (void)(visible), 1)
#define model_capture(inst) ((void)(inst))
#define model_free(inst) ((void)(inst))
#endif

#endif
