/* FMI 3.0 co-simulation interface of a native TAPMP FMU: maps the fmi3 functions onto the
 * version-neutral instance (instance.c). Variables are Float64 and Int32; the independent
 * variable `time` has the value reference N_VARS. A model with time events (MODEL_HAS_EVENTS: the
 * controller) has Event Mode (hasEventMode, mightReturnEarlyFromDoStep); the others refuse
 * eventModeUsed. A model with a periodic input clock (MODEL_CLOCK: the clocked controller) has the clock
 * functions and requires eventModeUsed. A model with a continuous state (MODEL_N_STATES: the plant) is
 * offered for Model Exchange too, under the same model identifier (model_exchange.c's tapmp_me_* operations,
 * shared with FMI 2.0; fmi3_model_exchange.c); its time derivatives der(X) ... are the Float64 variables
 * N_VARS + 1 ... The clock functions are in fmi3_clocks.c.
 * Scheduled Execution, other clocks, derivatives and, for the other models, Model Exchange are not
 * provided:
 * those calls return fmi3Error with a message (their capability flags are false in the
 * modelDescription). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "runtime.h"
#include "fmi3Functions.h"
#include "fmi3_events.h"

typedef struct {
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
} fmi3_env;

static void logger(void *instance, int status, const char *category, const char *message)
{
    tapmp_instance *inst = instance;
    fmi3_env *env = inst->env;
    if (env && env->log) env->log(env->env, (fmi3Status)status, category, message);
}

#define unsupported(c, call, why) ((fmi3Status)tapmp_unsupported((c), (call), (why)))

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean loggingOn, size_t n, const fmi3String categories[])
{
    (void)n, (void)categories;
    INSTANCE(c, fmi3Error);
    inst->logging_on = loggingOn;
    return fmi3OK;
}

static void log_no_instance(fmi3InstanceEnvironment env, fmi3LogMessageCallback log, const char *what)
{
    if (log) log(env, fmi3Error, "logStatusError", what);
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    (void)resourcePath, (void)visible;
#ifdef MODEL_N_STATES
    fmi3_env *env = calloc(1, sizeof *env);
    if (!env) return NULL;
    env->env = instanceEnvironment;
    env->log = logMessage;
    tapmp_instance *inst = tapmp_new(instanceName, "fmi3", logger, env, loggingOn, instantiationToken);
    if (!inst) free(env);
    else inst->model_exchange = 1;
    return inst;
#else
    (void)instanceName, (void)instantiationToken, (void)loggingOn;
    log_no_instance(instanceEnvironment, logMessage, "fmi3InstantiateModelExchange: " MODEL_IDENTIFIER_STRING
                    " is a co-simulation FMU only: allowed is fmi3InstantiateCoSimulation");
    return NULL;
#endif
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    (void)resourcePath, (void)visible, (void)requiredIntermediateVariables;
    (void)nRequiredIntermediateVariables, (void)intermediateUpdate;
#ifndef MODEL_HAS_EVENTS
    if (eventModeUsed) {
        log_no_instance(instanceEnvironment, logMessage, "fmi3InstantiateCoSimulation: eventModeUsed = true "
                        "is invalid: allowed is false (hasEventMode is false for " MODEL_IDENTIFIER_STRING ")");
        return NULL;
    }
#endif
#ifdef MODEL_CLOCK
    if (!eventModeUsed) {  /* FMI 3.0.2: an FMU with clocks is run in Event Mode, where its clocks tick */
        log_no_instance(instanceEnvironment, logMessage, "fmi3InstantiateCoSimulation: eventModeUsed = false is "
                        "invalid: allowed is true (" MODEL_IDENTIFIER_STRING " has the input clock " MODEL_CLOCK_NAME
                        ", which ticks only in Event Mode)");
        return NULL;
    }
