/* Native TAPMP_Controller FMU: maps the FMU variables to the SC-DC / APD-DC / PID-DC controller of
 * tapmp_model.c, as fmu_controller/TAPMP_Controller.py maps them to
 * tapmp.control.ControllerModel. On doStep(t, h) at a sample instant t0 + k T_s not sampled
 * yet it samples its inputs, computes the command and holds it; at any other communication
 * point the outputs hold (tapmp.control.ControllerModel.communication_point). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "instance.h"

#define R(name) inst->reals[VR_##name]

static const int PARAM_VR[] = {VR_m_p, VR_m_1, VR_m_2, VR_m_3, VR_I_y, VR_L_1, VR_g};
static const int GAIN_VR[5] = {VR_Lambda_p1, VR_Lambda_v1, VR_b1, VR_D1, VR_K_T1};
static const int MODAL_VR[6] = {VR_kp_c, VR_kv_c, VR_ki_c, VR_kp_d, VR_kv_d, VR_ki_d};

/* tapmp.params.ModelParams.validated, tapmp.control.Gains.validated, ModalGains.validated,
 * ControllerModel.__init__ */
int model_validate(const tapmp_instance *inst, char *msg, size_t size)
{
    char v[40];
    if (!tapmp_require_positive(inst, PARAM_VR, 7, msg, size)) return 0;  /* ModelParams.validated */
    for (int k = 0; k < 5; k++)
        for (int i = 0; i < 3; i++) {
            int vr = GAIN_VR[k] + i;  /* motors 1..3 are consecutive in the table */
            double x = inst->reals[vr];
            int k_t = k == 4;
            if (!(isfinite(x) && (k_t ? x > 0.0 : x >= 0.0)))
                return tapmp_invalid_text(msg, size, VARS[vr].name, tapmp_repr(x, v),
                                          k_t ? "a finite number > 0" : "a finite number >= 0", 0, 0);
        }
    for (int k = 0; k < 6; k++) {  /* ModalGains.validated */
        double x = inst->reals[MODAL_VR[k]];
        if (!(isfinite(x) && x >= 0.0))
            return tapmp_invalid_text(msg, size, VARS[MODAL_VR[k]].name, tapmp_repr(x, v),
                                      "a finite number >= 0", 0, 0);
    }
    int law = inst->ints[VR_law], vs = inst->ints[VR_velocity_source];
    if (law != TAPMP_SCDC && law != TAPMP_APDDC && law != TAPMP_PIDDC) {
        snprintf(v, sizeof v, "%d", law);
        return tapmp_invalid_text(msg, size, "law", v, "0 (SC-DC), 1 (APD-DC) or 2 (PID-DC)", 0, 0);
    }
    if (vs != 0 && vs != 1) {
        snprintf(v, sizeof v, "%d", vs);
        return tapmp_invalid_text(msg, size, "velocity_source", v,
                                  "0 (backward difference of q) or 1 (dq inputs)", 0, 0);
    }
    if (!(isfinite(R(force_limit)) && R(force_limit) >= 0.0))
        return tapmp_invalid_text(msg, size, "force_limit", tapmp_repr(R(force_limit), v),
                                  "a finite number >= 0 (0 = no limit)", 0, 0);
    if (!(isfinite(R(T_s)) && R(T_s) > 0.0))
        return tapmp_invalid_text(msg, size, "T_s", tapmp_repr(R(T_s), v),
                                  "a finite number > 0 (the controller's sample period [s])", 0, 0);
    return 1;
}

/* The parameters into the model; the loop state (integral, previous q) is kept. */
static void build(tapmp_instance *inst)
{
    ModelData *m = &inst->m;
    m->p = (tapmp_params){R(m_p), R(m_1), R(m_2), R(m_3), R(I_y), R(L_1), R(g)};
    for (int i = 0; i < 3; i++) {
        m->g.Lambda_p[i] = inst->reals[VR_Lambda_p1 + i];
        m->g.Lambda_v[i] = inst->reals[VR_Lambda_v1 + i];
        m->g.b[i] = inst->reals[VR_b1 + i];
        m->g.D[i] = inst->reals[VR_D1 + i];
        m->g.K_T[i] = inst->reals[VR_K_T1 + i];
    }
    m->g.kp_c = R(kp_c);
    m->g.kv_c = R(kv_c);
    m->g.ki_c = R(ki_c);
    m->g.kp_d = R(kp_d);
    m->g.kv_d = R(kv_d);
    m->g.ki_d = R(ki_d);
    m->law = inst->ints[VR_law];
    m->velocity_source = inst->ints[VR_velocity_source];
    m->force_limit = R(force_limit);
    m->T_s = R(T_s);
}

