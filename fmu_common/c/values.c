/* Get and set of the variables (instance.h); the initial unknowns recomputed on a get in
 * Initialization Mode, a tunable parameter checked when it is set once the model runs. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "runtime.h"

static int bad_vr(tapmp_instance *inst, const char *call, unsigned vr, char type)
{
    return tapmp_fail(inst, "%s%s: value reference %u is invalid: allowed are the %s variables of %s "
                      "(see modelDescription.xml)", inst->fmi, call, vr,
                      type == 'R' ? (inst->fmi[3] == '3' ? "Float64" : "Real") : (inst->fmi[3] == '3' ? "Int32" : "Integer"),
                      MODEL_IDENTIFIER_STRING);
}

/* Both arrays are readable (or, for a get, writable) over their whole length before anything is
 * touched. */
int tapmp_check_arrays(tapmp_instance *inst, const char *call, const unsigned vr[], size_t n, const void *v,
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
    if (inst->failed || !model_validate(inst, msg, sizeof msg) || !tapmp_check_ranges(inst, msg, sizeof msg))
        return;
    memcpy(saved, inst->reals + MODEL_OUT_FIRST, sizeof saved);
    model_setup(inst);
    inst->has_model = 1;
    if (model_initial_outputs(inst, msg, sizeof msg)) tapmp_outputs_finite(inst, saved, inst->time, msg, sizeof msg);
    else memcpy(inst->reals + MODEL_OUT_FIRST, saved, sizeof saved);
}

int tapmp_get_real(tapmp_instance *inst, const unsigned vr[], size_t n, double v[], size_t nv)
{
    ALLOW(inst, OP_GET_REAL);
    const char *call = tapmp_call(inst, OP_GET_REAL);
    int status = tapmp_check_arrays(inst, call, vr, n, v, nv);
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
    ALLOW(inst, OP_GET_INTEGER);
    const char *call = tapmp_call(inst, OP_GET_INTEGER);
    int status = tapmp_check_arrays(inst, call, vr, n, v, nv);
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
static int settable(tapmp_instance *inst, unsigned vr, double x)
{
    const tapmp_var *var = &VARS[vr];
    char text[40];
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
    if (model_validate(inst, msg, sizeof msg) && tapmp_check_ranges(inst, msg, sizeof msg)) {
        inst->retune = 1;
        return ST_OK;
    }
    inst->reals[vr] = old_real;
    inst->ints[vr] = old_int;
    return tapmp_fail(inst, "%s (at t = %.6g s)", msg, inst->time);
}

int tapmp_set_real(tapmp_instance *inst, const unsigned vr[], size_t n, const double v[], size_t nv)
{
    ALLOW_VALUES(inst, OP_SET_REAL, n);
    const char *call = tapmp_call(inst, OP_SET_REAL);
    char text[40];
    int worst = ST_OK;
    int status = tapmp_check_arrays(inst, call, vr, n, v, nv);
    if (status != ST_OK) return status;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= N_VARS || VARS[vr[i]].type != 'R') return bad_vr(inst, call, vr[i], 'R');
        status = settable(inst, vr[i], v[i]);
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
    ALLOW_VALUES(inst, OP_SET_INTEGER, n);
    const char *call = tapmp_call(inst, OP_SET_INTEGER);
    int status = tapmp_check_arrays(inst, call, vr, n, v, nv);
    if (status != ST_OK) return status;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= N_VARS || VARS[vr[i]].type != 'I') return bad_vr(inst, call, vr[i], 'I');
        status = settable(inst, vr[i], (double)v[i]);
        if (status != ST_OK) return status;
        int old = inst->ints[vr[i]];
        inst->ints[vr[i]] = v[i];
        inst->dirty |= inst->mode == MODE_INITIALIZATION;
        if ((status = check_tunable(inst, vr[i], inst->reals[vr[i]], old)) != ST_OK) return status;
    }
    return ST_OK;
}
