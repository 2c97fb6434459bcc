/* FMI 2.0 co-simulation interface of a TAPMP FMU, native or pythonfmu: maps every fmi2
 * function onto the version-neutral instance (instance.c). Functions a co-simulation FMU
 * of this kind does not support (Boolean/String variables, derivatives, asynchronous
 * steps) return fmi2Error with a message. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "instance.h"

#include "fmi2Functions.h"

/* The callbacks used, copied member by member: the standard's fmi2CallbackFunctions has
 * const members, so the struct itself cannot be assigned. */
typedef struct {
    fmi2CallbackLogger logger;
    fmi2ComponentEnvironment componentEnvironment;
} fmi2_callbacks;

/* Model Exchange's modes after Initialization Mode (the instance itself is in Step Mode). */
enum { ME_NONE, ME_EVENT, ME_CONTINUOUS };

typedef struct {
    fmi2_callbacks cb;
    int me;            /* instantiated as fmi2ModelExchange */
    int me_mode;       /* ME_EVENT or ME_CONTINUOUS once initialized */
} fmi2_env;

#ifdef MODEL_N_STATES
#define ME_TYPES "fmi2ModelExchange (0) or fmi2CoSimulation (1) (%s offers both)"
#define ME_OFFERED 1
#else
#define ME_TYPES "fmi2CoSimulation (1); %s is a co-simulation FMU"
#define ME_OFFERED 0
#endif

static void logger(void *instance, int status, const char *category, const char *message)
{
    tapmp_instance *inst = instance;
    fmi2_env *env = inst->env;
    if (env && env->cb.logger)
        env->cb.logger(env->cb.componentEnvironment, inst->name, (fmi2Status)status, category, "%s", message);
}

/* Every call on an instance goes through here: a NULL or freed instance is refused. */
#define INSTANCE(c) tapmp_instance *inst = (tapmp_instance *)(c); if (!tapmp_alive(inst)) return fmi2Error

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    fmi2_env *env = calloc(1, sizeof *env);
    if (!env) return NULL;
    if (functions) {
        env->cb.logger = functions->logger;
        env->cb.componentEnvironment = functions->componentEnvironment;
    }
    if (fmuType != fmi2CoSimulation && !(ME_OFFERED && fmuType == fmi2ModelExchange)) {
        if (env->cb.logger)
            env->cb.logger(env->cb.componentEnvironment, instanceName, fmi2Error, "logStatusError",
                           "fmi2Instantiate: fmuType = %d is invalid: allowed is " ME_TYPES, (int)fmuType,
                           MODEL_IDENTIFIER_STRING);
        free(env);
        return NULL;
    }
    char why[1024];
    if (!model_prepare(fmuResourceLocation, why, sizeof why)) {
        if (env->cb.logger)
            env->cb.logger(env->cb.componentEnvironment, instanceName, fmi2Error, "logStatusError",
                           "fmi2Instantiate: %s", why);
        free(env);
        return NULL;
    }
    env->me = fmuType == fmi2ModelExchange;
    tapmp_instance *inst = tapmp_new(instanceName, "fmi2", logger, env, loggingOn, fmuGUID);
    if (inst && !model_instantiate(inst, fmuResourceLocation, visible)) {
        tapmp_free(inst);
        inst = NULL;
    }
    if (!inst) free(env);
    return inst;
}

void fmi2FreeInstance(fmi2Component c)
{
    tapmp_instance *inst = (tapmp_instance *)c;
    if (!tapmp_alive(inst)) return;  /* a second free, or not ours: ignored */
    void *env = inst->env;
    model_free(inst);
    tapmp_free(inst);
    free(env);
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t n, const fmi2String categories[])
{
    (void)n, (void)categories;
    INSTANCE(c);
    inst->logging_on = loggingOn;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    (void)toleranceDefined, (void)tolerance, (void)stopTimeDefined, (void)stopTime;
    INSTANCE(c);
    return (fmi2Status)tapmp_setup_experiment(inst, startTime);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) { INSTANCE(c); return (fmi2Status)tapmp_enter_initialization(inst); }
fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    INSTANCE(c);
    fmi2_env *env = inst->env;
    int status = tapmp_exit_initialization(inst);
#ifdef MODEL_N_STATES
    if (env->me && status <= ST_WARNING) {
        char msg[TAPMP_MESSAGE_MAX];
        if (!model_me_check(inst, msg, sizeof msg)) return (fmi2Status)tapmp_fail(inst, "%s", msg);
        env->me_mode = ME_EVENT;  /* FMI 2.0: Model Exchange leaves initialization into Event Mode */
    }
