/* Model Exchange (FMI 2.0 and 3.0), for a model with a continuous state (MODEL_N_STATES: the plant):
 * the host integrates it. A continuous state is inside the model's domain (model_me_set_states) and
 * the outputs it gives finite, a derivative returned is finite, SetTime never goes before the last
 * accepted time; Continuous-Time / Event Mode and that time are part of the FMU state. See
 * instance.h. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "runtime.h"

#ifdef MODEL_N_STATES

int tapmp_me_exit_initialization(tapmp_instance *inst)
{
    ALLOW(inst, OP_EXIT_INITIALIZATION);
    int status = tapmp_exit_initialization(inst);
    if (status > ST_WARNING) return status;
    char msg[TAPMP_MESSAGE_MAX];
    if (!model_me_check(inst, msg, sizeof msg)) return tapmp_fail(inst, "%s", msg);
    inst->me_continuous = 0;  /* Model Exchange leaves initialization into Event Mode */
    inst->me_floor = inst->time;
    return status;
}

/* In Initialization Mode the model follows the values set since it was last built: a get of no
 * variable rebuilds it (the initial unknowns) before a state or derivative is read. */
static void me_refresh(tapmp_instance *inst)
{
    if (inst->mode == MODE_INITIALIZATION) tapmp_get_real(inst, NULL, 0, NULL, 0);
}

static int me_array(tapmp_instance *inst, const char *call, const void *p, size_t n, size_t expected,
                    const char *what)
{
    if (n != expected)
        return tapmp_fail(inst, "%s%s: %s = %zu is invalid: allowed is %zu", inst->fmi, call, what, n, expected);
    if (n && !p)
        return tapmp_fail(inst, "%s%s: the array = NULL is invalid: allowed is an array of %zu values", inst->fmi,
                          call, n);
    return ST_OK;
}

int tapmp_me_set_time(tapmp_instance *inst, double time)
{
    ALLOW(inst, OP_ME_SET_TIME);
    char v[40], w[40], allowed[200];
    if (!isfinite(time)) return tapmp_invalid(inst, "time", tapmp_repr(time, v), "a finite number", 0);
    /* An integrator may go back over a step it rejects, but never before the last point it accepted:
     * the end of initialization, an event, or a completed integrator step (FMI's CompletedIntegratorStep). */
    double tol = tapmp_time_tolerance(inst->me_floor);
    if (time < inst->me_floor - tol) {
        snprintf(allowed, sizeof allowed, "a time >= %s s, the last accepted time (the end of initialization, an "
                 "event or a completed integrator step; time only moves forward)", tapmp_repr(inst->me_floor, w));
        return tapmp_invalid(inst, "time", tapmp_repr(time, v), allowed, 0);
    }
    inst->time = time;
    return ST_OK;
}

int tapmp_me_set_states(tapmp_instance *inst, const double x[], size_t nx)
{
    ALLOW(inst, OP_ME_SET_STATES);
    int status = me_array(inst, tapmp_call(inst, OP_ME_SET_STATES), x, nx, MODEL_N_STATES, "nx");
    if (status != ST_OK) return status;
    char msg[TAPMP_MESSAGE_MAX];
    ModelData before = inst->m;
    double saved[MODEL_N_OUT];
    memcpy(saved, inst->reals + MODEL_OUT_FIRST, sizeof saved);
    if (!model_me_set_states(inst, x, msg, sizeof msg)) return tapmp_fail(inst, "%s", msg);
    if (!tapmp_outputs_finite(inst, saved, inst->time, msg, sizeof msg)) {  /* the outputs put back; the state too */
        inst->m = before;
        return tapmp_fail(inst, "%sSetContinuousStates: %s", inst->fmi, msg);
    }
    return ST_OK;
}

int tapmp_me_get_states(tapmp_instance *inst, double x[], size_t nx)
{
    ALLOW(inst, OP_ME_GET_STATES);
    int status = me_array(inst, tapmp_call(inst, OP_ME_GET_STATES), x, nx, MODEL_N_STATES, "nx");
    if (status != ST_OK) return status;
    me_refresh(inst);
    model_me_get_states(inst, x);
    return ST_OK;
}