#endif
    fmi3_env *env = calloc(1, sizeof *env);
    if (!env) return NULL;
    env->env = instanceEnvironment;
    env->log = logMessage;
    tapmp_instance *inst = tapmp_new(instanceName, "fmi3", logger, env, loggingOn, instantiationToken);
    if (!inst) free(env);
    else {
        inst->event_mode_used = eventModeUsed != fmi3False;
        inst->early_return_allowed = earlyReturnAllowed != fmi3False;
    }
    return inst;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible,
                                               fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instanceName, (void)instantiationToken, (void)resourcePath, (void)visible, (void)loggingOn;
    (void)clockUpdate, (void)lockPreemption, (void)unlockPreemption;
    log_no_instance(instanceEnvironment, logMessage, "fmi3InstantiateScheduledExecution: " MODEL_IDENTIFIER_STRING
                    " is a co-simulation FMU only: allowed is fmi3InstantiateCoSimulation");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance c)
{
    tapmp_instance *inst = (tapmp_instance *)c;
    if (!tapmp_alive(inst)) return;  /* a second free, or not ours: ignored */
    void *env = inst->env;
    tapmp_free(inst);
    free(env);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    (void)toleranceDefined, (void)tolerance, (void)stopTimeDefined, (void)stopTime;
    INSTANCE(c, fmi3Error);
    /* the start time is set (tapmp_setup_experiment) only for a call that is allowed */
    int status = tapmp_allowed(inst, OP_ENTER_INITIALIZATION);
    if (status == ST_OK) status = tapmp_setup_experiment(inst, startTime);
    return (fmi3Status)(status != ST_OK ? status : tapmp_enter_initialization(inst));
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance c)
{
    INSTANCE(c, fmi3Error);
#ifdef MODEL_N_STATES
    if (inst->model_exchange) return (fmi3Status)tapmp_me_exit_initialization(inst);  /* into Event Mode */
#endif
    return (fmi3Status)tapmp_exit_initialization(inst);
}
fmi3Status fmi3Terminate(fmi3Instance c) { INSTANCE(c, fmi3Error); return (fmi3Status)tapmp_terminate(inst); }
fmi3Status fmi3Reset(fmi3Instance c) { INSTANCE(c, fmi3Error); return (fmi3Status)tapmp_reset(inst); }

fmi3Status fmi3GetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 v[], size_t nv)
{
    INSTANCE(c, fmi3Error);
#ifdef MODEL_N_STATES
    for (size_t i = 0; vr && v && i < n && nv == n; i++)  /* der(X) ... follow `time` (N_VARS) */
        if (vr[i] > N_VARS && vr[i] <= N_VARS + MODEL_N_STATES)
            return (fmi3Status)tapmp_me_get_real(inst, N_VARS + 1, vr, n, v, nv);
#endif
    return (fmi3Status)tapmp_get_real(inst, vr, n, v, nv);
}

fmi3Status fmi3SetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Float64 v[], size_t nv)
{
    INSTANCE(c, fmi3Error);
    return (fmi3Status)tapmp_set_real(inst, vr, n, v, nv);
}

fmi3Status fmi3GetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Int32 v[], size_t nv)
{
    INSTANCE(c, fmi3Error);
    return (fmi3Status)tapmp_get_integer(inst, vr, n, (int *)v, nv);
}

fmi3Status fmi3SetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Int32 v[], size_t nv)
{
    INSTANCE(c, fmi3Error);
    return (fmi3Status)tapmp_set_integer(inst, vr, n, (const int *)v, nv);
}

