/* FMU states (instance.h): get, set and free, serialized and deserialized; a state is checked
 * whole (its mode, settings, outputs and the model's hidden values, model_check_hidden) before any
 * of it is applied. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "runtime.h"

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

/* An FMU state call's full name as two arguments of a "%s%s" (the prefix fmi2 or fmi3, the name). */
#define STATE_CALL(op) inst->fmi, tapmp_call(inst, op)

/* The error for a state argument this instance does not hold. */
static int foreign_state(tapmp_instance *inst, tapmp_op op)
{
    return tapmp_fail(inst, "%s%s: FMUstate is invalid: allowed is a state from %s%s or %s%s of this instance that "
                      "was not freed", STATE_CALL(op), STATE_CALL(OP_GET_STATE), STATE_CALL(OP_DESERIALIZE));
}

int tapmp_get_state(tapmp_instance *inst, tapmp_state **state)
{
    ALLOW(inst, OP_GET_STATE);
    if (!state) return tapmp_fail(inst, "%s%s: FMUstate pointer is NULL", STATE_CALL(OP_GET_STATE));
    tapmp_state *s = *state;
    if (s && !held(inst, s))  /* FMI: NULL for a new state, or one of this instance's to overwrite */
        return tapmp_fail(inst, "%s%s: *FMUstate is invalid: allowed is NULL (a new state) or a state from %s%s or "
                          "%s%s of this instance that was not freed", STATE_CALL(OP_GET_STATE),
                          STATE_CALL(OP_GET_STATE), STATE_CALL(OP_DESERIALIZE));
    if (!s) {
        s = calloc(1, sizeof *s);
        if (!s || !hold(inst, s))  /* hold frees s if it cannot record it */
            return tapmp_fail(inst, "%s%s: out of memory", STATE_CALL(OP_GET_STATE));
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
                 tapmp_mode_name(c->mode), needs_model, needs_model ? "a model is built on entering Initialization "
                 "Mode" : "no model is built before Initialization Mode");
        return 0;
    }
    if (!isfinite(c->time)) return tapmp_invalid_text(msg, size, "FMU state: time", tapmp_repr(c->time, v),
                                                      "a finite number", 0, 0.0);
    /* Continuous-Time Mode is a mode of a Model Exchange instance after initialization */
    if (c->me_continuous && !(c->model_exchange && c->mode == MODE_STEP)) {
        snprintf(msg, size, "FMU state: Continuous-Time Mode = 1 is invalid in %s of a %s instance: allowed is 0 "
                 "(only a Model Exchange instance after initialization is in Continuous-Time Mode)",
                 tapmp_mode_name(c->mode), c->model_exchange ? "Model Exchange" : "Co-Simulation");
        return 0;
    }
    if (c->model_exchange && c->mode == MODE_STEP &&
        !(isfinite(c->me_floor) && c->me_floor <= c->time + tapmp_time_tolerance(c->time))) {
        char allowed[96], t[40];
        snprintf(allowed, sizeof allowed, "a finite time <= the state's time, %s s", tapmp_repr(c->time, t));
        return tapmp_invalid_text(msg, size, "FMU state: last accepted time", tapmp_repr(c->me_floor, v), allowed,
                                  0, 0.0);
    }
    if (c->clock_active && c->mode != MODE_EVENT) {  /* a tick lives in the event it was set in */
        snprintf(msg, size, "FMU state: clock tick = 1 is invalid in %s: allowed is 0 (a tick exists only in the "
                 "Event Mode it was set in)", tapmp_mode_name(c->mode));
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
    if (!model_validate(c, msg, size) || !tapmp_check_ranges(c, msg, size)) return 0;
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
    ALLOW(inst, OP_SET_STATE);
    char msg[TAPMP_MESSAGE_MAX];
    if (!held(inst, state)) return foreign_state(inst, OP_SET_STATE);
    if (!validate_state(&state->copy, msg, sizeof msg))
        return tapmp_fail(inst, "%s%s: %s; nothing was changed", STATE_CALL(OP_SET_STATE), msg);
    apply_state(inst, &state->copy);
    return ST_OK;
}

int tapmp_free_state(tapmp_instance *inst, tapmp_state **state)
{
    ALLOW(inst, OP_FREE_STATE);
    if (!state || !*state) return ST_OK;  /* FMI: a NULL state is ignored */
    if (!held(inst, *state)) return foreign_state(inst, OP_FREE_STATE);
    release(inst, *state);
    *state = NULL;
    return ST_OK;
}

int tapmp_serialized_size(tapmp_instance *inst, const tapmp_state *state, size_t *size)
{
    ALLOW(inst, OP_STATE_SIZE);
    if (!held(inst, state)) return foreign_state(inst, OP_STATE_SIZE);
    int status = tapmp_require_pointer(inst, size, tapmp_call(inst, OP_STATE_SIZE), "size");
    if (status == ST_OK) *size = sizeof(serial_layout);
    return status;
}

int tapmp_serialize(tapmp_instance *inst, const tapmp_state *state, char *bytes, size_t size)
{
    ALLOW(inst, OP_SERIALIZE);
    if (!held(inst, state)) return foreign_state(inst, OP_SERIALIZE);
    if (size < sizeof(serial_layout))
        return tapmp_fail(inst, "%s%s: size = %zu is invalid: allowed is >= %zu (from %s%s)", STATE_CALL(OP_SERIALIZE),
                          size, sizeof(serial_layout), STATE_CALL(OP_STATE_SIZE));
    if (!bytes) return tapmp_fail(inst, "%s%s: serializedState = NULL is invalid: allowed is an array of size bytes",
                                  STATE_CALL(OP_SERIALIZE));
    serial_layout *s = calloc(1, sizeof *s);
    if (!s) return tapmp_fail(inst, "%s%s: out of memory", STATE_CALL(OP_SERIALIZE));
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
    ALLOW(inst, OP_DESERIALIZE);
    char msg[TAPMP_MESSAGE_MAX], call[64];
    snprintf(call, sizeof call, "%s%s", STATE_CALL(OP_DESERIALIZE));
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