/* The derivatives into d, each finite; else the logged error. */
static int me_derivatives(tapmp_instance *inst, const char *call, double d[MODEL_N_STATES])
{
    me_refresh(inst);
    model_me_derivatives(inst, d);
    for (int i = 0; i < MODEL_N_STATES; i++)
        if (!isfinite(d[i])) {
            char v[40];
            return tapmp_fail(inst, "%s%s: the derivative of state %d is %s at t = %.6g s: allowed is a finite number "
                              "(the forces or the state are out of range)", inst->fmi, call, i, tapmp_repr(d[i], v),
                              inst->time);
        }
    return ST_OK;
}

int tapmp_me_get_derivatives(tapmp_instance *inst, double dx[], size_t nx)
{
    ALLOW(inst, OP_ME_GET_DERIVATIVES);
    const char *call = tapmp_call(inst, OP_ME_GET_DERIVATIVES);
    int status = me_array(inst, call, dx, nx, MODEL_N_STATES, "nx");
    if (status != ST_OK) return status;
    double d[MODEL_N_STATES];
    status = me_derivatives(inst, call, d);
    if (status == ST_OK) memcpy(dx, d, sizeof d);
    return status;
}

int tapmp_me_get_real(tapmp_instance *inst, unsigned first, const unsigned vr[], size_t n, double v[], size_t nv)
{
    ALLOW(inst, OP_GET_DERIVATIVE_VALUE);
    const char *call = tapmp_call(inst, OP_GET_DERIVATIVE_VALUE);
    int status = tapmp_check_arrays(inst, call, vr, n, v, nv);
    if (status != ST_OK) return status;
    double d[MODEL_N_STATES];
    status = me_derivatives(inst, call, d);
    if (status != ST_OK) return status;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= first && vr[i] < first + MODEL_N_STATES) {
            v[i] = d[vr[i] - first];
            continue;
        }
        status = tapmp_get_real(inst, vr + i, 1, v + i, 1);
        if (status > ST_WARNING) return status;
    }
    return ST_OK;
}

int tapmp_me_event_indicators(tapmp_instance *inst, double z[], size_t ni)
{
    ALLOW(inst, OP_ME_EVENT_INDICATORS);
    return me_array(inst, tapmp_call(inst, OP_ME_EVENT_INDICATORS), z, ni, 0, "ni");
}

int tapmp_me_nominals(tapmp_instance *inst, double nominals[], size_t nx)
{
    ALLOW(inst, OP_ME_NOMINALS);
    int status = me_array(inst, tapmp_call(inst, OP_ME_NOMINALS), nominals, nx, MODEL_N_STATES, "nx");
    if (status != ST_OK) return status;
    for (size_t i = 0; i < nx; i++) nominals[i] = 1.0;  /* the declared nominal of every Real */
    return ST_OK;
}

int tapmp_me_enter_event_mode(tapmp_instance *inst)
{
    ALLOW(inst, OP_ME_ENTER_EVENT_MODE);
    inst->me_continuous = 0;
    inst->me_floor = inst->time;  /* an event is a point the host accepted */
    return ST_OK;
}

int tapmp_me_enter_continuous_time_mode(tapmp_instance *inst)
{
    ALLOW(inst, OP_ME_ENTER_CONTINUOUS_TIME_MODE);
    inst->me_continuous = 1;
    inst->me_floor = inst->time;
    return ST_OK;
}

int tapmp_me_completed_integrator_step(tapmp_instance *inst, int *enter_event_mode, int *terminate)
{
    ALLOW(inst, OP_ME_COMPLETED_INTEGRATOR_STEP);
    inst->me_floor = inst->time;  /* the integrator accepted the step that ends here */
    *enter_event_mode = 0;
    *terminate = 0;
    return ST_OK;
}

int tapmp_me_update(tapmp_instance *inst, int *next_defined, double *next_time)
{
    ALLOW(inst, OP_ME_UPDATE);
    double next = model_me_next_event_time(inst);
    *next_defined = isfinite(next);
    *next_time = isfinite(next) ? next : 0.0;
    return ST_OK;
}
#endif
