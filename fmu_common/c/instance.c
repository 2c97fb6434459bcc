/* Version-neutral FMU instance, its life cycle and registry, the allowed-call table and doStep; see
 * instance.h and runtime.h. The rules the runtime enforces, for every family (the native models and
 * the pythonfmu backend supply only the model operations):
 * - bad input is an error status at the call that receives it, with one logged message
 *   naming the variable, the value, the time and what is allowed; after an error every
 *   doStep is refused, so no stale or non-finite value travels on;
 * - a call the state machine does not allow in the current mode is an error: every operation begins
 *   with the one-line check ALLOW(inst, OP_...) against its row of RULES, the modes it is allowed in;
 * - doStep(t, h) needs a finite t that continues the previous step (t equals the end of
 *   the previous step, or the start time, within the absolute tapmp_time_tolerance()) and a
 *   finite h > 0 whose end t + h lies after the previous end: time only moves forward;
 *   outputs are computed, checked to be finite and only then published;
 * - an FMU state is checked whole (its mode, settings, outputs and the model's hidden
 *   values, model_check_hidden) before any of it is applied;
 * - Model Exchange: a continuous state is inside the model's domain (model_me_set_states) and the
 *   outputs it gives finite, a derivative returned is finite, SetTime never goes before the last
 *   accepted time; Continuous-Time / Event Mode, that time and a clock's tick are part of the state;
 * - a clock's tick belongs to its event: EnterStepMode with a tick not handled is an error. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef _WIN32
#define WIN32_LEAN_AND_MEAN
#include <windows.h>  /* SRWLOCK */
#else
#include <pthread.h>
#endif

#include "runtime.h"

#define INSTANCE_MAGIC 0x7A3D9C51u
/* How far [s] a doStep's communication point may lie from the instance's time: 1e-4 of the servo
 * period T_s = 1e-4 s. That is the controller's own tolerance for its sample instants
 * (TAPMP_SAMPLE_TOLERANCE T_s), so a point accepted here is the same instant to every model, and
 * it is absolute: it does not grow with the time (1e-9 |t| let 1 ms pass at t = 1e6 s). */
#define TIME_TOLERANCE 1e-8

TAPMP_DEFINITION const tapmp_var VARS[N_VARS] = MODEL_VARS_INIT;

/* Live instances: a call on, or a free of, an instance that is not live (freed already,
 * or a stray pointer) is refused without touching it. Kept compact, so the check on every
 * call scans only the live instances of this FMU in the process (usually one). FMI lets a
 * host run different instances on different threads: the registry, the one state they share,
 * is read and changed only under registry_lock. */
#define MAX_LIVE 4096
static tapmp_instance *live[MAX_LIVE];
static int n_live;
#ifdef _WIN32
static SRWLOCK registry_lock = SRWLOCK_INIT;
#define LOCK() AcquireSRWLockExclusive(&registry_lock)
#define UNLOCK() ReleaseSRWLockExclusive(&registry_lock)
#else
static pthread_mutex_t registry_lock = PTHREAD_MUTEX_INITIALIZER;
#define LOCK() pthread_mutex_lock(&registry_lock)
#define UNLOCK() pthread_mutex_unlock(&registry_lock)
#endif

static int registry_add(tapmp_instance *inst)
{
    LOCK();
    int added = n_live < MAX_LIVE;
    if (added) live[n_live++] = inst;
    UNLOCK();
    return added;
}

static void registry_remove(const tapmp_instance *inst)
{
    LOCK();
    for (int i = 0; i < n_live; i++)
        if (live[i] == inst) {
            live[i] = live[--n_live];
            break;
        }
    UNLOCK();
}

int tapmp_alive(const tapmp_instance *inst)
{
    int found = 0;
    LOCK();
    for (int i = n_live - 1; i >= 0 && !found; i--) found = live[i] == inst;
    UNLOCK();
    return found;
}

/* TIME_TOLERANCE, or at times so large that it is below 4 units in the last place of the time,
 * those: two exact ways of computing the same communication point (t0 + k h, or the previous
 * t + h) differ after rounding by up to about two of them. */
double tapmp_time_tolerance(double time)
{
    double a = fabs(time);
    return fmax(TIME_TOLERANCE, 4.0 * (nextafter(a, INFINITY) - a));
}

