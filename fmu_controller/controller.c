/* Native TAPMP_Controller FMU (and its clocked variant TAPMP_ControllerClocked, MODEL_CLOCK): maps the
 * FMU variables to the SC-DC / APD-DC / PID-DC controller of tapmp_model.c, as
 * fmu_controller/TAPMP_Controller.py maps them to tapmp.control.ControllerModel. On doStep(t, h) at a
 * sample instant t0 + k T_s not sampled yet it samples its inputs, computes the command and holds it; at
 * any other communication point the outputs hold (tapmp.control.ControllerModel.communication_point). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "instance.h"

/* Every parameter into the model's settings struct (generated from tapmp/interface.py); the
 * loop state (integral, previous q) and the clock are kept, the clock takes the sample period. */
static void read_settings(const tapmp_instance *inst, ModelData *m)
{
    MODEL_READ_SETTINGS(inst, &m->s);
    m->clock.T_s = m->s.k.T_s;
}

/* The range check of the settings as read_settings() takes them: tapmp.control.ControllerModel
 * and the Python model's validated() run the same. */
int model_validate(const tapmp_instance *inst, char *msg, size_t size)
{
    const char *name = NULL, *allowed = NULL;
    double x = 0.0;
    tapmp_controller_settings s;
    MODEL_READ_SETTINGS(inst, &s);
    return tapmp_range_text(tapmp_controller_settings_check(&s, &name, &x, &allowed), name, x, allowed, msg,
                            size);
}

void model_setup(tapmp_instance *inst)
{
    read_settings(inst, &inst->m);
    memset(&inst->m.st, 0, sizeof inst->m.st);
    inst->m.clock = (tapmp_clock){inst->time, inst->m.clock.T_s, 0.0, 0, 0};
}

static int sample(tapmp_instance *inst, double t, double h, int advance, double out[], char *msg,
                  size_t size)
{
    ModelData *m = &inst->m;
    double arg;
    const double *r = inst->reals;
    if (tapmp_controller_sample(&m->s.p, &m->s.g, m->s.k.law, m->s.k.velocity_source, m->s.k.force_limit,
                                m->s.k.anti_windup, m->s.k.anti_windup_time, &m->st, h,
                                r + VR_X_d, r + VR_q1, r + VR_dq1, advance, out, &m->st, &arg))
        return 1;
    char a[40], q1[40], q2[40], q3[40], l1[40], allowed[256];
    snprintf(allowed, sizeof allowed, "|value| < 1 (q = [%s, %s, %s] m, L1 = %s m)", tapmp_repr(r[VR_q1], q1),
             tapmp_repr(r[VR_q2], q2), tapmp_repr(r[VR_q3], q3), tapmp_repr(m->s.p.L_1, l1));
    tapmp_invalid_text(msg, size, "sqrt(3)/(2 L1)*(2 q2 - q1 - q3)", tapmp_repr(arg, a), allowed, 0, 0);
    (void)t;
    return 0;
}

int model_initial_outputs(tapmp_instance *inst, char *msg, size_t size)
{
    double out[MODEL_N_OUT];
    if (!sample(inst, inst->time, 0.0, 0, out, msg, size)) return 0;
    memcpy(inst->reals + MODEL_OUT_FIRST, out, sizeof out);
    return 1;
}

/* A warning of the clock (tapmp_clock_*_text), passed on whatever loggingOn says, as the
 * pythonfmu family's binary passes on every warning; doStep still returns OK. */
static void warn(tapmp_instance *inst, void (*text_of)(const tapmp_clock *, double, double, char *, size_t),
                 double t, double x)
{
    char text[TAPMP_MESSAGE_MAX];
    text_of(&inst->m.clock, t, x, text, sizeof text);
    if (inst->log) inst->log(inst, ST_WARNING, "logStatusWarning", text);
}

#ifdef MODEL_CLOCK
/* The clocked controller's one warning when a step from t by h [s] passes a tick of the input clock that the
 * host did not activate (an importer that does not schedule input clocks): the outputs hold, as they do
 * until the next tick the host activates. */
static void clock_missed(tapmp_instance *inst, double t, double h)
{
    tapmp_clock *clock = &inst->m.clock;
    double due = clock->t0 + (clock->has_sample ? clock->k_last + 1.0 : 0.0) * clock->T_s;
    if (clock->warned || !(t + h > due + TAPMP_SAMPLE_TOLERANCE * clock->T_s)) return;
    clock->warned = 1;
    char text[TAPMP_MESSAGE_MAX], a[40], b[40];
    snprintf(text, sizeof text, "the input clock " MODEL_CLOCK_NAME " (interval T_s = %g s) did not tick at t = %s "
             "s: the controller holds its command until the host activates the clock (fmi3SetClock in Event Mode, "
             "then fmi3UpdateDiscreteStates) at an instant t0 + k T_s; doStep reached t = %s s", clock->T_s,
             tapmp_repr(due, a), tapmp_repr(t + h, b));
    if (inst->log) inst->log(inst, ST_WARNING, "logStatusWarning", text);
}

double model_clock_interval(const tapmp_instance *inst) { return inst->reals[VR_T_s]; }
#endif

/* tapmp.control.ControllerModel.communication_point; with eventModeUsed the outputs hold in every
 * step: the controller samples in Event Mode (model_event_update). */
