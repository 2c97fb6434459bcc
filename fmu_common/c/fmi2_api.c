/* FMI 2.0 co-simulation interface of a TAPMP FMU, native or pythonfmu: maps every fmi2
 * function onto the version-neutral runtime (instance.c and the files of runtime.h), whose
 * operations check the call against the allowed-call table. Functions a co-simulation FMU
 * of this kind does not support (Boolean/String variables, derivatives, asynchronous
 * steps) return fmi2Error with a message. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "runtime.h"

#include "fmi2Functions.h"

/* The callbacks used, copied member by member: the standard's fmi2CallbackFunctions has
 * const members, so the struct itself cannot be assigned. */
typedef struct {
    fmi2CallbackLogger logger;
    fmi2ComponentEnvironment componentEnvironment;
} fmi2_callbacks;

typedef struct {
    fmi2_callbacks cb;
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
    tapmp_instance *inst = tapmp_new(instanceName, "fmi2", logger, env, loggingOn, fmuGUID);
    if (inst) inst->model_exchange = fmuType == fmi2ModelExchange;
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
    INSTANCE(c, fmi2Error);
    inst->logging_on = loggingOn;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    (void)toleranceDefined, (void)tolerance, (void)stopTimeDefined, (void)stopTime;
    INSTANCE(c, fmi2Error);
    return (fmi2Status)tapmp_setup_experiment(inst, startTime);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    INSTANCE(c, fmi2Error);
    return (fmi2Status)tapmp_enter_initialization(inst);
}
fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    INSTANCE(c, fmi2Error);
#ifdef MODEL_N_STATES
    if (inst->model_exchange) return (fmi2Status)tapmp_me_exit_initialization(inst);
#endif
    return (fmi2Status)tapmp_exit_initialization(inst);
}
fmi2Status fmi2Terminate(fmi2Component c) { INSTANCE(c, fmi2Error); return (fmi2Status)tapmp_terminate(inst); }
fmi2Status fmi2Reset(fmi2Component c) { INSTANCE(c, fmi2Error); return (fmi2Status)tapmp_reset(inst); }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[])
{
    INSTANCE(c, fmi2Error);
#ifdef MODEL_N_STATES
    for (size_t i = 0; vr && value && i < n; i++)  /* the state derivatives der(X) ... follow the variables */
        if (vr[i] >= N_VARS && vr[i] < N_VARS + MODEL_N_STATES)
            return (fmi2Status)tapmp_me_get_real(inst, N_VARS, vr, n, value, n);
#endif
    return (fmi2Status)tapmp_get_real(inst, vr, n, value, n);
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer value[])
{
    INSTANCE(c, fmi2Error);
    return (fmi2Status)tapmp_get_integer(inst, vr, n, value, n);
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[])
{
    INSTANCE(c, fmi2Error);
    return (fmi2Status)tapmp_set_real(inst, vr, n, value, n);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer value[])
{
    INSTANCE(c, fmi2Error);
    return (fmi2Status)tapmp_set_integer(inst, vr, n, value, n);
}

static fmi2Status unsupported(tapmp_instance *inst, const char *call, const char *why)
{
    return (fmi2Status)tapmp_unsupported(inst, call, why);
}