tapmp_instance *tapmp_new(const char *name, const char *fmi, tapmp_logger log, void *env,
                          int logging_on, const char *token)
{
    tapmp_instance *inst = calloc(1, sizeof *inst);
    if (!inst) return NULL;
    inst->name = malloc(strlen(name ? name : "") + 1);
    if (!inst->name) {
        free(inst);
        return NULL;
    }
    strcpy(inst->name, name ? name : "");
    inst->fmi = fmi;
    inst->log = log;
    inst->env = env;
    inst->logging_on = logging_on;
    inst->magic = INSTANCE_MAGIC;
    if (!token || strcmp(token, INSTANTIATION_TOKEN) != 0) {
        tapmp_log(inst, ST_ERROR, "logStatusError",
                  "%sInstantiate: %s = '%s' is not this FMU's: allowed is '%s' (the modelDescription.xml "
                  "does not belong to this binary of %s)", fmi,
                  strcmp(fmi, "fmi2") == 0 ? "fmuGUID" : "instantiationToken", token ? token : "(null)",
                  INSTANTIATION_TOKEN, MODEL_IDENTIFIER_STRING);
        tapmp_free(inst);
        return NULL;
    }
    tapmp_reset(inst);
    if (!registry_add(inst)) {
        tapmp_log(inst, ST_ERROR, "logStatusError", "%sInstantiate: more than %d live instances of %s in "
                  "this process: allowed are at most %d", fmi, MAX_LIVE, MODEL_IDENTIFIER_STRING, MAX_LIVE);
        tapmp_free(inst);
        return NULL;
    }
    return inst;
}

void tapmp_free(tapmp_instance *inst)
{
    if (!inst) return;
    registry_remove(inst);
    for (size_t i = 0; i < inst->n_states; i++) free(inst->states[i]);  /* states the master did not free */
    free(inst->states);
    inst->magic = 0;
    free(inst->name);
    free(inst);
}

/* --- the allowed-call table ------------------------------------------------------------
 * One row per operation, as the Reference FMUs' MASK_fmi3* table: the call's name in FMI 2.0 and
 * 3.0 (without the prefix), the modes it is allowed in, and those modes in the words of its refusal
 * ("fmi2DoStep is not allowed in Terminated: allowed in Step Mode ..."). Every operation begins with
 * ALLOW(inst, OP_...), which checks its row (tapmp_allowed). */
enum {
    RULE_ME = 1,                /* Model Exchange: refused for a Co-Simulation instance; modes are ME_* bits */
    RULE_EVENT_MODE_USED = 2,   /* refused for an instance without eventModeUsed (FMI 3.0) */
    RULE_ANY_AFTER_ERROR = 4,   /* allowed in every mode after an error (Terminate: the way out) */
    RULE_REFUSED_AFTER_ERROR = 8,  /* refused after an earlier error, before the mode is looked at */
    RULE_ME_NAMES = 16          /* a Model Exchange instance's mode named as Model Exchange names it */
};
#define RULE_ME_OP (RULE_ME | RULE_REFUSED_AFTER_ERROR | RULE_ME_NAMES)

typedef struct {
    const char *call[2];          /* FMI 2.0, FMI 3.0 */
    const char *what;             /* what of the call is refused, after its name (NULL: the call) */
    unsigned modes;               /* IN(mode) bits; ME_* bits for a RULE_ME row */
    const char *allowed;          /* the modes in words, after "allowed " (a RULE_ME row: from the bits) */
    const char *allowed_events;   /* the same for an instance with eventModeUsed (NULL: as allowed) */
    const char *const *hints;     /* a hint per mode the call is refused in, or NULL */
    unsigned flags;               /* RULE_* */
} tapmp_rule;

#define SETTABLE (IN(MODE_INSTANTIATED) | IN(MODE_INITIALIZATION) | IN(MODE_STEP) | IN(MODE_EVENT))
#define BEFORE_RUNNING (IN(MODE_INSTANTIATED) | IN(MODE_INITIALIZATION))
#define LEAVE_INITIALIZATION " (leave initialization first: EnterInitializationMode, ExitInitializationMode)"
static const char *const DO_STEP_HINTS[] = {LEAVE_INITIALIZATION, LEAVE_INITIALIZATION, "",
                                            " (the instance is terminated; reset it first)",
                                            " (finish the event first: fmi3UpdateDiscreteStates, fmi3EnterStepMode)"};

