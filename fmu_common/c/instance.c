/* Version-neutral FMU instance; see instance.h. The rules it enforces, for every family
 * (the native models and the pythonfmu backend supply only the model operations):
 * - bad input is an error status at the call that receives it, with one logged message
 *   naming the variable, the value, the time and what is allowed; after an error every
 *   doStep is refused, so no stale or non-finite value travels on;
 * - a call the co-simulation state machine does not allow in the current mode is an error;
 * - doStep(t, h) needs a finite t that continues the previous step (t equals the end of
 *   the previous step, or the start time, within the absolute time_tolerance()) and a
 *   finite h > 0 whose end t + h lies after the previous end: time only moves forward;
 *   outputs are computed, checked to be finite and only then published;
 * - an FMU state is checked whole (its mode, settings, outputs and the model's hidden
 *   values, model_check_hidden) before any of it is applied;
 * - Model Exchange: a continuous state is inside the model's domain (model_me_set_states) and the
 *   outputs it gives finite, a derivative returned is finite, SetTime never goes before the last
 *   accepted time; Continuous-Time / Event Mode, that time and a clock's tick are part of the state;
 * - a clock's tick belongs to its event: EnterStepMode with a tick not handled is an error. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef _WIN32
#define WIN32_LEAN_AND_MEAN
#include <windows.h>  /* SRWLOCK */
#else
#include <pthread.h>
#endif

#include "instance.h"

#define INSTANCE_MAGIC 0x7A3D9C51u
/* How far [s] a doStep's communication point may lie from the instance's time: 1e-4 of the servo
 * period T_s = 1e-4 s. That is the controller's own tolerance for its sample instants
 * (TAPMP_SAMPLE_TOLERANCE T_s), so a point accepted here is the same instant to every model, and
 * it is absolute: it does not grow with the time (1e-9 |t| let 1 ms pass at t = 1e6 s). */
#define TIME_TOLERANCE 1e-8

TAPMP_DEFINITION const tapmp_var VARS[N_VARS] = MODEL_VARS_INIT;

static const char *MODE_NAMES[] = {"Instantiated", "Initialization Mode", "Step Mode", "Terminated", "Event Mode"};

char *tapmp_repr(double x, char *buf)
{
    if (isnan(x)) return strcpy(buf, "nan");
    if (isinf(x)) return strcpy(buf, x > 0 ? "inf" : "-inf");
    if (x == 0.0) return strcpy(buf, signbit(x) ? "-0.0" : "0.0");
    char e[40];
    for (int p = 1; p <= 17; p++) {  /* the shortest digits that read back as x */
        snprintf(e, sizeof e, "%.*e", p - 1, x);
        if (strtod(e, NULL) == x) break;
    }
    const char *s = e;
    int neg = *s == '-';
    if (neg) s++;
    char digits[24];
    int nd = 0;
    for (; *s && *s != 'e'; s++)
        if (*s != '.') digits[nd++] = *s;
    while (nd > 1 && digits[nd - 1] == '0') nd--;
    digits[nd] = 0;
    int exp10 = atoi(s + 1), decpt = exp10 + 1;
    char *o = buf;
    if (neg) *o++ = '-';
    if (decpt <= -4 || decpt > 16) {  /* Python's switch to scientific notation */
        *o++ = digits[0];
        if (nd > 1) o += sprintf(o, ".%s", digits + 1);
        sprintf(o, "e%c%02d", exp10 < 0 ? '-' : '+', abs(exp10));
    } else if (decpt <= 0) {
        o += sprintf(o, "0.");
        for (int i = 0; i < -decpt; i++) *o++ = '0';
        strcpy(o, digits);
    } else if (decpt >= nd) {
        o += sprintf(o, "%s", digits);
        for (int i = nd; i < decpt; i++) *o++ = '0';
        strcpy(o, ".0");
    } else {
        memcpy(o, digits, (size_t)decpt);
        o += decpt;
        sprintf(o, ".%s", digits + decpt);
    }
    return buf;
}

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
static double time_tolerance(double time)
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

void tapmp_log(tapmp_instance *inst, int status, const char *category, const char *fmt, ...)
{
    char msg[TAPMP_MESSAGE_MAX];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (status >= ST_ERROR && !inst->failed) {
        inst->failed = 1;
        snprintf(inst->error, sizeof inst->error, "%s", msg);
    }
    if (inst->log && (inst->logging_on || status >= ST_ERROR)) inst->log(inst, status, category, msg);
}

int tapmp_fail(tapmp_instance *inst, const char *fmt, ...)
{
    char msg[TAPMP_MESSAGE_MAX];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    tapmp_log(inst, ST_ERROR, "logStatusError", "%s", msg);
    return ST_ERROR;
}

int tapmp_invalid_text(char *buf, size_t size, const char *name, const char *value,
                       const char *allowed, int has_time, double time)
{
    char at[64] = "";
    if (has_time) snprintf(at, sizeof at, " at t = %.6g s", time);
    snprintf(buf, size, "%s = %s%s is invalid: allowed is %s", name, value, at, allowed);
    return 0;
}

int tapmp_invalid(tapmp_instance *inst, const char *name, const char *value, const char *allowed,
                  int time_in_value)
{
    char msg[TAPMP_MESSAGE_MAX];
    tapmp_invalid_text(msg, sizeof msg, name, value, allowed, time_in_value, inst->time);
    if (time_in_value) return tapmp_fail(inst, "%s", msg);
    return tapmp_fail(inst, "%s (at t = %.6g s)", msg, inst->time);
}

int tapmp_mode_error(tapmp_instance *inst, const char *call, const char *allowed)
{
    return tapmp_fail(inst, "%s%s is not allowed in %s: allowed in %s", inst->fmi, call,
                      MODE_NAMES[inst->mode], allowed);
}

