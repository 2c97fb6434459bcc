/* FMI 3.0's Model Exchange functions of a native TAPMP FMU with a continuous state (MODEL_N_STATES: the
 * plant), on the version-neutral operations of model_exchange.c (tapmp_me_*), shared with FMI 2.0. A
 * Co-Simulation instance of this model has no Event Mode (hasEventMode is false). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "runtime.h"
#include "fmi3Functions.h"
#include "fmi3_events.h"

#ifdef MODEL_N_STATES
#ifdef MODEL_HAS_EVENTS
#error "a model with time events for Co-Simulation and a continuous state for Model Exchange is not supported"
#endif

fmi3Status fmi3EnterEventMode(fmi3Instance c)
{
    INSTANCE(c, fmi3Error);
    if (!inst->model_exchange) return (fmi3Status)tapmp_unsupported(c, "EnterEventMode", "hasEventMode is false");
    return (fmi3Status)tapmp_me_enter_event_mode(inst);
}

fmi3Status fmi3EnterStepMode(fmi3Instance c)
{
    INSTANCE(c, fmi3Error);
    return (fmi3Status)tapmp_unsupported(c, "EnterStepMode", inst->model_exchange ? "the instance is a Model Exchange "
                                         "instance (allowed: fmi3EnterContinuousTimeMode)" : "hasEventMode is false");
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime)
{
    INSTANCE(c, fmi3Error);
    if (!inst->model_exchange) return (fmi3Status)tapmp_unsupported(c, "UpdateDiscreteStates", "hasEventMode is false");
    int defined = 0;
    double next = 0.0;
    int status = tapmp_me_update(inst, &defined, &next);
    if (status != ST_OK) return (fmi3Status)status;
    tapmp_fmi3_report_update(defined, next, discreteStatesNeedUpdate, terminateSimulation,
                             nominalsOfContinuousStatesChanged, valuesOfContinuousStatesChanged, nextEventTimeDefined,
                             nextEventTime);
    return fmi3OK;
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance c)
{
    INSTANCE(c, fmi3Error);
    return (fmi3Status)tapmp_me_enter_continuous_time_mode(inst);
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance c, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    INSTANCE(c, fmi3Error);
    int enter = 0, terminate = 0, status = tapmp_allowed(inst, OP_ME_COMPLETED_INTEGRATOR_STEP);
    if (status == ST_OK) status = tapmp_require_pointer(inst, enterEventMode, "CompletedIntegratorStep", "enterEventMode");
    if (status == ST_OK)
        status = tapmp_require_pointer(inst, terminateSimulation, "CompletedIntegratorStep", "terminateSimulation");
    if (status == ST_OK) status = tapmp_me_completed_integrator_step(inst, &enter, &terminate);
    if (status != ST_OK) return (fmi3Status)status;
    *enterEventMode = enter ? fmi3True : fmi3False;
    *terminateSimulation = terminate ? fmi3True : fmi3False;
    return fmi3OK;
}

fmi3Status fmi3SetTime(fmi3Instance c, fmi3Float64 time)
{
    INSTANCE(c, fmi3Error);
    return (fmi3Status)tapmp_me_set_time(inst, time);
}

fmi3Status fmi3SetContinuousStates(fmi3Instance c, const fmi3Float64 x[], size_t nx)
{
    INSTANCE(c, fmi3Error);
    return (fmi3Status)tapmp_me_set_states(inst, x, nx);
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance c, fmi3Float64 dx[], size_t nx)
{
    INSTANCE(c, fmi3Error);
    return (fmi3Status)tapmp_me_get_derivatives(inst, dx, nx);
}

fmi3Status fmi3GetEventIndicators(fmi3Instance c, fmi3Float64 z[], size_t ni)
{
    INSTANCE(c, fmi3Error);
    return (fmi3Status)tapmp_me_event_indicators(inst, z, ni);
}

fmi3Status fmi3GetContinuousStates(fmi3Instance c, fmi3Float64 x[], size_t nx)
{
    INSTANCE(c, fmi3Error);
    return (fmi3Status)tapmp_me_get_states(inst, x, nx);
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance c, fmi3Float64 nominals[], size_t nx)
{
    INSTANCE(c, fmi3Error);
    return (fmi3Status)tapmp_me_nominals(inst, nominals, nx);
}

/* Allowed in every mode (the numbers are fixed); only the pointer is checked. */
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance c, size_t *n)
{
    INSTANCE(c, fmi3Error);
    if (tapmp_require_pointer(inst, n, "GetNumberOfEventIndicators", "nEventIndicators") != ST_OK) return fmi3Error;
    *n = 0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance c, size_t *n)
{
    INSTANCE(c, fmi3Error);
    if (tapmp_require_pointer(inst, n, "GetNumberOfContinuousStates", "nContinuousStates") != ST_OK) return fmi3Error;
    *n = MODEL_N_STATES;
    return fmi3OK;
}
#endif