/* A row: the call's names, its modes and their words; ANYWHERE: allowed in every mode. */
#define RULE(fmi2, fmi3, in, words) {.call = {fmi2, fmi3}, .modes = (in), .allowed = (words)}
#define ANYWHERE(fmi2, fmi3) RULE(fmi2, fmi3, IN_ANY, NULL)
#define ME_RULE(fmi2, fmi3, in) {.call = {fmi2, fmi3}, .modes = (in), .flags = RULE_ME_OP}
/* set is refused in Terminated only; the refusal keeps the words it has always had */
#define SET_WORDS "in Instantiated, Initialization Mode or Step Mode"

static const tapmp_rule RULES[OP_COUNT] = {
    [OP_SETUP_EXPERIMENT] = RULE("SetupExperiment", "SetupExperiment", IN(MODE_INSTANTIATED), "in Instantiated"),
    [OP_ENTER_INITIALIZATION] = RULE("EnterInitializationMode", "EnterInitializationMode", IN(MODE_INSTANTIATED),
                                     "in Instantiated"),
    [OP_EXIT_INITIALIZATION] = RULE("ExitInitializationMode", "ExitInitializationMode", IN(MODE_INITIALIZATION),
                                    "in Initialization Mode"),
    [OP_DO_STEP] = {.call = {"DoStep", "DoStep"}, .modes = IN(MODE_STEP), .allowed = "in Step Mode",
                    .hints = DO_STEP_HINTS},
    [OP_TERMINATE] = {.call = {"Terminate", "Terminate"}, .modes = IN(MODE_STEP) | IN(MODE_EVENT),
                      .allowed = "in Step Mode", .allowed_events = "in Step Mode or Event Mode",
                      .flags = RULE_ANY_AFTER_ERROR},
    [OP_RESET] = ANYWHERE("Reset", "Reset"),
    [OP_GET_REAL] = ANYWHERE("GetReal", "GetFloat64"),
    [OP_GET_INTEGER] = ANYWHERE("GetInteger", "GetInt32"),
    [OP_SET_REAL] = RULE("SetReal", "SetFloat64", SETTABLE, SET_WORDS),
    [OP_SET_INTEGER] = RULE("SetInteger", "SetInt32", SETTABLE, SET_WORDS),
    /* in either interface, once the model is set up */
    [OP_GET_DERIVATIVE_VALUE] = {.call = {"GetReal", "GetFloat64"}, .what = " of a state derivative",
                                 .modes = IN(MODE_INITIALIZATION) | IN(MODE_STEP),
                                 .allowed = "from Initialization Mode on",
                                 .flags = RULE_REFUSED_AFTER_ERROR | RULE_ME_NAMES},
    [OP_GET_STATE] = ANYWHERE("GetFMUstate", "GetFMUState"),
    [OP_SET_STATE] = ANYWHERE("SetFMUstate", "SetFMUState"),
    [OP_FREE_STATE] = ANYWHERE("FreeFMUstate", "FreeFMUState"),
    [OP_STATE_SIZE] = ANYWHERE("SerializedFMUstateSize", "SerializedFMUStateSize"),
    [OP_SERIALIZE] = ANYWHERE("SerializeFMUstate", "SerializeFMUState"),
    [OP_DESERIALIZE] = ANYWHERE("DeSerializeFMUstate", "DeserializeFMUState"),
    /* Event Mode again in Event Mode: the host may announce an event it is in already */
    [OP_ENTER_EVENT_MODE] = {.call = {"EnterEventMode", "EnterEventMode"}, .modes = IN(MODE_STEP) | IN(MODE_EVENT),
                             .allowed = "in Step Mode", .flags = RULE_EVENT_MODE_USED},
    [OP_UPDATE_DISCRETE_STATES] = RULE("UpdateDiscreteStates", "UpdateDiscreteStates", IN(MODE_EVENT),
                                       "in Event Mode"),
    [OP_ENTER_STEP_MODE] = RULE("EnterStepMode", "EnterStepMode", IN(MODE_EVENT), "in Event Mode"),
#ifdef MODEL_CLOCK
    /* an input clock ticks only in Event Mode (FMI 3.0, Clocks) */
    [OP_SET_CLOCK] = RULE("SetClock", "SetClock", IN(MODE_EVENT),
                          "in Event Mode (the clock " MODEL_CLOCK_NAME " ticks at an event)"),
    [OP_GET_CLOCK] = ANYWHERE("GetClock", "GetClock"),
    [OP_GET_INTERVAL] = ANYWHERE("GetIntervalDecimal", "GetIntervalDecimal"),
    [OP_SET_INTERVAL] = RULE("SetIntervalDecimal", "SetIntervalDecimal", BEFORE_RUNNING, "in Instantiated or "
                             "Initialization Mode (the interval of the clock " MODEL_CLOCK_NAME " is fixed once the "
                             "model runs)"),
    [OP_GET_SHIFT] = ANYWHERE("GetShiftDecimal", "GetShiftDecimal"),
    [OP_SET_SHIFT] = RULE("SetShiftDecimal", "SetShiftDecimal", BEFORE_RUNNING,
                          "in Instantiated or Initialization Mode"),
#endif
    [OP_ME_SET_TIME] = ME_RULE("SetTime", "SetTime", ME_AFTER_INIT),
    [OP_ME_SET_STATES] = ME_RULE("SetContinuousStates", "SetContinuousStates", ME_AFTER_INIT),
    [OP_ME_GET_STATES] = ME_RULE("GetContinuousStates", "GetContinuousStates", ME_ANY),
    [OP_ME_GET_DERIVATIVES] = ME_RULE("GetDerivatives", "GetContinuousStateDerivatives", ME_ANY),
    [OP_ME_EVENT_INDICATORS] = ME_RULE("GetEventIndicators", "GetEventIndicators", ME_ANY),
    [OP_ME_NOMINALS] = ME_RULE("GetNominalsOfContinuousStates", "GetNominalsOfContinuousStates", ME_ANY),
    [OP_ME_ENTER_EVENT_MODE] = ME_RULE("EnterEventMode", "EnterEventMode", ME_AFTER_INIT),
    [OP_ME_ENTER_CONTINUOUS_TIME_MODE] = ME_RULE("EnterContinuousTimeMode", "EnterContinuousTimeMode", ME_EVENT),
    [OP_ME_COMPLETED_INTEGRATOR_STEP] = ME_RULE("CompletedIntegratorStep", "CompletedIntegratorStep", ME_CONTINUOUS),
    [OP_ME_UPDATE] = ME_RULE("NewDiscreteStates", "UpdateDiscreteStates", ME_EVENT),
};