int tapmp_range_text(int kind, const char *name, double value, const char *allowed, char *msg, size_t size)
{
    char v[40];
    if (!kind) return 1;
    /* an integer setting's value may lie outside int (that is why it is refused): printed, not converted */
    if (kind == 2) snprintf(v, sizeof v, "%.0f", value);
    return tapmp_invalid_text(msg, size, name ? name : "a setting", kind == 2 ? v : tapmp_repr(value, v),
                              allowed ? allowed : "a value in its range", 0, 0);
}

/* Range of a parameter, declared as min/max in the modelDescription (tapmp/interface.py). */
static int check_ranges(const tapmp_instance *inst, char *msg, size_t size)
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

#define OVERFLOW "a finite number (the output overflowed; check the inputs and parameters)"

/* After outputs were published at t: if one is not finite, put back `saved` (the outputs
 * before) and write the message naming the first such output; 0 then. */
static int outputs_finite(tapmp_instance *inst, const double saved[], double t, char *msg, size_t size)
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
    if (!model_validate(inst, msg, sizeof msg) || !check_ranges(inst, msg, sizeof msg)) {
        return tapmp_fail(inst, "%s (at t = %.6g s)", msg, inst->time);
    }
    memcpy(saved, inst->reals + MODEL_OUT_FIRST, sizeof saved);
    model_setup(inst);
    inst->has_model = 1;
    if (inst->failed) return ST_ERROR;  /* model_setup logged an error (the Python backend can) */
    if (!outputs_finite(inst, saved, inst->time, msg, sizeof msg)) return tapmp_fail(inst, "%s", msg);
    return ST_OK;
}

int tapmp_setup_experiment(tapmp_instance *inst, double start_time)
{
    if (inst->mode != MODE_INSTANTIATED) return tapmp_mode_error(inst, "SetupExperiment", "Instantiated");
    if (!isfinite(start_time)) {
        char v[40];
        return tapmp_invalid(inst, "startTime", tapmp_repr(start_time, v), "a finite number", 0);
    }
    inst->time = start_time;
    return ST_OK;
}

int tapmp_enter_initialization(tapmp_instance *inst)
{
    if (inst->mode != MODE_INSTANTIATED)
        return tapmp_mode_error(inst, "EnterInitializationMode", "Instantiated");
    inst->mode = MODE_INITIALIZATION;
    inst->dirty = 1;
    return inst->failed ? ST_ERROR : setup(inst);
}

int tapmp_exit_initialization(tapmp_instance *inst)
{
    if (inst->mode != MODE_INITIALIZATION)
        return tapmp_mode_error(inst, "ExitInitializationMode", "Initialization Mode");
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
    if (!outputs_finite(inst, saved, inst->time, msg, sizeof msg)) return tapmp_fail(inst, "%s", msg);
    return ST_OK;
}