#endif
    (void)env;
    return (fmi2Status)status;
}
fmi2Status fmi2Terminate(fmi2Component c) { INSTANCE(c); return (fmi2Status)tapmp_terminate(inst); }
fmi2Status fmi2Reset(fmi2Component c) { INSTANCE(c); return (fmi2Status)tapmp_reset(inst); }

#ifdef MODEL_N_STATES
static fmi2Status get_state_derivatives(tapmp_instance *inst, const fmi2ValueReference vr[], size_t n,
                                        fmi2Real value[]);
#endif

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[])
{
    INSTANCE(c);
#ifdef MODEL_N_STATES
    for (size_t i = 0; vr && value && i < n; i++)  /* the state derivatives der(X) ... follow the variables */
        if (vr[i] >= N_VARS && vr[i] < N_VARS + MODEL_N_STATES) return get_state_derivatives(inst, vr, n, value);
#endif
    return (fmi2Status)tapmp_get_real(inst, vr, n, value, n);
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer value[])
{
    INSTANCE(c);
    return (fmi2Status)tapmp_get_integer(inst, vr, n, value, n);
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[])
{
    INSTANCE(c);
    return (fmi2Status)tapmp_set_real(inst, vr, n, value, n);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer value[])
{
    INSTANCE(c);
    return (fmi2Status)tapmp_set_integer(inst, vr, n, value, n);
}

static fmi2Status unsupported(tapmp_instance *inst, const char *call, const char *why)
{
    return (fmi2Status)tapmp_fail(inst, "fmi2%s is not supported: %s", call, why);
}