/* Getters and setters of types this FMU has no variables of: fine for n = 0. */
#define NO_VARIABLES(name, type, constness)                                                         \
    fmi3Status fmi3##name(fmi3Instance c, const fmi3ValueReference vr[], size_t n, constness type v[],   \
                          size_t nv)                                                                 \
    {                                                                                                \
        (void)vr, (void)v, (void)nv;                                                                 \
        return n ? unsupported(c, #name, "this FMU has no variables of that type (n must be 0)") : fmi3OK; \
    }
NO_VARIABLES(GetFloat32, fmi3Float32, )
NO_VARIABLES(GetInt8, fmi3Int8, )
NO_VARIABLES(GetUInt8, fmi3UInt8, )
NO_VARIABLES(GetInt16, fmi3Int16, )
NO_VARIABLES(GetUInt16, fmi3UInt16, )
NO_VARIABLES(GetUInt32, fmi3UInt32, )
NO_VARIABLES(GetInt64, fmi3Int64, )
NO_VARIABLES(GetUInt64, fmi3UInt64, )
NO_VARIABLES(GetBoolean, fmi3Boolean, )
NO_VARIABLES(GetString, fmi3String, )
NO_VARIABLES(SetFloat32, fmi3Float32, const)
NO_VARIABLES(SetInt8, fmi3Int8, const)
NO_VARIABLES(SetUInt8, fmi3UInt8, const)
NO_VARIABLES(SetInt16, fmi3Int16, const)
NO_VARIABLES(SetUInt16, fmi3UInt16, const)
NO_VARIABLES(SetUInt32, fmi3UInt32, const)
NO_VARIABLES(SetInt64, fmi3Int64, const)
NO_VARIABLES(SetUInt64, fmi3UInt64, const)
NO_VARIABLES(SetBoolean, fmi3Boolean, const)
NO_VARIABLES(SetString, fmi3String, const)

fmi3Status fmi3GetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t n, size_t sizes[],
                         fmi3Binary v[], size_t nv)
{
    (void)vr, (void)sizes, (void)v, (void)nv;
    return n ? unsupported(c, "GetBinary", "this FMU has no Binary variables (n must be 0)") : fmi3OK;
}

fmi3Status fmi3SetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const size_t sizes[],
                         const fmi3Binary v[], size_t nv)
{
    (void)vr, (void)sizes, (void)v, (void)nv;
    return n ? unsupported(c, "SetBinary", "this FMU has no Binary variables (n must be 0)") : fmi3OK;
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance c, fmi3ValueReference vr, size_t *n)
{
    (void)vr, (void)n;
    return unsupported(c, "GetNumberOfVariableDependencies", "the dependencies are in modelDescription.xml");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance c, fmi3ValueReference dependent, size_t elementIndicesOfDependent[],
                                       fmi3ValueReference independents[], size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[], size_t nDependencies)
{
    (void)dependent, (void)elementIndicesOfDependent, (void)independents, (void)elementIndicesOfIndependents;
    (void)dependencyKinds, (void)nDependencies;
    return unsupported(c, "GetVariableDependencies", "the dependencies are in modelDescription.xml");
}

fmi3Status fmi3GetFMUState(fmi3Instance c, fmi3FMUState *state)
{
    INSTANCE(c, fmi3Error);
    return (fmi3Status)tapmp_get_state(inst, (tapmp_state **)state);
}

fmi3Status fmi3SetFMUState(fmi3Instance c, fmi3FMUState state)
{
    INSTANCE(c, fmi3Error);
    return (fmi3Status)tapmp_set_state(inst, (const tapmp_state *)state);
}

fmi3Status fmi3FreeFMUState(fmi3Instance c, fmi3FMUState *state)
{
    INSTANCE(c, fmi3Error);
    return (fmi3Status)tapmp_free_state(inst, (tapmp_state **)state);
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance c, fmi3FMUState state, size_t *size)
{
    INSTANCE(c, fmi3Error);
    return (fmi3Status)tapmp_serialized_size(inst, (const tapmp_state *)state, size);
}

fmi3Status fmi3SerializeFMUState(fmi3Instance c, fmi3FMUState state, fmi3Byte bytes[], size_t size)
{
    INSTANCE(c, fmi3Error);
    return (fmi3Status)tapmp_serialize(inst, (const tapmp_state *)state, (char *)bytes, size);
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance c, const fmi3Byte bytes[], size_t size, fmi3FMUState *state)
{
    INSTANCE(c, fmi3Error);
    return (fmi3Status)tapmp_deserialize(inst, (const char *)bytes, size, (tapmp_state **)state);
}

fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 t, fmi3Float64 h, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    INSTANCE(c, fmi3Error);
    if (inst->model_exchange)
        return unsupported(c, "DoStep", "the instance is a Model Exchange instance (fmi3InstantiateModelExchange)");
    int event = 0, early = 0;
    double last = inst->time;
    int status = tapmp_do_step_events(inst, t, h, &event, &early, &last);
    if (eventHandlingNeeded) *eventHandlingNeeded = event ? fmi3True : fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = early ? fmi3True : fmi3False;
    if (lastSuccessfulTime) *lastSuccessfulTime = last;
    return (fmi3Status)status;
}

#ifdef MODEL_HAS_EVENTS
fmi3Status fmi3EnterEventMode(fmi3Instance c)
{
    INSTANCE(c, fmi3Error);
    return (fmi3Status)tapmp_enter_event_mode(inst);
}

fmi3Status fmi3EnterStepMode(fmi3Instance c)
{
    INSTANCE(c, fmi3Error);
    return (fmi3Status)tapmp_enter_step_mode(inst);
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime)
{
    INSTANCE(c, fmi3Error);
    int changed = 0, defined = 0;
    double next = 0.0;
    int status = tapmp_update_discrete_states(inst, &changed, &defined, &next);
    tapmp_fmi3_report_update(defined, next, discreteStatesNeedUpdate, terminateSimulation,
                             nominalsOfContinuousStatesChanged, valuesOfContinuousStatesChanged, nextEventTimeDefined,
                             nextEventTime);
    return (fmi3Status)status;
}
#endif

/* Everything below belongs to interfaces this FMU does not provide. PARAMS is the
 * parenthesized parameter list, the rest marks the parameters other than c as unused. */
#define NOT_PROVIDED(name, why, params, ...)                                                         \
    fmi3Status fmi3##name params { __VA_ARGS__; return unsupported(c, #name, why); }
#define NOT_PROVIDED0(name, why)                                                                     \
    fmi3Status fmi3##name(fmi3Instance c) { return unsupported(c, #name, why); }
#define NO_ME "Model Exchange is not provided"
#define NO_CLOCKS "this FMU has no clocks"
#define NO_DERIVATIVES "providesDirectionalDerivatives and providesAdjointDerivatives are false"
#if !defined(MODEL_HAS_EVENTS) && !defined(MODEL_N_STATES)
NOT_PROVIDED0(EnterEventMode, "hasEventMode is false")
NOT_PROVIDED0(EnterStepMode, "hasEventMode is false")
NOT_PROVIDED(UpdateDiscreteStates, "hasEventMode is false",
             (fmi3Instance c, fmi3Boolean *a, fmi3Boolean *b, fmi3Boolean *d, fmi3Boolean *e, fmi3Boolean *f,
              fmi3Float64 *g),
             (void)a, (void)b, (void)d, (void)e, (void)f, (void)g)
#endif
NOT_PROVIDED0(EnterConfigurationMode, "this FMU has no structural parameters")
NOT_PROVIDED0(ExitConfigurationMode, "this FMU has no structural parameters")
NOT_PROVIDED(GetDirectionalDerivative, NO_DERIVATIVES,
             (fmi3Instance c, const fmi3ValueReference u[], size_t nu, const fmi3ValueReference k[], size_t nk,
              const fmi3Float64 seed[], size_t ns, fmi3Float64 sens[], size_t nsens),
             (void)u, (void)nu, (void)k, (void)nk, (void)seed, (void)ns, (void)sens, (void)nsens)
NOT_PROVIDED(GetAdjointDerivative, NO_DERIVATIVES,
             (fmi3Instance c, const fmi3ValueReference u[], size_t nu, const fmi3ValueReference k[], size_t nk,
              const fmi3Float64 seed[], size_t ns, fmi3Float64 sens[], size_t nsens),
             (void)u, (void)nu, (void)k, (void)nk, (void)seed, (void)ns, (void)sens, (void)nsens)