int tapmp_do_step(tapmp_instance *inst, double t, double h)
{
    char v[40], w[40], allowed[160], msg[TAPMP_MESSAGE_MAX];
    if (inst->mode != MODE_STEP) {
        const char *hint = inst->mode == MODE_TERMINATED ? " (the instance is terminated; reset it first)" :
                           inst->mode == MODE_EVENT ? " (finish the event first: fmi3UpdateDiscreteStates, "
                           "fmi3EnterStepMode)" :
                           " (leave initialization first: EnterInitializationMode, ExitInitializationMode)";
        return tapmp_fail(inst, "%sDoStep is not allowed in %s: allowed in Step Mode%s", inst->fmi,
                          MODE_NAMES[inst->mode], hint);
    }
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
    double tol = time_tolerance(inst->time);
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
        if (!model_validate(inst, msg, sizeof msg) || !check_ranges(inst, msg, sizeof msg)) {
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

/* --- events (FMI 3.0 Event Mode) ----------------------------------------------------- */

int tapmp_enter_event_mode(tapmp_instance *inst)
{
    if (!inst->event_mode_used)
        return tapmp_fail(inst, "%sEnterEventMode is not allowed: the instance was created with eventModeUsed = "
                          "false (allowed: instantiate with eventModeUsed = true)", inst->fmi);
    if (inst->mode == MODE_EVENT) return ST_OK;  /* the host may announce an event it is in already */
    if (inst->mode != MODE_STEP) return tapmp_mode_error(inst, "EnterEventMode", "Step Mode");
    if (inst->failed) return tapmp_fail(inst, "%sEnterEventMode refused after an earlier error: %s", inst->fmi,
                                        inst->error);
    inst->mode = MODE_EVENT;
    inst->clock_active = 0;  /* a tick belongs to the event it was set in: none carries into this one */
    return ST_OK;
}

int tapmp_update_discrete_states(tapmp_instance *inst, int *values_changed, int *next_defined, double *next_time)
{
    char v[40], msg[TAPMP_MESSAGE_MAX];
    double out[MODEL_N_OUT];
    if (inst->mode != MODE_EVENT) return tapmp_mode_error(inst, "UpdateDiscreteStates", "Event Mode");
    if (inst->failed) return tapmp_fail(inst, "%sUpdateDiscreteStates at t = %.6g s refused after an earlier error: "
                                        "%s", inst->fmi, inst->time, inst->error);
    ModelData before = inst->m;
    if (inst->retune) {  /* new tunable values take effect at this event */
        inst->retune = 0;
        if (!model_validate(inst, msg, sizeof msg) || !check_ranges(inst, msg, sizeof msg))
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
    if (inst->mode != MODE_EVENT) return tapmp_mode_error(inst, "EnterStepMode", "Event Mode");
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
    double te;
    *event_needed = *early_return = 0;
    if (!inst->event_mode_used || inst->mode != MODE_STEP || inst->failed || !isfinite(t) ||
        !(isfinite(h) && h > 0.0) || !model_next_event(inst, &te)) {
        int status = tapmp_do_step(inst, t, h);  /* no event ahead, or its checks refuse the call */
        *last_time = inst->time;
        return status;
    }
    char v[40], w[40];
    double tol = time_tolerance(te);
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
static int check_clock_refs(tapmp_instance *inst, const char *call, const unsigned vr[], size_t n, const void *v)
{
    char value[40], allowed[160];
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
    int status = check_clock_refs(inst, "SetClock", vr, n, v);
    if (status != ST_OK || n == 0) return status;
    if (inst->mode != MODE_EVENT)  /* an input clock ticks only in Event Mode (FMI 3.0, Clocks) */
        return tapmp_mode_error(inst, "SetClock", "Event Mode (the clock " MODEL_CLOCK_NAME " ticks at an event)");
    if (inst->failed)
        return tapmp_fail(inst, "%sSetClock refused after an earlier error: %s", inst->fmi, inst->error);
    for (size_t i = 0; i < n; i++) inst->clock_active = v[i] != 0;
    return ST_OK;
}

int tapmp_get_clock(tapmp_instance *inst, const unsigned vr[], size_t n, int v[])
{
    int status = check_clock_refs(inst, "GetClock", vr, n, v);
    if (status != ST_OK) return status;
    for (size_t i = 0; i < n; i++) v[i] = inst->mode == MODE_EVENT && inst->clock_active;
    return ST_OK;
}

int tapmp_get_interval(tapmp_instance *inst, const unsigned vr[], size_t n, double interval[], int qualifier[])
{
    int status = check_clock_refs(inst, "GetIntervalDecimal", vr, n, interval);
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
    char value[40], period[40], allowed[200];
    int status = check_clock_refs(inst, "SetIntervalDecimal", vr, n, interval);
    if (status != ST_OK || n == 0) return status;
    if (inst->mode != MODE_INSTANTIATED && inst->mode != MODE_INITIALIZATION)
        return tapmp_mode_error(inst, "SetIntervalDecimal", "Instantiated or Initialization Mode (the interval of "
                                "the clock " MODEL_CLOCK_NAME " is fixed once the model runs)");
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
    int status = check_clock_refs(inst, "GetShiftDecimal", vr, n, shift);
    if (status != ST_OK) return status;
    for (size_t i = 0; i < n; i++) shift[i] = 0.0;
    return ST_OK;
}

int tapmp_set_shift(tapmp_instance *inst, const unsigned vr[], size_t n, const double shift[])
{
    char value[40];
    int status = check_clock_refs(inst, "SetShiftDecimal", vr, n, shift);
    if (status != ST_OK || n == 0) return status;
    if (inst->mode != MODE_INSTANTIATED && inst->mode != MODE_INITIALIZATION)
        return tapmp_mode_error(inst, "SetShiftDecimal", "Instantiated or Initialization Mode");
    for (size_t i = 0; i < n; i++)
        if (shift[i] != 0.0)
            return tapmp_invalid(inst, "shift of " MODEL_CLOCK_NAME, tapmp_repr(shift[i], value),
                                 "0 (the controller samples at t0 + k T_s, t0 the start time)", 0);
    return ST_OK;
}
#endif

int tapmp_terminate(tapmp_instance *inst)
{
    if (!MODE_RUNNING(inst->mode) && !inst->failed)
        return tapmp_mode_error(inst, "Terminate", inst->event_mode_used ? "Step Mode or Event Mode" : "Step Mode");
    inst->mode = MODE_TERMINATED;
    inst->clock_active = 0;  /* a tick lives in its event only */
    return ST_OK;
}

int tapmp_reset(tapmp_instance *inst)
{
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

/* The names of the get and set calls in messages, per FMI version. */
static const char *call_name(const tapmp_instance *inst, int set, char type)
{
    int fmi3 = inst->fmi[3] == '3';
    if (type == 'R') return set ? (fmi3 ? "SetFloat64" : "SetReal") : (fmi3 ? "GetFloat64" : "GetReal");
    return set ? (fmi3 ? "SetInt32" : "SetInteger") : (fmi3 ? "GetInt32" : "GetInteger");
}

static int bad_vr(tapmp_instance *inst, const char *call, unsigned vr, char type)
{
    return tapmp_fail(inst, "%s%s: value reference %u is invalid: allowed are the %s variables of %s "
                      "(see modelDescription.xml)", inst->fmi, call, vr,
                      type == 'R' ? (inst->fmi[3] == '3' ? "Float64" : "Real") : (inst->fmi[3] == '3' ? "Int32" : "Integer"),
                      MODEL_IDENTIFIER_STRING);
}

/* The arrays of a get or set: n value references and nv values, both readable (or, for
 * a get, writable) over their whole length before anything is touched. */
static int check_arrays(tapmp_instance *inst, const char *call, const unsigned vr[], size_t n, const void *v,
                        size_t nv)
{
    if (nv != n)
        return tapmp_fail(inst, "%s%s: nValues = %zu is invalid: allowed is %zu, the number of value references "
                          "(every variable of %s is a scalar)", inst->fmi, call, nv, n, MODEL_IDENTIFIER_STRING);
    if (n && (!vr || !v))
        return tapmp_fail(inst, "%s%s: %s = NULL is invalid: allowed is an array of %zu elements", inst->fmi, call,
                          !vr ? "valueReferences" : "values", n);
    return ST_OK;
}

int tapmp_require_pointer(tapmp_instance *inst, const void *p, const char *call, const char *what)
{
    if (p) return ST_OK;
    return tapmp_fail(inst, "%s%s: %s = NULL is invalid: allowed is a pointer to write the result to", inst->fmi,
                      call, what);
}

/* FMI lets a master set parameters and inputs in Initialization Mode and read the
 * outputs (initial unknowns) before leaving it; libcosim, Ecos and fmpy's container do.
 * The first get after a set recomputes them. A combination that is invalid may be a
 * master's half-way point: the outputs keep their values, and ExitInitializationMode,
 * which sets the model up again, reports the error if it is still there. */
static void update_initial_unknowns(tapmp_instance *inst)
{
    char msg[TAPMP_MESSAGE_MAX];
    double saved[MODEL_N_OUT];
    inst->dirty = 0;
    if (inst->failed || !model_validate(inst, msg, sizeof msg) || !check_ranges(inst, msg, sizeof msg))
        return;
    memcpy(saved, inst->reals + MODEL_OUT_FIRST, sizeof saved);
    model_setup(inst);
    inst->has_model = 1;
    if (model_initial_outputs(inst, msg, sizeof msg)) outputs_finite(inst, saved, inst->time, msg, sizeof msg);
    else memcpy(inst->reals + MODEL_OUT_FIRST, saved, sizeof saved);
}

int tapmp_get_real(tapmp_instance *inst, const unsigned vr[], size_t n, double v[], size_t nv)
{
    const char *call = call_name(inst, 0, 'R');
    int status = check_arrays(inst, call, vr, n, v, nv);
    if (status != ST_OK) return status;
    if (inst->dirty && inst->mode == MODE_INITIALIZATION) update_initial_unknowns(inst);
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == N_VARS && inst->fmi[3] == '3') {  /* FMI 3.0's independent variable `time` */
            v[i] = inst->time;
            continue;
        }
        if (vr[i] >= N_VARS || VARS[vr[i]].type != 'R') return bad_vr(inst, call, vr[i], 'R');
        v[i] = inst->reals[vr[i]];
    }
    return ST_OK;
}

int tapmp_get_integer(tapmp_instance *inst, const unsigned vr[], size_t n, int v[], size_t nv)
{
    const char *call = call_name(inst, 0, 'I');
    int status = check_arrays(inst, call, vr, n, v, nv);
    if (status != ST_OK) return status;
    if (inst->dirty && inst->mode == MODE_INITIALIZATION) update_initial_unknowns(inst);
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= N_VARS || VARS[vr[i]].type != 'I') return bad_vr(inst, call, vr[i], 'I');
        v[i] = inst->ints[vr[i]];
    }
    return ST_OK;
}

/* OK if variable vr may be set to x now, else the logged error. The value is printed
 * only for a message (Python's repr for a Real, %d for an Integer). */
static int settable(tapmp_instance *inst, unsigned vr, double x, const char *call)
{
    const tapmp_var *var = &VARS[vr];
    char text[40];
    if (inst->mode == MODE_TERMINATED) return tapmp_mode_error(inst, call, "Instantiated, Initialization "
                                                               "Mode or Step Mode");
    if (var->causality == 'i') return ST_OK;
    if (var->type == 'R') tapmp_repr(x, text);
    else snprintf(text, sizeof text, "%d", (int)x);
    if (var->causality == 'o') return tapmp_invalid(inst, var->name, text, "no value: it is an output", 0);
    if (var->variability == 'f' && MODE_RUNNING(inst->mode))
        return tapmp_invalid(inst, var->name, text, "no change after initialization: it is a fixed parameter", 0);
    return ST_OK;
}

/* A tunable parameter set in Step Mode is checked at once: the model's own rules, then
 * the declared range. On failure the previous value stays. */
static int check_tunable(tapmp_instance *inst, unsigned vr, double old_real, int old_int)
{
    char msg[TAPMP_MESSAGE_MAX];
    if (!MODE_RUNNING(inst->mode) || VARS[vr].variability != 't') return ST_OK;
    if (model_validate(inst, msg, sizeof msg) && check_ranges(inst, msg, sizeof msg)) {
        inst->retune = 1;
        return ST_OK;
    }
    inst->reals[vr] = old_real;
    inst->ints[vr] = old_int;
    return tapmp_fail(inst, "%s (at t = %.6g s)", msg, inst->time);
}

int tapmp_set_real(tapmp_instance *inst, const unsigned vr[], size_t n, const double v[], size_t nv)
{
    char text[40];
    int worst = ST_OK;
    const char *call = call_name(inst, 1, 'R');
    int status = check_arrays(inst, call, vr, n, v, nv);
    if (status != ST_OK) return status;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= N_VARS || VARS[vr[i]].type != 'R') return bad_vr(inst, call, vr[i], 'R');
        status = settable(inst, vr[i], v[i], call);
        if (status != ST_OK) return status;
        if (!isfinite(v[i])) {
            int answer = model_input_status(inst, vr[i], v[i]);  /* a status the model answers with, or -1 */
            if (answer >= 0) {  /* the value is ignored */
                if (answer > worst) worst = answer;
                continue;
            }
            return tapmp_invalid(inst, VARS[vr[i]].name, tapmp_repr(v[i], text), "a finite number", 1);
        }
        double old = inst->reals[vr[i]];
        inst->reals[vr[i]] = v[i];
        inst->dirty |= inst->mode == MODE_INITIALIZATION;
        if ((status = check_tunable(inst, vr[i], old, inst->ints[vr[i]])) != ST_OK) return status;
    }
    return worst;
}

