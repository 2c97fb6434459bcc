/* FMI 3.0's Event Mode of a Co-Simulation instance (eventModeUsed: the controller's sample instants
 * as time events, doStep ending at them) and the model's periodic input clock (MODEL_CLOCK: the
 * clocked controller); see instance.h. A clock's tick belongs to its event: EnterStepMode with a
 * tick not handled is an error. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "runtime.h"

int tapmp_enter_event_mode(tapmp_instance *inst)
{
    ALLOW(inst, OP_ENTER_EVENT_MODE);
    if (inst->mode == MODE_EVENT) return ST_OK;  /* the host may announce an event it is in already */
    if (inst->failed) return tapmp_fail(inst, "%sEnterEventMode refused after an earlier error: %s", inst->fmi,
                                        inst->error);
    inst->mode = MODE_EVENT;
    inst->clock_active = 0;  /* a tick belongs to the event it was set in: none carries into this one */
    return ST_OK;
}

int tapmp_update_discrete_states(tapmp_instance *inst, int *values_changed, int *next_defined, double *next_time)
{
    ALLOW(inst, OP_UPDATE_DISCRETE_STATES);
    char v[40], msg[TAPMP_MESSAGE_MAX];
    double out[MODEL_N_OUT];
    if (inst->failed) return tapmp_fail(inst, "%sUpdateDiscreteStates at t = %.6g s refused after an earlier error: "
                                        "%s", inst->fmi, inst->time, inst->error);
    ModelData before = inst->m;
    if (inst->retune) {  /* new tunable values take effect at this event */
        inst->retune = 0;
        if (!model_validate(inst, msg, sizeof msg) || !tapmp_check_ranges(inst, msg, sizeof msg))
            return tapmp_fail(inst, "%s (at t = %.6g s)", msg, inst->time);
    }
    if (!model_event_update(inst, out, msg, sizeof msg)) {
        inst->m = before;
        return tapmp_fail(inst, "%s", msg);
    }
    int changed = 0;
    for (int i = 0; i < MODEL_N_OUT; i++) {
        if (!isfinite(out[i])) {
            inst->m = before;
            tapmp_invalid_text(msg, sizeof msg, VARS[MODEL_OUT_FIRST + i].name, tapmp_repr(out[i], v), OVERFLOW, 1,
                               inst->time);
            return tapmp_fail(inst, "%s", msg);
        }
        changed |= memcmp(&out[i], &inst->reals[MODEL_OUT_FIRST + i], sizeof out[i]) != 0;
    }
    memcpy(inst->reals + MODEL_OUT_FIRST, out, sizeof out);
    inst->clock_active = 0;  /* the clock's tick is handled: clocks are inactive again until the next SetClock */
    *values_changed = changed;
    *next_defined = model_next_event(inst, next_time);
    if (!*next_defined) *next_time = 0.0;
    return ST_OK;
}

int tapmp_enter_step_mode(tapmp_instance *inst)
{
    ALLOW(inst, OP_ENTER_STEP_MODE);
#ifdef MODEL_CLOCK
    /* A tick set in this event and not handled by fmi3UpdateDiscreteStates is refused, not discarded
     * with a warning: the tick is the host's order to sample at this instant, so leaving the event
     * without the sample loses a control sample (the command would hold a period or more), and keeping
     * it would sample at a later event, at the wrong instant. The error shows the host's omission at
     * the call that makes it; the tick never outlives its event either way. */
    if (inst->clock_active) {
        char v[40];
        inst->clock_active = 0;
        return tapmp_fail(inst, "%sEnterStepMode at t = %s s is not allowed: the tick of the clock " MODEL_CLOCK_NAME
                          " set in this event (%sSetClock) was not handled: allowed is %sUpdateDiscreteStates "
                          "before leaving Event Mode (a tick belongs to its event)", inst->fmi,
                          tapmp_repr(inst->time, v), inst->fmi, inst->fmi);
    }
#endif
    inst->mode = MODE_STEP;
    return ST_OK;
}

int tapmp_do_step_events(tapmp_instance *inst, double t, double h, int *event_needed, int *early_return,
                         double *last_time)
{
    ALLOW(inst, OP_DO_STEP);  /* a refusal leaves the caller's outputs: no event, the time */
    double te;
    *event_needed = *early_return = 0;
    if (!inst->event_mode_used || inst->failed || !isfinite(t) ||
        !(isfinite(h) && h > 0.0) || !model_next_event(inst, &te)) {
        int status = tapmp_do_step(inst, t, h);  /* no event ahead, or its checks refuse the call */
        *last_time = inst->time;
        return status;
    }
    char v[40], w[40];
    double tol = tapmp_time_tolerance(te);
    if (inst->time >= te - tol)  /* the event at te is due and was not handled */
        return tapmp_fail(inst, "%sDoStep at t = %s s is not allowed: the event at t = %s s is pending (doStep "
                          "returned eventHandlingNeeded = true): allowed is %sEnterEventMode, "
                          "%sUpdateDiscreteStates, %sEnterStepMode first", inst->fmi, tapmp_repr(t, v),
                          tapmp_repr(te, w), inst->fmi, inst->fmi, inst->fmi);
    int passes = t + h > te + tol;
    if (passes && !inst->early_return_allowed) {
        char e[40];
        return tapmp_fail(inst, "communicationStepSize = %s is invalid: allowed is a step that ends at or before the "
                          "next event, t = %s s (nextEventTime; earlyReturnAllowed is false, so doStep cannot stop "
                          "there; at t = %s s)", tapmp_repr(h, v), tapmp_repr(te, w), tapmp_repr(t, e));
    }
    int status = tapmp_do_step(inst, t, passes ? te - t : h);
    if (status <= ST_WARNING && passes) inst->time = te;  /* exactly the event's time, not t + (te - t) */
    *last_time = inst->time;
    if (status > ST_WARNING) return status;
    *early_return = passes;
    *event_needed = passes || fabs(t + h - te) <= tol;  /* stopped at the event, or the step ends on it */
    return status;
}