#ifndef MODEL_CLOCK
NOT_PROVIDED(GetIntervalDecimal, NO_CLOCKS,
             (fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 i[], fmi3IntervalQualifier q[]),
             (void)vr, (void)n, (void)i, (void)q)
NOT_PROVIDED(GetIntervalFraction, NO_CLOCKS,
             (fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3UInt64 c_[], fmi3UInt64 r[],
              fmi3IntervalQualifier q[]),
             (void)vr, (void)n, (void)c_, (void)r, (void)q)
NOT_PROVIDED(GetShiftDecimal, NO_CLOCKS,
             (fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 s[]), (void)vr, (void)n, (void)s)
NOT_PROVIDED(GetShiftFraction, NO_CLOCKS,
             (fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3UInt64 c_[], fmi3UInt64 r[]),
             (void)vr, (void)n, (void)c_, (void)r)
NOT_PROVIDED(SetIntervalDecimal, NO_CLOCKS,
             (fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Float64 i[]),
             (void)vr, (void)n, (void)i)
NOT_PROVIDED(SetIntervalFraction, NO_CLOCKS,
             (fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 c_[], const fmi3UInt64 r[]),
             (void)vr, (void)n, (void)c_, (void)r)
NOT_PROVIDED(SetShiftDecimal, NO_CLOCKS,
             (fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Float64 s[]), (void)vr, (void)n, (void)s)
NOT_PROVIDED(SetShiftFraction, NO_CLOCKS,
             (fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 c_[], const fmi3UInt64 r[]),
             (void)vr, (void)n, (void)c_, (void)r)
#endif
NOT_PROVIDED0(EvaluateDiscreteStates, "providesEvaluateDiscreteStates is false")
#ifndef MODEL_N_STATES
NOT_PROVIDED0(EnterContinuousTimeMode, NO_ME)
NOT_PROVIDED(CompletedIntegratorStep, NO_ME, (fmi3Instance c, fmi3Boolean a, fmi3Boolean *b, fmi3Boolean *d),
             (void)a, (void)b, (void)d)
NOT_PROVIDED(SetTime, NO_ME, (fmi3Instance c, fmi3Float64 t), (void)t)
NOT_PROVIDED(SetContinuousStates, NO_ME, (fmi3Instance c, const fmi3Float64 x[], size_t n), (void)x, (void)n)
NOT_PROVIDED(GetContinuousStateDerivatives, NO_ME, (fmi3Instance c, fmi3Float64 x[], size_t n), (void)x, (void)n)
NOT_PROVIDED(GetEventIndicators, NO_ME, (fmi3Instance c, fmi3Float64 x[], size_t n), (void)x, (void)n)
NOT_PROVIDED(GetContinuousStates, NO_ME, (fmi3Instance c, fmi3Float64 x[], size_t n), (void)x, (void)n)
NOT_PROVIDED(GetNominalsOfContinuousStates, NO_ME, (fmi3Instance c, fmi3Float64 x[], size_t n), (void)x, (void)n)
NOT_PROVIDED(GetNumberOfEventIndicators, NO_ME, (fmi3Instance c, size_t *n), (void)n)
NOT_PROVIDED(GetNumberOfContinuousStates, NO_ME, (fmi3Instance c, size_t *n), (void)n)
#endif
NOT_PROVIDED(GetOutputDerivatives, "maxOutputDerivativeOrder is 0",
             (fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Int32 o[], fmi3Float64 v[], size_t nv),
             (void)vr, (void)n, (void)o, (void)v, (void)nv)
NOT_PROVIDED(ActivateModelPartition, NO_CLOCKS, (fmi3Instance c, fmi3ValueReference clock, fmi3Float64 t),
             (void)clock, (void)t)