int tapmp_set_integer(tapmp_instance *inst, const unsigned vr[], size_t n, const int v[], size_t nv)
{
    const char *call = call_name(inst, 1, 'I');
    int status = check_arrays(inst, call, vr, n, v, nv);
    if (status != ST_OK) return status;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= N_VARS || VARS[vr[i]].type != 'I') return bad_vr(inst, call, vr[i], 'I');
        status = settable(inst, vr[i], (double)v[i], call);
        if (status != ST_OK) return status;
        int old = inst->ints[vr[i]];
        inst->ints[vr[i]] = v[i];
        inst->dirty |= inst->mode == MODE_INITIALIZATION;
        if ((status = check_tunable(inst, vr[i], inst->reals[vr[i]], old)) != ST_OK) return status;
    }
    return ST_OK;
}

/* --- FMU state ---------------------------------------------------------------------- */
/* The state is the instance from `mode` to the end. Serialized, it is a fixed layout:
 * magic, model identifier, variable count, then the values in native byte order. */
struct tapmp_state {
    unsigned magic;
    tapmp_instance copy;
};
#define STATE_MAGIC 0x5EA7E001u
/* Format 2 adds the Model Exchange mode flag and time floor and the clock's tick: a state of
 * format 1 has another size and magic and is refused as not this FMU's. */