#define NO_VARIABLES(call) unsupported(inst, call, "this FMU has no variables of that type (n must be 0)")

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[])
{
    (void)vr, (void)v;
    INSTANCE(c);
    return n ? NO_VARIABLES("GetBoolean") : fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[])
{
    (void)vr, (void)v;
    INSTANCE(c);
    return n ? NO_VARIABLES("GetString") : fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[])
{
    (void)vr, (void)v;
    INSTANCE(c);
    return n ? NO_VARIABLES("SetBoolean") : fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[])
{
    (void)vr, (void)v;
    INSTANCE(c);
    return n ? NO_VARIABLES("SetString") : fmi2OK;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    INSTANCE(c);
    return (fmi2Status)tapmp_get_state(inst, (tapmp_state **)state);
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    INSTANCE(c);
    return (fmi2Status)tapmp_set_state(inst, (const tapmp_state *)state);
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    INSTANCE(c);
    return (fmi2Status)tapmp_free_state(inst, (tapmp_state **)state);
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    INSTANCE(c);
    return (fmi2Status)tapmp_serialized_size(inst, (const tapmp_state *)state, size);
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size)
{
    INSTANCE(c);
    return (fmi2Status)tapmp_serialize(inst, (const tapmp_state *)state, bytes, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate *state)
{
    INSTANCE(c);
    return (fmi2Status)tapmp_deserialize(inst, bytes, size, (tapmp_state **)state);
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real dv[],
                                        fmi2Real dz[])
{
    (void)u, (void)nu, (void)z, (void)nz, (void)dv, (void)dz;
    INSTANCE(c);
    return unsupported(inst, "GetDirectionalDerivative", "providesDirectionalDerivative is false");
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    (void)vr, (void)n, (void)order, (void)value;
    INSTANCE(c);
    return unsupported(inst, "SetRealInputDerivatives", "canInterpolateInputs is false");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real value[])
{
    (void)vr, (void)n, (void)order, (void)value;
    INSTANCE(c);
    return unsupported(inst, "GetRealOutputDerivatives", "maxOutputDerivativeOrder is 0");
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    INSTANCE(c);
    if (((fmi2_env *)inst->env)->me)
        return unsupported(inst, "DoStep", "the instance is a Model Exchange instance (fmuType = fmi2ModelExchange)");
    return (fmi2Status)tapmp_do_step(inst, t, h);
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    INSTANCE(c);
    return unsupported(inst, "CancelStep", "doStep always completes synchronously");
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    (void)s, (void)value;
    INSTANCE(c);
    return unsupported(inst, "GetStatus", "doStep always completes synchronously");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    INSTANCE(c);
    if (tapmp_require_pointer(inst, value, "GetRealStatus", "value") != ST_OK) return fmi2Error;
    if (s == fmi2LastSuccessfulTime) {
        *value = inst->time;
        return fmi2OK;
    }
    return unsupported(inst, "GetRealStatus", "only fmi2LastSuccessfulTime is available");
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    (void)s, (void)value;
    INSTANCE(c);
    return unsupported(inst, "GetIntegerStatus", "doStep always completes synchronously");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    INSTANCE(c);
    if (tapmp_require_pointer(inst, value, "GetBooleanStatus", "value") != ST_OK) return fmi2Error;
    if (s == fmi2Terminated) {
        *value = fmi2False;
        return fmi2OK;
    }
    return unsupported(inst, "GetBooleanStatus", "only fmi2Terminated is available");
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    (void)s, (void)value;
    INSTANCE(c);
    return unsupported(inst, "GetStringStatus", "doStep always completes synchronously");
}

#ifdef MODEL_N_STATES
/* --- Model Exchange ------------------------------------------------------------------------
 * The host integrates the model's continuous state (model_me_* hooks of the model file). No
 * event indicators: the right-hand side is smooth in the state (the Coulomb friction is
 * tanh-smoothed; the force saturation acts on the inputs, which the host sets); the one
 * discontinuity in time, the external force step at disturbance_time, is a time event. */

static const char *me_mode_name(const tapmp_instance *inst)
{
    static const char *names[] = {"Instantiated", "Initialization Mode", "", "Terminated"};
    if (inst->mode == MODE_STEP) return ((fmi2_env *)inst->env)->me_mode == ME_CONTINUOUS ? "Continuous-Time Mode"
                                                                                          : "Event Mode";
    return names[inst->mode];
}

/* ST_OK if `call` may run now: a Model Exchange instance, no earlier error, in one of the modes
 * of `modes` (bits: 1 Initialization Mode, 2 Event Mode, 4 Continuous-Time Mode, named in
 * `allowed`); else the logged error. */
static int me_allowed(tapmp_instance *inst, const char *call, int modes, const char *allowed)
{
    fmi2_env *env = inst->env;
    if (!env->me)
        return tapmp_fail(inst, "fmi2%s is not allowed: the instance was instantiated for Co-Simulation "
                          "(fmuType = fmi2CoSimulation)", call);
    if (inst->failed) return tapmp_fail(inst, "fmi2%s refused after an earlier error: %s", call, inst->error);
    int bit = inst->mode == MODE_INITIALIZATION ? 1 : inst->mode != MODE_STEP ? 0
              : env->me_mode == ME_CONTINUOUS ? 4 : 2;
    if (!(modes & bit))
        return tapmp_fail(inst, "fmi2%s is not allowed in %s: allowed in %s", call, me_mode_name(inst), allowed);
    return ST_OK;
}

/* In Initialization Mode the model follows the values set since it was last built: a get of no
 * variable rebuilds it (instance.c's initial unknowns) before a state or derivative is read. */
static void refresh(tapmp_instance *inst)
{
    if (inst->mode == MODE_INITIALIZATION) tapmp_get_real(inst, NULL, 0, NULL, 0);
}

#define AFTER_INIT 6
#define ANY_ME_MODE 7
#define AFTER_INIT_TEXT "Event Mode and Continuous-Time Mode"
#define ANY_ME_MODE_TEXT "Initialization Mode, Event Mode and Continuous-Time Mode"

static int me_array(tapmp_instance *inst, const char *call, const void *p, size_t n, size_t expected,
                    const char *what)
{
    if (n != expected)
        return tapmp_fail(inst, "fmi2%s: %s = %zu is invalid: allowed is %zu", call, what, n, expected);
    if (n && !p)
        return tapmp_fail(inst, "fmi2%s: the array = NULL is invalid: allowed is an array of %zu values", call, n);
    return ST_OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time)
{
    INSTANCE(c);
    int status = me_allowed(inst, "SetTime", AFTER_INIT, AFTER_INIT_TEXT);
    if (status != ST_OK) return (fmi2Status)status;
    char v[40];
    if (!isfinite(time)) return (fmi2Status)tapmp_invalid(inst, "time", tapmp_repr(time, v), "a finite number", 0);
    inst->time = time;
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx)
{
    INSTANCE(c);
    int status = me_allowed(inst, "SetContinuousStates", AFTER_INIT, AFTER_INIT_TEXT);
    if (status == ST_OK) status = me_array(inst, "SetContinuousStates", x, nx, MODEL_N_STATES, "nx");
    if (status != ST_OK) return (fmi2Status)status;
    char msg[TAPMP_MESSAGE_MAX];
    if (!model_me_set_states(inst, x, msg, sizeof msg)) return (fmi2Status)tapmp_fail(inst, "%s", msg);
    return fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx)
{
    INSTANCE(c);
    int status = me_allowed(inst, "GetContinuousStates", ANY_ME_MODE, ANY_ME_MODE_TEXT);
    if (status == ST_OK) status = me_array(inst, "GetContinuousStates", x, nx, MODEL_N_STATES, "nx");
    if (status != ST_OK) return (fmi2Status)status;
    refresh(inst);
    model_me_get_states(inst, x);
    return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real dx[], size_t nx)
{
    INSTANCE(c);
    int status = me_allowed(inst, "GetDerivatives", ANY_ME_MODE, ANY_ME_MODE_TEXT);
    if (status == ST_OK) status = me_array(inst, "GetDerivatives", dx, nx, MODEL_N_STATES, "nx");
    if (status != ST_OK) return (fmi2Status)status;
    double d[MODEL_N_STATES];
    refresh(inst);
    model_me_derivatives(inst, d);
    for (int i = 0; i < MODEL_N_STATES; i++)
        if (!isfinite(d[i])) {
            char v[40];
            return (fmi2Status)tapmp_fail(inst, "fmi2GetDerivatives: the derivative of state %d is %s at t = %.6g s: "
                                          "allowed is a finite number (the forces or the state are out of range)",
                                          i, tapmp_repr(d[i], v), inst->time);
        }
    memcpy(dx, d, sizeof d);
    return fmi2OK;
}

/* der(X) ... der(dB) as variables (value references N_VARS ... N_VARS + 5), with the others; in
 * either interface, once the model is set up (Initialization Mode on). */
static fmi2Status get_state_derivatives(tapmp_instance *inst, const fmi2ValueReference vr[], size_t n,
                                        fmi2Real value[])
{
    int status;
    if (inst->failed) return (fmi2Status)tapmp_fail(inst, "fmi2GetReal refused after an earlier error: %s", inst->error);
    if (inst->mode != MODE_INITIALIZATION && inst->mode != MODE_STEP)
        return (fmi2Status)tapmp_fail(inst, "fmi2GetReal of a state derivative is not allowed in %s: allowed from "
                                      "Initialization Mode on", me_mode_name(inst));
    double d[MODEL_N_STATES];
    refresh(inst);
    model_me_derivatives(inst, d);
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= N_VARS && vr[i] < N_VARS + MODEL_N_STATES) {
            value[i] = d[vr[i] - N_VARS];
            continue;
        }
        status = tapmp_get_real(inst, vr + i, 1, value + i, 1);
        if (status > ST_WARNING) return (fmi2Status)status;
    }
    return fmi2OK;
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real z[], size_t ni)
{
    (void)z;
    INSTANCE(c);
    int status = me_allowed(inst, "GetEventIndicators", ANY_ME_MODE, ANY_ME_MODE_TEXT);
    if (status == ST_OK) status = me_array(inst, "GetEventIndicators", z, ni, 0, "ni");
    return (fmi2Status)status;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx)
{
    INSTANCE(c);
    int status = me_allowed(inst, "GetNominalsOfContinuousStates", ANY_ME_MODE, ANY_ME_MODE_TEXT);
    if (status == ST_OK) status = me_array(inst, "GetNominalsOfContinuousStates", x_nominal, nx, MODEL_N_STATES, "nx");
    if (status != ST_OK) return (fmi2Status)status;
    for (size_t i = 0; i < nx; i++) x_nominal[i] = 1.0;  /* the declared nominal of every Real */
    return fmi2OK;
}