void model_setup(tapmp_instance *inst)
{
    build(inst);
    memset(&inst->m.st, 0, sizeof inst->m.st);
    inst->m.t0 = inst->time;
    inst->m.k_last = 0.0;
    inst->m.has_sample = inst->m.warned = 0;
}

static int sample(tapmp_instance *inst, double t, double h, int advance, double out[], char *msg,
                  size_t size)
{
    ModelData *m = &inst->m;
    double arg;
    const double *r = inst->reals;
    if (tapmp_controller_sample(&m->p, &m->g, m->law, m->velocity_source, m->force_limit, &m->st, h,
                                r + VR_X_d, r + VR_q1, r + VR_dq1, advance, out, &m->st, &arg))
        return 1;
    char a[40], q1[40], q2[40], q3[40], l1[40], allowed[256];
    snprintf(allowed, sizeof allowed, "|value| < 1 (q = [%s, %s, %s] m, L1 = %s m)", tapmp_repr(r[VR_q1], q1),
             tapmp_repr(r[VR_q2], q2), tapmp_repr(r[VR_q3], q3), tapmp_repr(m->p.L_1, l1));
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

/* The warning logged once when the host's communication points skip sample instants
 * (tapmp.control.skipped_samples_text). Passed on whatever loggingOn says, as the pythonfmu
 * family's binary passes on every warning; doStep still returns OK. */
static void warn_skipped(tapmp_instance *inst, double t, double steps)
{
    char text[TAPMP_MESSAGE_MAX];
    double T_s = inst->m.T_s;
    snprintf(text, sizeof text, "the host's communication points skip sample instants of T_s = %g s: the "
             "controller sampled at t = %.9g s, %g s (%.0f T_s) after its previous sample, and uses that "
             "interval for the velocity estimate and the integral (it samples only at communication points "
             "on its grid t0 + k T_s)", T_s, t, steps * T_s, steps);
    if (inst->log) inst->log(inst, ST_WARNING, "logStatusWarning", text);
}

/* tapmp.control.missed_sample_text */
static void warn_missed(tapmp_instance *inst, double t, double due)
{
    char text[TAPMP_MESSAGE_MAX];
    snprintf(text, sizeof text, "the host's communication points skip sample instants of T_s = %g s: none fell "
             "on the sample instant t = %.9g s; at t = %.9g s the controller holds its command until a "
             "communication point falls on its grid t0 + k T_s", inst->m.T_s, due, t);
    if (inst->log) inst->log(inst, ST_WARNING, "logStatusWarning", text);
}

int model_step(tapmp_instance *inst, double t, double h, double out[], char *msg, size_t size)
{
    ModelData *m = &inst->m;
    double k;
    (void)h;  /* the host's step never enters the law: the time between samples does */
    build(inst);  /* new tunable values take effect at this sample; the loop state carries over */
    int on_grid = tapmp_sample_index(t, m->t0, m->T_s, &k);
    if (!on_grid || (m->has_sample && k <= m->k_last)) {
        memcpy(out, inst->reals + MODEL_OUT_FIRST, MODEL_N_OUT * sizeof *out);  /* hold */
        if (!on_grid && m->has_sample && !m->warned &&
            t > m->t0 + (m->k_last + 1.0 + TAPMP_SAMPLE_TOLERANCE) * m->T_s) {
            m->warned = 1;  /* a due sample instant passed without a communication point on it */
            warn_missed(inst, t, m->t0 + (m->k_last + 1.0) * m->T_s);
        }
        return 1;
    }
    /* the first sample integrates over one period, as every later one on an unbroken grid */
    double steps = m->has_sample ? k - m->k_last : 1.0;
    if (sample(inst, t, steps * m->T_s, 1, out, msg, size)) {
        if (steps > 1.0 && !m->warned) {
            m->warned = 1;
            warn_skipped(inst, t, steps);
        }
        m->k_last = k;
        m->has_sample = 1;
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
    hidden[7] = inst->m.t0;
    hidden[8] = inst->m.k_last;
    hidden[9] = inst->m.has_sample;
    hidden[10] = inst->m.warned;
}

void model_set_hidden(tapmp_instance *inst, const double hidden[])
{
    tapmp_controller_state *st = &inst->m.st;
    for (int i = 0; i < 3; i++) {
        st->integral[i] = hidden[i];
        st->q_prev[i] = hidden[3 + i];
    }
    st->has_q_prev = hidden[6] != 0.0;
    inst->m.t0 = hidden[7];
    inst->m.k_last = hidden[8];
    inst->m.has_sample = hidden[9] != 0.0;
    inst->m.warned = hidden[10] != 0.0;
}