static const char SERIAL_MAGIC[8] = {'T', 'A', 'P', 'M', 'P', 'S', 'T', '2'};

typedef struct {
    char magic[8];
    char model[32];
    int n_vars, n_hidden, mode, failed, retune, has_model, me_continuous, clock_active;
    double time, me_floor;
    double reals[N_VARS];
    int ints[N_VARS];
    double hidden[MODEL_N_HIDDEN > 0 ? MODEL_N_HIDDEN : 1];
    char error[TAPMP_MESSAGE_MAX];
} serial_layout;

/* Is s a state this instance holds? Compares pointers only: s is never read. */
static int held(const tapmp_instance *inst, const tapmp_state *s)
{
    for (size_t i = 0; s && i < inst->n_states; i++)
        if (inst->states[i] == s) return 1;
    return 0;
}

/* Record a new state as held; 0 if out of memory (the state is then freed). */
static int hold(tapmp_instance *inst, tapmp_state *s)
{
    if (inst->n_states == inst->max_states) {
        size_t max = inst->max_states ? 2 * inst->max_states : 4;
        tapmp_state **grown = realloc(inst->states, max * sizeof *grown);
        if (!grown) {
            free(s);
            return 0;
        }
        inst->states = grown;
        inst->max_states = max;
    }
    inst->states[inst->n_states++] = s;
    return 1;
}

static void release(tapmp_instance *inst, tapmp_state *s)
{
    for (size_t i = 0; i < inst->n_states; i++)
        if (inst->states[i] == s) {
            inst->states[i] = inst->states[--inst->n_states];
            break;
        }
    free(s);
}

/* The FMU state calls, as each FMI version spells them. */
enum { GET_STATE, SET_STATE, FREE_STATE, STATE_SIZE, SERIALIZE, DESERIALIZE };
static const char *state_call(const tapmp_instance *inst, int call)
{
    static const char *const fmi2[] = {"fmi2GetFMUstate", "fmi2SetFMUstate", "fmi2FreeFMUstate",
                                       "fmi2SerializedFMUstateSize", "fmi2SerializeFMUstate", "fmi2DeSerializeFMUstate"};
    static const char *const fmi3[] = {"fmi3GetFMUState", "fmi3SetFMUState", "fmi3FreeFMUState",
                                       "fmi3SerializedFMUStateSize", "fmi3SerializeFMUState", "fmi3DeserializeFMUState"};
    return inst->fmi[3] == '3' ? fmi3[call] : fmi2[call];
}

/* The error for a state argument this instance does not hold. */
static int foreign_state(tapmp_instance *inst, int call)
{
    return tapmp_fail(inst, "%s: FMUstate is invalid: allowed is a state from %s or %s of this instance that was "
                      "not freed", state_call(inst, call), state_call(inst, GET_STATE), state_call(inst, DESERIALIZE));
}

int tapmp_get_state(tapmp_instance *inst, tapmp_state **state)
{
    if (!state) return tapmp_fail(inst, "%s: FMUstate pointer is NULL", state_call(inst, GET_STATE));
    tapmp_state *s = *state;
    if (s && !held(inst, s))  /* FMI: NULL for a new state, or one of this instance's to overwrite */
        return tapmp_fail(inst, "%s: *FMUstate is invalid: allowed is NULL (a new state) or a state from %s or %s "
                          "of this instance that was not freed", state_call(inst, GET_STATE),
                          state_call(inst, GET_STATE), state_call(inst, DESERIALIZE));
    if (!s) {
        s = calloc(1, sizeof *s);
        if (!s || !hold(inst, s))  /* hold frees s if it cannot record it */
            return tapmp_fail(inst, "%s: out of memory", state_call(inst, GET_STATE));
        s->magic = STATE_MAGIC;
    }
    if (inst->has_model) model_capture(inst);
    s->copy = *inst;
    *state = s;
    return ST_OK;
}

/* The parts of a state that need no model: its mode, whether a model is built (as that mode
 * requires), its time and its Real values finite; 0 + msg if one is not valid. */