fmi2Status fmi2EnterEventMode(fmi2Component c)
{
    INSTANCE(c);
    int status = me_allowed(inst, "EnterEventMode", AFTER_INIT, AFTER_INIT_TEXT);
    if (status != ST_OK) return (fmi2Status)status;
    ((fmi2_env *)inst->env)->me_mode = ME_EVENT;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info)
{
    INSTANCE(c);
    int status = me_allowed(inst, "NewDiscreteStates", 2, "Event Mode");
    if (status == ST_OK) status = tapmp_require_pointer(inst, info, "NewDiscreteStates", "fmi2eventInfo");
    if (status != ST_OK) return (fmi2Status)status;
    double next = model_me_next_event_time(inst);
    info->newDiscreteStatesNeeded = fmi2False;  /* no discrete state: the time event changes the forces only */
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2False;
    info->nextEventTimeDefined = isfinite(next) ? fmi2True : fmi2False;
    info->nextEventTime = isfinite(next) ? next : 0.0;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c)
{
    INSTANCE(c);
    int status = me_allowed(inst, "EnterContinuousTimeMode", 2, "Event Mode");
    if (status != ST_OK) return (fmi2Status)status;
    ((fmi2_env *)inst->env)->me_mode = ME_CONTINUOUS;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    INSTANCE(c);
    int status = me_allowed(inst, "CompletedIntegratorStep", 4, "Continuous-Time Mode");
    if (status == ST_OK) status = tapmp_require_pointer(inst, enterEventMode, "CompletedIntegratorStep", "enterEventMode");
    if (status == ST_OK)
        status = tapmp_require_pointer(inst, terminateSimulation, "CompletedIntegratorStep", "terminateSimulation");
    if (status != ST_OK) return (fmi2Status)status;
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}
#endif
