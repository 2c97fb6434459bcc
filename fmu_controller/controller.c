/* Native TAPMP_Controller FMU: maps the FMU variables to the SC-DC / APD-DC / PID-DC controller of
 * tapmp_model.c, as fmu_controller/TAPMP_Controller.py maps them to
 * tapmp.control.ControllerModel. On doStep(t, h) it samples its inputs, computes the
 * command and holds it. */
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
}

void model_setup(tapmp_instance *inst)
{
    build(inst);
    memset(&inst->m.st, 0, sizeof inst->m.st);
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

int model_step(tapmp_instance *inst, double t, double h, double out[], char *msg, size_t size)
{
    build(inst);  /* new tunable values take effect at this sample; the loop state carries over */
    if (sample(inst, t, h, 1, out, msg, size)) return 1;
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
}

void model_set_hidden(tapmp_instance *inst, const double hidden[])
{
    tapmp_controller_state *st = &inst->m.st;
    for (int i = 0; i < 3; i++) {
        st->integral[i] = hidden[i];
        st->q_prev[i] = hidden[3 + i];
    }
    st->has_q_prev = hidden[6] != 0.0;
}