const char *tapmp_call(const tapmp_instance *inst, tapmp_op op)
{
    return RULES[op].call[inst->fmi[3] == '3'];
}

/* The Model Exchange mode of inst as an ME_* bit (0: Instantiated or Terminated). */
static int me_mode_bit(const tapmp_instance *inst)
{
    if (inst->mode == MODE_INITIALIZATION) return ME_INIT;
    if (inst->mode != MODE_STEP) return 0;
    return inst->me_continuous ? ME_CONTINUOUS : ME_EVENT;
}

static const char *me_mode_name(const tapmp_instance *inst)
{
    if (inst->mode == MODE_STEP) return inst->me_continuous ? "Continuous-Time Mode" : "Event Mode";
    return tapmp_mode_name(inst->mode);
}

/* The names of the Model Exchange modes of `modes` (ME_INIT ...), joined as "in A, B and C". */
static const char *me_modes_text(unsigned modes)
{
    static const char *const texts[8] = {"in no mode", "in Initialization Mode", "in Event Mode",
                                         "in Initialization Mode and Event Mode", "in Continuous-Time Mode",
                                         "in Initialization Mode and Continuous-Time Mode",
                                         "in Event Mode and Continuous-Time Mode",
                                         "in Initialization Mode, Event Mode and Continuous-Time Mode"};
    return texts[modes & 7];
}