/* --- the periodic input clock (FMI 3.0, MODEL_CLOCK) ------------------------------------ */
#ifdef MODEL_CLOCK
/* Every vr is the clock's, and the arrays are there when n > 0; else the error naming the first other. */
static int check_clock_refs(tapmp_instance *inst, tapmp_op op, const unsigned vr[], size_t n, const void *v)
{
    char value[40], allowed[160];
    const char *call = tapmp_call(inst, op);
    if (n && (!vr || !v))
        return tapmp_fail(inst, "%s%s: valueReferences and values must not be NULL for nValueReferences = %zu",
                          inst->fmi, call, n);
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == MODEL_CLOCK_VR) continue;
        snprintf(value, sizeof value, "%u", vr[i]);
        snprintf(allowed, sizeof allowed, "%d, the clock %s (%s%s takes clocks only)", MODEL_CLOCK_VR,
                 MODEL_CLOCK_NAME, inst->fmi, call);
        char name[64];
        snprintf(name, sizeof name, "%s valueReference", call);
        return tapmp_invalid(inst, name, value, allowed, 0);
    }
    return ST_OK;
}

int tapmp_set_clock(tapmp_instance *inst, const unsigned vr[], size_t n, const int v[])
{
    ALLOW_VALUES(inst, OP_SET_CLOCK, n);
    int status = check_clock_refs(inst, OP_SET_CLOCK, vr, n, v);
    if (status != ST_OK || n == 0) return status;
    if (inst->failed)
        return tapmp_fail(inst, "%sSetClock refused after an earlier error: %s", inst->fmi, inst->error);
    for (size_t i = 0; i < n; i++) inst->clock_active = v[i] != 0;
    return ST_OK;
}

int tapmp_get_clock(tapmp_instance *inst, const unsigned vr[], size_t n, int v[])
{
    ALLOW(inst, OP_GET_CLOCK);
    int status = check_clock_refs(inst, OP_GET_CLOCK, vr, n, v);
    if (status != ST_OK) return status;
    for (size_t i = 0; i < n; i++) v[i] = inst->mode == MODE_EVENT && inst->clock_active;
    return ST_OK;
}

int tapmp_get_interval(tapmp_instance *inst, const unsigned vr[], size_t n, double interval[], int qualifier[])
{
    ALLOW(inst, OP_GET_INTERVAL);
    int status = check_clock_refs(inst, OP_GET_INTERVAL, vr, n, interval);
    if (status != ST_OK) return status;
    for (size_t i = 0; i < n; i++) {
        interval[i] = model_clock_interval(inst);
        if (qualifier) qualifier[i] = inst->interval_reported && MODE_RUNNING(inst->mode) ? 1 : 2;
    }
    if (n && MODE_RUNNING(inst->mode)) inst->interval_reported = 1;
    return ST_OK;
}

int tapmp_set_interval(tapmp_instance *inst, const unsigned vr[], size_t n, const double interval[])
{
    ALLOW_VALUES(inst, OP_SET_INTERVAL, n);
    char value[40], period[40], allowed[200];
    int status = check_clock_refs(inst, OP_SET_INTERVAL, vr, n, interval);
    if (status != ST_OK || n == 0) return status;
    double T = model_clock_interval(inst);
    for (size_t i = 0; i < n; i++) {
        /* the interval is the parameter T_s: the clock cannot tick at another period than the one the
         * controller's law uses (its velocity estimate and integral take T_s) */
        if (interval[i] == T || fabs(interval[i] - T) <= 1e-12 * T) continue;
        snprintf(allowed, sizeof allowed, "the sample period T_s = %s s (set the parameter T_s for another "
                 "period)", tapmp_repr(T, period));
        return tapmp_invalid(inst, "interval of " MODEL_CLOCK_NAME, tapmp_repr(interval[i], value), allowed, 0);
    }
    return ST_OK;
}

int tapmp_get_shift(tapmp_instance *inst, const unsigned vr[], size_t n, double shift[])
{
    ALLOW(inst, OP_GET_SHIFT);
    int status = check_clock_refs(inst, OP_GET_SHIFT, vr, n, shift);
    if (status != ST_OK) return status;
    for (size_t i = 0; i < n; i++) shift[i] = 0.0;
    return ST_OK;
}

int tapmp_set_shift(tapmp_instance *inst, const unsigned vr[], size_t n, const double shift[])
{
    ALLOW_VALUES(inst, OP_SET_SHIFT, n);
    char value[40];
    int status = check_clock_refs(inst, OP_SET_SHIFT, vr, n, shift);
    if (status != ST_OK || n == 0) return status;
    for (size_t i = 0; i < n; i++)
        if (shift[i] != 0.0)
            return tapmp_invalid(inst, "shift of " MODEL_CLOCK_NAME, tapmp_repr(shift[i], value),
                                 "0 (the controller samples at t0 + k T_s, t0 the start time)", 0);
    return ST_OK;
}
#endif