static int validate_values(const tapmp_instance *c, char *msg, size_t size)
{
    char v[40];
    if (c->mode < MODE_INSTANTIATED || c->mode > MODE_LAST) {
        snprintf(msg, size, "FMU state: mode = %d is invalid: allowed are 0 to %d", (int)c->mode, (int)MODE_LAST);
        return 0;
    }
    /* EnterInitializationMode builds the model or fails: every later mode has one unless an error
     * stopped the instance; Instantiated (after Reset too) has none */
    int needs_model = c->mode != MODE_INSTANTIATED && !c->failed;
    if (needs_model != c->has_model && (c->mode == MODE_INSTANTIATED || needs_model)) {
        snprintf(msg, size, "FMU state: has_model = %d is invalid in %s: allowed is %d (%s)", c->has_model,
                 MODE_NAMES[c->mode], needs_model, needs_model ? "a model is built on entering Initialization "
                 "Mode" : "no model is built before Initialization Mode");
        return 0;
    }
    if (!isfinite(c->time)) return tapmp_invalid_text(msg, size, "FMU state: time", tapmp_repr(c->time, v),
                                                      "a finite number", 0, 0.0);
    /* Continuous-Time Mode is a mode of a Model Exchange instance after initialization */
    if (c->me_continuous && !(c->model_exchange && c->mode == MODE_STEP)) {
        snprintf(msg, size, "FMU state: Continuous-Time Mode = 1 is invalid in %s of a %s instance: allowed is 0 "
                 "(only a Model Exchange instance after initialization is in Continuous-Time Mode)",
                 MODE_NAMES[c->mode], c->model_exchange ? "Model Exchange" : "Co-Simulation");
        return 0;
    }
    if (c->model_exchange && c->mode == MODE_STEP &&
        !(isfinite(c->me_floor) && c->me_floor <= c->time + time_tolerance(c->time))) {
        char allowed[96], t[40];
        snprintf(allowed, sizeof allowed, "a finite time <= the state's time, %s s", tapmp_repr(c->time, t));
        return tapmp_invalid_text(msg, size, "FMU state: last accepted time", tapmp_repr(c->me_floor, v), allowed,
                                  0, 0.0);
    }
    if (c->clock_active && c->mode != MODE_EVENT) {  /* a tick lives in the event it was set in */
        snprintf(msg, size, "FMU state: clock tick = 1 is invalid in %s: allowed is 0 (a tick exists only in the "
                 "Event Mode it was set in)", MODE_NAMES[c->mode]);
        return 0;
    }
    for (int vr = 0; vr < N_VARS; vr++)
        if (VARS[vr].type == 'R' && !isfinite(c->reals[vr]))
            return tapmp_invalid_text(msg, size, VARS[vr].name, tapmp_repr(c->reals[vr], v),
                                      "a finite number (in the FMU state)", 0, 0.0);
    return 1;
}

/* The model's part of a state with a model: its settings, then its hidden values (finite, then
 * model_check_hidden); 0 + msg if one is not valid. */
static int validate_model(const tapmp_instance *c, const double hidden[], char *msg, size_t size)
{
    char v[40];
    if (!model_validate(c, msg, size) || !check_ranges(c, msg, size)) return 0;
    for (int i = 0; i < MODEL_N_HIDDEN; i++)
        if (!isfinite(hidden[i])) {
            snprintf(msg, size, "FMU state: hidden state value %d = %s is invalid: allowed is a finite "
                     "number", i, tapmp_repr(hidden[i], v));
            return 0;
        }
    static const char prefix[] = "FMU state: ";  /* the model's message follows it in msg (size > the prefix) */
    memcpy(msg, prefix, sizeof prefix - 1);
    return model_check_hidden(c, hidden, msg + sizeof prefix - 1, size - (sizeof prefix - 1));
}

/* Check a state fully before any of it is applied; 0 + msg if it is not valid. */
static int validate_state(const tapmp_instance *c, char *msg, size_t size)
{
    double hidden[MODEL_N_HIDDEN > 0 ? MODEL_N_HIDDEN : 1];
    if (!validate_values(c, msg, size)) return 0;
    if (!c->has_model) return 1;
    model_get_hidden(c, hidden);
    return validate_model(c, hidden, msg, size);
}

/* Apply a validated copy: everything from `mode` on, keeping identity and callbacks. */
static void apply_state(tapmp_instance *inst, const tapmp_instance *c)
{
    inst->mode = c->mode;
    inst->time = c->time;
    inst->me_continuous = c->me_continuous;
    inst->me_floor = c->me_floor;
    inst->clock_active = c->clock_active;
    inst->failed = c->failed;
    inst->retune = c->retune;
    inst->has_model = c->has_model;
    inst->dirty = c->dirty;
    memcpy(inst->reals, c->reals, sizeof inst->reals);
    memcpy(inst->ints, c->ints, sizeof inst->ints);
    inst->m = c->m;
    memcpy(inst->error, c->error, sizeof inst->error);
}

int tapmp_set_state(tapmp_instance *inst, const tapmp_state *state)
{
    char msg[TAPMP_MESSAGE_MAX];
    if (!held(inst, state)) return foreign_state(inst, SET_STATE);
    if (!validate_state(&state->copy, msg, sizeof msg))
        return tapmp_fail(inst, "%s: %s; nothing was changed", state_call(inst, SET_STATE), msg);
    apply_state(inst, &state->copy);
    return ST_OK;
}

int tapmp_free_state(tapmp_instance *inst, tapmp_state **state)
{
    if (!state || !*state) return ST_OK;  /* FMI: a NULL state is ignored */
    if (!held(inst, *state)) return foreign_state(inst, FREE_STATE);
    release(inst, *state);
    *state = NULL;
    return ST_OK;
}

int tapmp_serialized_size(tapmp_instance *inst, const tapmp_state *state, size_t *size)
{
    if (!held(inst, state)) return foreign_state(inst, STATE_SIZE);
    int status = tapmp_require_pointer(inst, size, state_call(inst, STATE_SIZE) + 4, "size");
    if (status == ST_OK) *size = sizeof(serial_layout);
    return status;
}

int tapmp_serialize(tapmp_instance *inst, const tapmp_state *state, char *bytes, size_t size)
{
    if (!held(inst, state)) return foreign_state(inst, SERIALIZE);
    if (size < sizeof(serial_layout))
        return tapmp_fail(inst, "%s: size = %zu is invalid: allowed is >= %zu (from %s)", state_call(inst, SERIALIZE),
                          size, sizeof(serial_layout), state_call(inst, STATE_SIZE));
    if (!bytes) return tapmp_fail(inst, "%s: serializedState = NULL is invalid: allowed is an array of size bytes",
                                  state_call(inst, SERIALIZE));
    serial_layout *s = calloc(1, sizeof *s);
    if (!s) return tapmp_fail(inst, "%s: out of memory", state_call(inst, SERIALIZE));
    const tapmp_instance *c = &state->copy;
    memcpy(s->magic, SERIAL_MAGIC, sizeof s->magic);
    snprintf(s->model, sizeof s->model, "%s", MODEL_IDENTIFIER_STRING);
    s->n_vars = N_VARS;
    s->n_hidden = MODEL_N_HIDDEN;
    s->mode = (int)c->mode;
    s->failed = c->failed;
    s->retune = c->retune;
    s->has_model = c->has_model;
    s->me_continuous = c->me_continuous;
    s->clock_active = c->clock_active;
    s->time = c->time;
    s->me_floor = c->me_floor;
    memcpy(s->reals, c->reals, sizeof s->reals);
    memcpy(s->ints, c->ints, sizeof s->ints);
    if (c->has_model) model_get_hidden(c, s->hidden);
    memcpy(s->error, c->error, sizeof s->error);
    memcpy(bytes, s, sizeof *s);
    free(s);
    return ST_OK;
}