#define NO_VARIABLES(call) unsupported(inst, call, "this FMU has no variables of that type (n must be 0)")

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[])
{
    (void)vr, (void)v;
    INSTANCE(c, fmi2Error);
    return n ? NO_VARIABLES("GetBoolean") : fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[])
{
    (void)vr, (void)v;
    INSTANCE(c, fmi2Error);
    return n ? NO_VARIABLES("GetString") : fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[])
{
    (void)vr, (void)v;
    INSTANCE(c, fmi2Error);
    return n ? NO_VARIABLES("SetBoolean") : fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[])
{
    (void)vr, (void)v;
    INSTANCE(c, fmi2Error);
    return n ? NO_VARIABLES("SetString") : fmi2OK;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    INSTANCE(c, fmi2Error);
    return (fmi2Status)tapmp_get_state(inst, (tapmp_state **)state);
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    INSTANCE(c, fmi2Error);
    return (fmi2Status)tapmp_set_state(inst, (const tapmp_state *)state);
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    INSTANCE(c, fmi2Error);
    return (fmi2Status)tapmp_free_state(inst, (tapmp_state **)state);
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    INSTANCE(c, fmi2Error);
    return (fmi2Status)tapmp_serialized_size(inst, (const tapmp_state *)state, size);
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size)
{
    INSTANCE(c, fmi2Error);
    return (fmi2Status)tapmp_serialize(inst, (const tapmp_state *)state, bytes, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate *state)
{
    INSTANCE(c, fmi2Error);
    return (fmi2Status)tapmp_deserialize(inst, bytes, size, (tapmp_state **)state);
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real dv[],
                                        fmi2Real dz[])
{
    (void)u, (void)nu, (void)z, (void)nz, (void)dv, (void)dz;
    INSTANCE(c, fmi2Error);
    return unsupported(inst, "GetDirectionalDerivative", "providesDirectionalDerivative is false");
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    (void)vr, (void)n, (void)order, (void)value;
    INSTANCE(c, fmi2Error);
    return unsupported(inst, "SetRealInputDerivatives", "canInterpolateInputs is false");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real value[])
{
    (void)vr, (void)n, (void)order, (void)value;
    INSTANCE(c, fmi2Error);
    return unsupported(inst, "GetRealOutputDerivatives", "maxOutputDerivativeOrder is 0");
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    INSTANCE(c, fmi2Error);
    if (inst->model_exchange)
        return unsupported(inst, "DoStep", "the instance is a Model Exchange instance (fmuType = fmi2ModelExchange)");
    return (fmi2Status)tapmp_do_step(inst, t, h);
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    INSTANCE(c, fmi2Error);
    return unsupported(inst, "CancelStep", "doStep always completes synchronously");
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    (void)s, (void)value;
    INSTANCE(c, fmi2Error);
    return unsupported(inst, "GetStatus", "doStep always completes synchronously");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    INSTANCE(c, fmi2Error);
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
    INSTANCE(c, fmi2Error);
    return unsupported(inst, "GetIntegerStatus", "doStep always completes synchronously");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    INSTANCE(c, fmi2Error);
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
    INSTANCE(c, fmi2Error);
    return unsupported(inst, "GetStringStatus", "doStep always completes synchronously");
}

#ifdef MODEL_N_STATES
/* --- Model Exchange: the version-neutral operations of instance.c (tapmp_me_*) -------------- */

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time)
{
    INSTANCE(c, fmi2Error);
    return (fmi2Status)tapmp_me_set_time(inst, time);
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx)
{
    INSTANCE(c, fmi2Error);
    return (fmi2Status)tapmp_me_set_states(inst, x, nx);
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx)
{
    INSTANCE(c, fmi2Error);
    return (fmi2Status)tapmp_me_get_states(inst, x, nx);
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real dx[], size_t nx)
{
    INSTANCE(c, fmi2Error);
    return (fmi2Status)tapmp_me_get_derivatives(inst, dx, nx);
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real z[], size_t ni)
{
    INSTANCE(c, fmi2Error);
    return (fmi2Status)tapmp_me_event_indicators(inst, z, ni);
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx)
{
    INSTANCE(c, fmi2Error);
    return (fmi2Status)tapmp_me_nominals(inst, x_nominal, nx);
}

fmi2Status fmi2EnterEventMode(fmi2Component c)
{
    INSTANCE(c, fmi2Error);
    return (fmi2Status)tapmp_me_enter_event_mode(inst);
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info)
{
    INSTANCE(c, fmi2Error);
    int defined = 0, status = tapmp_allowed(inst, OP_ME_UPDATE);
    double next = 0.0;
    if (status == ST_OK) status = tapmp_require_pointer(inst, info, "NewDiscreteStates", "fmi2eventInfo");
    if (status == ST_OK) status = tapmp_me_update(inst, &defined, &next);
    if (status != ST_OK) return (fmi2Status)status;
    info->newDiscreteStatesNeeded = fmi2False;  /* no discrete state: the time event changes the forces only */
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2False;
    info->nextEventTimeDefined = defined ? fmi2True : fmi2False;
    info->nextEventTime = next;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c)
{
    INSTANCE(c, fmi2Error);
    return (fmi2Status)tapmp_me_enter_continuous_time_mode(inst);
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    INSTANCE(c, fmi2Error);
    int enter = 0, terminate = 0, status = tapmp_allowed(inst, OP_ME_COMPLETED_INTEGRATOR_STEP);
    if (status == ST_OK) status = tapmp_require_pointer(inst, enterEventMode, "CompletedIntegratorStep", "enterEventMode");
    if (status == ST_OK)
        status = tapmp_require_pointer(inst, terminateSimulation, "CompletedIntegratorStep", "terminateSimulation");
    if (status == ST_OK) status = tapmp_me_completed_integrator_step(inst, &enter, &terminate);
    if (status != ST_OK) return (fmi2Status)status;
    *enterEventMode = enter ? fmi2True : fmi2False;
    *terminateSimulation = terminate ? fmi2True : fmi2False;
    return fmi2OK;
}
#endif