int tapmp_allowed(tapmp_instance *inst, tapmp_op op)
{
    const tapmp_rule *rule = &RULES[op];
    const char *call = tapmp_call(inst, op);
    int me = (rule->flags & RULE_ME) != 0;
    if (me && !inst->model_exchange)
        return tapmp_fail(inst, "%s%s is not allowed: the instance was instantiated for Co-Simulation (%s)", inst->fmi,
                          call, inst->fmi[3] == '3' ? "fmi3InstantiateCoSimulation" : "fmuType = fmi2CoSimulation");
    if ((rule->flags & RULE_EVENT_MODE_USED) && !inst->event_mode_used)
        return tapmp_fail(inst, "%s%s is not allowed: the instance was created with eventModeUsed = false (allowed: "
                          "instantiate with eventModeUsed = true)", inst->fmi, call);
    if (inst->failed && (rule->flags & RULE_REFUSED_AFTER_ERROR))
        return tapmp_fail(inst, "%s%s refused after an earlier error: %s", inst->fmi, call, inst->error);
    if (inst->failed && (rule->flags & RULE_ANY_AFTER_ERROR)) return ST_OK;
    if (rule->modes & (me ? (unsigned)me_mode_bit(inst) : IN(inst->mode))) return ST_OK;
    const char *mode = (rule->flags & RULE_ME_NAMES) && inst->model_exchange ? me_mode_name(inst)
                       : tapmp_mode_name(inst->mode);
    const char *allowed = me ? me_modes_text(rule->modes)
                          : inst->event_mode_used && rule->allowed_events ? rule->allowed_events : rule->allowed;
    return tapmp_fail(inst, "%s%s%s is not allowed in %s: allowed %s%s", inst->fmi, call,
                      rule->what ? rule->what : "", mode, allowed, rule->hints ? rule->hints[inst->mode] : "");
}
/* Range of a parameter, declared as min/max in the modelDescription (tapmp/interface.py). */
int tapmp_check_ranges(const tapmp_instance *inst, char *msg, size_t size)
{
    char v[40], lo[40], allowed[120];
    for (int vr = 0; vr < N_VARS; vr++) {
        const tapmp_var *var = &VARS[vr];
        if (var->causality != 'p') continue;
        double x = var->type == 'R' ? inst->reals[vr] : (double)inst->ints[vr];
        if (x >= var->min && x <= var->max) continue;
        if (var->type == 'R') tapmp_repr(x, v);
        else snprintf(v, sizeof v, "%d", inst->ints[vr]);
        snprintf(lo, sizeof lo, "%g", var->min);
        snprintf(allowed, sizeof allowed, "a number in [%s, %g]", lo, var->max);
        return tapmp_invalid_text(msg, size, var->name, v, allowed, 0, 0.0);
    }
    return 1;
}

int tapmp_outputs_finite(tapmp_instance *inst, const double saved[], double t, char *msg, size_t size)
{
    char v[40];
    double *out = inst->reals + MODEL_OUT_FIRST;
    for (int i = 0; i < MODEL_N_OUT; i++)
        if (!isfinite(out[i])) {
            tapmp_invalid_text(msg, size, VARS[MODEL_OUT_FIRST + i].name, tapmp_repr(out[i], v), OVERFLOW, 1, t);
            memcpy(out, saved, MODEL_N_OUT * sizeof *out);
            return 0;
        }
    return 1;
}

/* model_validate + ranges + model_setup; on failure logs "<msg> (at t = T s)" and nothing
 * is published. */
static int setup(tapmp_instance *inst)
{
    char msg[TAPMP_MESSAGE_MAX];
    double saved[MODEL_N_OUT];
    if (!model_validate(inst, msg, sizeof msg) || !tapmp_check_ranges(inst, msg, sizeof msg)) {
        return tapmp_fail(inst, "%s (at t = %.6g s)", msg, inst->time);
    }
    memcpy(saved, inst->reals + MODEL_OUT_FIRST, sizeof saved);
    model_setup(inst);
    inst->has_model = 1;
    if (inst->failed) return ST_ERROR;  /* model_setup logged an error (the Python backend can) */
    if (!tapmp_outputs_finite(inst, saved, inst->time, msg, sizeof msg)) return tapmp_fail(inst, "%s", msg);
    return ST_OK;
}

int tapmp_setup_experiment(tapmp_instance *inst, double start_time)
{
    ALLOW(inst, OP_SETUP_EXPERIMENT);
    if (!isfinite(start_time)) {
        char v[40];
        return tapmp_invalid(inst, "startTime", tapmp_repr(start_time, v), "a finite number", 0);
    }
    inst->time = start_time;
    return ST_OK;
}

int tapmp_enter_initialization(tapmp_instance *inst)
{
    ALLOW(inst, OP_ENTER_INITIALIZATION);
    inst->mode = MODE_INITIALIZATION;
    inst->dirty = 1;
    return inst->failed ? ST_ERROR : setup(inst);
}

int tapmp_exit_initialization(tapmp_instance *inst)
{
    ALLOW(inst, OP_EXIT_INITIALIZATION);
    /* FMI 3.0: with eventModeUsed the instance leaves initialization into Event Mode */
    inst->mode = inst->event_mode_used ? MODE_EVENT : MODE_STEP;
    inst->retune = inst->dirty = 0;
    if (inst->failed) return ST_ERROR;
    int status = setup(inst);
    if (status != ST_OK) return status;
    char msg[TAPMP_MESSAGE_MAX];
    double saved[MODEL_N_OUT];
    memcpy(saved, inst->reals + MODEL_OUT_FIRST, sizeof saved);
    if (!model_initial_outputs(inst, msg, sizeof msg))
        return tapmp_fail(inst, "%s (at t = %.6g s)", msg, inst->time);
    if (!tapmp_outputs_finite(inst, saved, inst->time, msg, sizeof msg)) return tapmp_fail(inst, "%s", msg);
    return ST_OK;
}