int model_step(tapmp_instance *inst, double t, double h, double out[], char *msg, size_t size)
{
    tapmp_clock *clock = &inst->m.clock;
    double k, steps, missed;
    (void)h;  /* the host's step never enters the law: the time between samples does */
    read_settings(inst, &inst->m);  /* new tunable values take effect here; the loop state carries over */
    if (inst->event_mode_used) {
        memcpy(out, inst->reals + MODEL_OUT_FIRST, MODEL_N_OUT * sizeof *out);
#ifdef MODEL_CLOCK
        clock_missed(inst, t, h);
#endif
        return 1;
    }
    if (!tapmp_clock_at(clock, t, &k, &steps, &missed)) {
        memcpy(out, inst->reals + MODEL_OUT_FIRST, MODEL_N_OUT * sizeof *out);  /* hold */
        if (!isnan(missed)) warn(inst, tapmp_clock_missed_text, t, missed);
        return 1;
    }
    if (sample(inst, t, steps * clock->T_s, 1, out, msg, size)) {
        if (tapmp_clock_sampled(clock, k, steps)) warn(inst, tapmp_clock_skipped_text, t, steps);
        return 1;
    }
    size_t n = strlen(msg);
    snprintf(msg + n, size - n, " (at t = %.6g s)", t);
    return 0;
}

/* tapmp.control.ControllerModel.next_event_time: the next sample instant not sampled yet, t0 + k T_s. */
int model_next_event(const tapmp_instance *inst, double *time)
{
#ifdef MODEL_CLOCK
    (void)inst, (void)time;
    return 0;  /* no time events of its own: the host activates the input clock at the sample instants */
#else
    const tapmp_clock *clock = &inst->m.clock;
    *time = clock->t0 + (clock->has_sample ? clock->k_last + 1.0 : 0.0) * clock->T_s;
    return 1;
#endif
}

/* tapmp.control.ControllerModel.event: in Event Mode at a sample instant not sampled yet the
 * controller samples its inputs and publishes the new command at once; at any other time of an
 * event the outputs hold. doStep never passes a sample instant (it returns early there), so no
 * instant is skipped and the clock's warnings cannot arise. */
int model_event_update(tapmp_instance *inst, double out[], char *msg, size_t size)
{
    tapmp_clock *clock = &inst->m.clock;
    double t = inst->time, k, steps, missed;
    read_settings(inst, &inst->m);
#ifdef MODEL_CLOCK
    /* the clocked controller samples exactly when its clock ticks, and only then */
    if (!inst->clock_active) {
        memcpy(out, inst->reals + MODEL_OUT_FIRST, MODEL_N_OUT * sizeof *out);  /* hold */
        return 1;
    }
    if (!tapmp_sample_index(t, clock->t0, clock->T_s, &k)) {
        char v[40], allowed[160], t0[40], ts[40];
        snprintf(allowed, sizeof allowed, "an instant t0 + k T_s (t0 = %s s, T_s = %s s)", tapmp_repr(clock->t0, t0),
                 tapmp_repr(clock->T_s, ts));
        tapmp_invalid_text(msg, size, "time of the tick of " MODEL_CLOCK_NAME, tapmp_repr(t, v), allowed, 0, 0);
        return 0;
    }
#endif
    if (!tapmp_clock_at(clock, t, &k, &steps, &missed)) {
        memcpy(out, inst->reals + MODEL_OUT_FIRST, MODEL_N_OUT * sizeof *out);  /* hold */
        return 1;
    }
    if (sample(inst, t, steps * clock->T_s, 1, out, msg, size)) {
        tapmp_clock_sampled(clock, k, steps);
        return 1;
    }
    size_t n = strlen(msg);
    snprintf(msg + n, size - n, " (at t = %.6g s)", t);
    return 0;
}

void model_get_hidden(const tapmp_instance *inst, double hidden[])
{
    const tapmp_controller_state *st = &inst->m.st;
    for (int i = 0; i < 3; i++) {
        hidden[i] = st->integral[i];
        hidden[3 + i] = st->q_prev[i];
    }
    hidden[6] = st->has_q_prev;
    hidden[7] = inst->m.clock.t0;
    hidden[8] = inst->m.clock.k_last;
    hidden[9] = inst->m.clock.has_sample;
    hidden[10] = inst->m.clock.warned;
}

void model_set_hidden(tapmp_instance *inst, const double hidden[])
{
    tapmp_controller_state *st = &inst->m.st;
    for (int i = 0; i < 3; i++) {
        st->integral[i] = hidden[i];
        st->q_prev[i] = hidden[3 + i];
    }
    st->has_q_prev = hidden[6] != 0.0;
    inst->m.clock.t0 = hidden[7];
    inst->m.clock.k_last = hidden[8];
    inst->m.clock.has_sample = hidden[9] != 0.0;
    inst->m.clock.warned = hidden[10] != 0.0;
}

/* The loop state and clock of an FMU state (model_get_hidden's layout) for its settings and time. */
int model_check_hidden(const tapmp_instance *state, const double hidden[], char *msg, size_t size)
{
    ModelData m = state->m;
    tapmp_controller_state st;
    const char *name = NULL, *allowed = NULL;
    double x = 0.0;
    read_settings(state, &m);
    for (int i = 0; i < 3; i++) {
        st.integral[i] = hidden[i];
        st.q_prev[i] = hidden[3 + i];
    }
    st.has_q_prev = hidden[6] != 0.0;
    m.clock.t0 = hidden[7];
    m.clock.k_last = hidden[8];
    m.clock.has_sample = hidden[9] != 0.0;
    int bad = tapmp_controller_state_check(&m.s.p, &m.s.g, m.s.k.law, m.s.k.force_limit, &st, &m.clock, state->time,
                                           &name, &x, &allowed);
    return tapmp_range_text(bad, name, x, allowed, msg, size);
}