int tapmp_deserialize(tapmp_instance *inst, const char *bytes, size_t size, tapmp_state **state)
{
    char msg[TAPMP_MESSAGE_MAX];
    const char *call = state_call(inst, DESERIALIZE);
    if (!state) return tapmp_fail(inst, "%s: FMUstate pointer is NULL", call);
    if (!bytes || size != sizeof(serial_layout))
        return tapmp_fail(inst, "%s: size = %zu is invalid: allowed is %zu (a state serialized by this FMU)", call,
                          size, sizeof(serial_layout));
    serial_layout *s = malloc(sizeof *s);
    tapmp_state *st = calloc(1, sizeof *st);
    if (!s || !st) {
        free(s);
        free(st);
        return tapmp_fail(inst, "%s: out of memory", call);
    }
    memcpy(s, bytes, sizeof *s);
    int ok = 1;
    if (memcmp(s->magic, SERIAL_MAGIC, sizeof s->magic) != 0 ||
        strncmp(s->model, MODEL_IDENTIFIER_STRING, sizeof s->model) != 0 || s->n_vars != N_VARS ||
        s->n_hidden != MODEL_N_HIDDEN) {
        snprintf(msg, sizeof msg, "the bytes are not a state of %s serialized by this FMU",
                 MODEL_IDENTIFIER_STRING);
        ok = 0;
    }
    tapmp_instance *c = &st->copy;
    if (ok) {
        *c = *inst;
        c->mode = s->mode >= MODE_INSTANTIATED && s->mode <= MODE_LAST ? (tapmp_mode)s->mode : MODE_INSTANTIATED;
        c->failed = s->failed != 0;
        c->retune = s->retune != 0;
        c->has_model = s->has_model != 0;  /* as claimed: validate_values checks it against the mode */
        c->me_continuous = s->me_continuous != 0;  /* as claimed: validate_values checks them against the mode */
        c->clock_active = s->clock_active != 0;
        c->time = s->time;
        c->me_floor = s->me_floor;
        memcpy(c->reals, s->reals, sizeof c->reals);
        memcpy(c->ints, s->ints, sizeof c->ints);
        s->error[sizeof s->error - 1] = 0;
        memcpy(c->error, s->error, sizeof c->error);
        memset(&c->m, 0, sizeof c->m);
        if (s->mode != (int)c->mode) {
            snprintf(msg, sizeof msg, "FMU state: mode = %d is invalid: allowed are 0 to %d", s->mode, (int)MODE_LAST);
            ok = 0;
        } else if ((ok = validate_values(c, msg, sizeof msg)) && c->has_model &&
                   (ok = validate_model(c, s->hidden, msg, sizeof msg))) {
            /* the model data from the checked settings and hidden values; the serialized outputs stand */
#ifndef MODEL_OWN_RESOURCES
            model_setup(c);
#endif
            model_set_hidden(c, s->hidden);  /* a model with its own resources keeps them as data */
            memcpy(c->reals, s->reals, sizeof c->reals);
        }
    }
    free(s);
    if (!ok) {
        free(st);
        return tapmp_fail(inst, "%s: %s; nothing was changed", call, msg);
    }
    if (*state && !held(inst, *state)) {  /* FMI: NULL for a new state, or one of this instance's to replace */
        free(st);
        return tapmp_fail(inst, "%s: *FMUstate is invalid: allowed is NULL (a new state) or a state of this instance "
                          "that was not freed", call);
    }
    if (!hold(inst, st)) return tapmp_fail(inst, "%s: out of memory", call);
    st->magic = STATE_MAGIC;
    if (*state) release(inst, *state);
    *state = st;
    return ST_OK;
}

#ifdef MODEL_N_STATES
/* --- Model Exchange (FMI 2.0 and 3.0): the host integrates the model's continuous state ------ */

static const char *me_mode_name(const tapmp_instance *inst)
{
    if (inst->mode == MODE_STEP) return inst->me_continuous ? "Continuous-Time Mode" : "Event Mode";
    return MODE_NAMES[inst->mode];
}

/* The names of the modes of `modes` (ME_INIT ...), joined as "A, B and C". */
static const char *me_modes_text(int modes)
{
    static const char *const texts[8] = {"no mode", "Initialization Mode", "Event Mode",
                                         "Initialization Mode and Event Mode", "Continuous-Time Mode",
                                         "Initialization Mode and Continuous-Time Mode",
                                         "Event Mode and Continuous-Time Mode",
                                         "Initialization Mode, Event Mode and Continuous-Time Mode"};
    return texts[modes & 7];
}