int tapmp_do_step(tapmp_instance *inst, double t, double h)
{
    ALLOW(inst, OP_DO_STEP);
    char v[40], w[40], allowed[160], msg[TAPMP_MESSAGE_MAX];
    if (inst->failed)
        return tapmp_fail(inst, "doStep at t = %.6g s refused after an earlier error: %s", t, inst->error);
    if (!isfinite(t)) return tapmp_invalid(inst, "currentCommunicationPoint", tapmp_repr(t, v),
                                           "a finite number", 0);
    if (!(isfinite(h) && h > 0.0))
        return tapmp_fail(inst, "communicationStepSize = %s is invalid: allowed is a finite number > 0 "
                          "(at t = %.6g s)", tapmp_repr(h, v), t);
    if (!isfinite(t + h))
        return tapmp_fail(inst, "communicationStepSize = %s is invalid: allowed is a step whose end t + h is "
                          "finite (at t = %.6g s)", tapmp_repr(h, v), t);
    double tol = tapmp_time_tolerance(inst->time);
    if (fabs(t - inst->time) > tol) {
        snprintf(allowed, sizeof allowed, "the end of the previous step, %s s (within %g s)",
                 tapmp_repr(inst->time, w), tol);
        return tapmp_invalid(inst, "currentCommunicationPoint", tapmp_repr(t, v), allowed, 0);
    }
    if (!(t + h > inst->time)) {  /* t within the tolerance before the time, h too small to make up for it */
        char e[40];
        return tapmp_fail(inst, "communicationStepSize = %s is invalid: allowed is a step whose end t + h = %s s "
                          "lies after the end of the previous step, %s s (time only moves forward; at t = %.6g s)",
                          tapmp_repr(h, v), tapmp_repr(t + h, e), tapmp_repr(inst->time, w), t);
    }
    double out[MODEL_N_OUT];
    ModelData before = inst->m;
    if (inst->retune) {  /* new tunable values take effect at this sample */
        if (!model_validate(inst, msg, sizeof msg) || !tapmp_check_ranges(inst, msg, sizeof msg)) {
            inst->retune = 0;
            return tapmp_fail(inst, "%s (at t = %.6g s)", msg, t);
        }
    }
    int stepped = model_step(inst, t, h, out, msg, sizeof msg);
    inst->retune = 0;  /* after model_step, which may read it (the Python models rebuild on it) */
    if (stepped < 0) {  /* a status the model answered with: nothing published, nothing logged */
        inst->m = before;
        return -stepped;
    }
    if (!stepped) {
        inst->m = before;
        return tapmp_fail(inst, "%s", msg);
    }
    for (int i = 0; i < MODEL_N_OUT; i++)
        if (!isfinite(out[i])) {
            inst->m = before;
            tapmp_invalid_text(msg, sizeof msg, VARS[MODEL_OUT_FIRST + i].name, tapmp_repr(out[i], v),
                               OVERFLOW, 1, t + h);
            return tapmp_fail(inst, "%s", msg);
        }
    memcpy(inst->reals + MODEL_OUT_FIRST, out, sizeof out);
    inst->time = t + h;
    return ST_OK;
}

int tapmp_terminate(tapmp_instance *inst)
{
    ALLOW(inst, OP_TERMINATE);
    inst->mode = MODE_TERMINATED;
    inst->clock_active = 0;  /* a tick lives in its event only */
    return ST_OK;
}

int tapmp_reset(tapmp_instance *inst)
{
    ALLOW(inst, OP_RESET);
    inst->mode = MODE_INSTANTIATED;
    inst->time = 0.0;
    inst->clock_active = inst->interval_reported = 0;
    inst->failed = inst->retune = inst->has_model = inst->dirty = 0;
    inst->error[0] = 0;
    inst->me_continuous = 0;
    inst->me_floor = 0.0;
    memset(&inst->m, 0, sizeof inst->m);
    for (int vr = 0; vr < N_VARS; vr++) {
        inst->reals[vr] = VARS[vr].type == 'R' ? VARS[vr].start : 0.0;
        inst->ints[vr] = VARS[vr].type == 'I' ? (int)VARS[vr].start : 0;
    }
    return ST_OK;
}