int tapmp_me_allowed(tapmp_instance *inst, const char *call, int modes)
{
    if (!inst->model_exchange)
        return tapmp_fail(inst, "%s%s is not allowed: the instance was instantiated for Co-Simulation (%s)", inst->fmi,
                          call, inst->fmi[3] == '3' ? "fmi3InstantiateCoSimulation" : "fmuType = fmi2CoSimulation");
    if (inst->failed) return tapmp_fail(inst, "%s%s refused after an earlier error: %s", inst->fmi, call, inst->error);
    int bit = inst->mode == MODE_INITIALIZATION ? ME_INIT : inst->mode != MODE_STEP ? 0
              : inst->me_continuous ? ME_CONTINUOUS : ME_EVENT;
    if (!(modes & bit))
        return tapmp_fail(inst, "%s%s is not allowed in %s: allowed in %s", inst->fmi, call, me_mode_name(inst),
                          me_modes_text(modes));
    return ST_OK;
}

int tapmp_me_exit_initialization(tapmp_instance *inst)
{
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
    int status = tapmp_me_allowed(inst, "SetTime", ME_AFTER_INIT);
    if (status != ST_OK) return status;
    char v[40], w[40], allowed[200];
    if (!isfinite(time)) return tapmp_invalid(inst, "time", tapmp_repr(time, v), "a finite number", 0);
    /* An integrator may go back over a step it rejects, but never before the last point it accepted:
     * the end of initialization, an event, or a completed integrator step (FMI's CompletedIntegratorStep). */
    double tol = time_tolerance(inst->me_floor);
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
    int status = tapmp_me_allowed(inst, "SetContinuousStates", ME_AFTER_INIT);
    if (status == ST_OK) status = me_array(inst, "SetContinuousStates", x, nx, MODEL_N_STATES, "nx");
    if (status != ST_OK) return status;
    char msg[TAPMP_MESSAGE_MAX];
    ModelData before = inst->m;
    double saved[MODEL_N_OUT];
    memcpy(saved, inst->reals + MODEL_OUT_FIRST, sizeof saved);
    if (!model_me_set_states(inst, x, msg, sizeof msg)) return tapmp_fail(inst, "%s", msg);
    if (!outputs_finite(inst, saved, inst->time, msg, sizeof msg)) {  /* the outputs put back; the state too */
        inst->m = before;
        return tapmp_fail(inst, "%sSetContinuousStates: %s", inst->fmi, msg);
    }
    return ST_OK;
}

int tapmp_me_get_states(tapmp_instance *inst, const char *call, double x[], size_t nx)
{
    int status = tapmp_me_allowed(inst, call, ME_ANY);
    if (status == ST_OK) status = me_array(inst, call, x, nx, MODEL_N_STATES, "nx");
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

int tapmp_me_get_derivatives(tapmp_instance *inst, const char *call, double dx[], size_t nx)
{
    int status = tapmp_me_allowed(inst, call, ME_ANY);
    if (status == ST_OK) status = me_array(inst, call, dx, nx, MODEL_N_STATES, "nx");
    if (status != ST_OK) return status;
    double d[MODEL_N_STATES];
    status = me_derivatives(inst, call, d);
    if (status == ST_OK) memcpy(dx, d, sizeof d);
    return status;
}

int tapmp_me_get_real(tapmp_instance *inst, unsigned first, const unsigned vr[], size_t n, double v[], size_t nv)
{
    const char *call = call_name(inst, 0, 'R');
    int status = check_arrays(inst, call, vr, n, v, nv);
    if (status != ST_OK) return status;
    if (inst->failed) return tapmp_fail(inst, "%s%s refused after an earlier error: %s", inst->fmi, call, inst->error);
    /* in either interface, once the model is set up */
    if (inst->mode != MODE_INITIALIZATION && inst->mode != MODE_STEP)
        return tapmp_fail(inst, "%s%s of a state derivative is not allowed in %s: allowed from Initialization Mode "
                          "on", inst->fmi, call, inst->model_exchange ? me_mode_name(inst) : MODE_NAMES[inst->mode]);
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
    int status = tapmp_me_allowed(inst, "GetEventIndicators", ME_ANY);
    return status == ST_OK ? me_array(inst, "GetEventIndicators", z, ni, 0, "ni") : status;
}

int tapmp_me_nominals(tapmp_instance *inst, double nominals[], size_t nx)
{
    int status = tapmp_me_allowed(inst, "GetNominalsOfContinuousStates", ME_ANY);
    if (status == ST_OK) status = me_array(inst, "GetNominalsOfContinuousStates", nominals, nx, MODEL_N_STATES, "nx");
    if (status != ST_OK) return status;
    for (size_t i = 0; i < nx; i++) nominals[i] = 1.0;  /* the declared nominal of every Real */
    return ST_OK;
}

int tapmp_me_enter_event_mode(tapmp_instance *inst)
{
    int status = tapmp_me_allowed(inst, "EnterEventMode", ME_AFTER_INIT);
    if (status == ST_OK) {
        inst->me_continuous = 0;
        inst->me_floor = inst->time;  /* an event is a point the host accepted */
    }
    return status;
}

int tapmp_me_enter_continuous_time_mode(tapmp_instance *inst)
{
    int status = tapmp_me_allowed(inst, "EnterContinuousTimeMode", ME_EVENT);
    if (status == ST_OK) {
        inst->me_continuous = 1;
        inst->me_floor = inst->time;
    }
    return status;
}

int tapmp_me_completed_integrator_step(tapmp_instance *inst, int *enter_event_mode, int *terminate)
{
    int status = tapmp_me_allowed(inst, "CompletedIntegratorStep", ME_CONTINUOUS);
    if (status != ST_OK) return status;
    inst->me_floor = inst->time;  /* the integrator accepted the step that ends here */
    *enter_event_mode = 0;
    *terminate = 0;
    return ST_OK;
}

int tapmp_me_update(tapmp_instance *inst, const char *call, int *next_defined, double *next_time)
{
    int status = tapmp_me_allowed(inst, call, ME_EVENT);
    if (status != ST_OK) return status;
    double next = model_me_next_event_time(inst);
    *next_defined = isfinite(next);
    *next_time = isfinite(next) ? next : 0.0;
    return ST_OK;
}
#endif
