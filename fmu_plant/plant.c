/* Native TAPMP_Plant FMU: maps the FMU variables to the plant of tapmp_model.c, as
 * fmu_plant/TAPMP_Plant.py maps them to tapmp.plant.PlantModel. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "instance.h"

#define R(name) inst->reals[VR_##name]

/* Every parameter into the model's settings struct (generated from tapmp/interface.py) and its
 * range check: tapmp.plant.PlantModel.__init__ and the Python model's validated() run the same. */
int model_validate(const tapmp_instance *inst, char *msg, size_t size)
{
    const char *name = NULL, *allowed = NULL;
    double x = 0.0;
    tapmp_plant_settings s;
    MODEL_READ_SETTINGS(inst, &s);
    return tapmp_range_text(tapmp_plant_settings_check(&s, &name, &x, &allowed), name, x, allowed, msg, size);
}

static void publish(tapmp_instance *inst)
{
    tapmp_plant_outputs(&inst->m.plant, inst->reals + MODEL_OUT_FIRST);
}

void model_setup(tapmp_instance *inst)
{
    tapmp_plant *pl = &inst->m.plant;
    tapmp_plant_settings s;
    MODEL_READ_SETTINGS(inst, &s);
    pl->p = s.p;
    pl->c = s.c;
    tapmp_plant_init(pl, s.x0.pose, s.x0.rate);
    publish(inst);
}

int model_initial_outputs(tapmp_instance *inst, char *msg, size_t size)
{
    (void)inst, (void)msg, (void)size;
    return 1;
}

int model_step(tapmp_instance *inst, double t, double h, double out[], char *msg, size_t size)
{
    double F[3] = {R(F1), R(F2), R(F3)}, s[TAPMP_PLANT_STATES];
    tapmp_plant *pl = &inst->m.plant;
    if (!tapmp_plant_step(pl, t, h, F, s)) {
        char value[6 * 40 + 16] = "(", v[40];
        for (int i = 0; i < 6; i++) {
            snprintf(value + strlen(value), sizeof value - strlen(value), "%s%s", i ? ", " : "",
                     tapmp_repr(s[i], v));
        }
        strcat(value, ")");
        return tapmp_invalid_text(msg, size, "plant state (X, Z, B, dX, dZ, dB)", value,
                                  "finite values with |B| < pi/2 rad", 1, t + h);
    }
    for (int i = 0; i < TAPMP_PLANT_STATES; i++) pl->s[i] = s[i];
    pl->sample += 1.0;
    tapmp_plant_outputs(pl, out);
    return 1;
}

void model_get_hidden(const tapmp_instance *inst, double hidden[])
{
    for (int i = 0; i < 6; i++) hidden[i] = inst->m.plant.s[i];
    hidden[6] = inst->m.plant.sample;
    hidden[7] = inst->m.plant.s[6];  /* the flexible mode after the sample count: its index stays 6 */
    hidden[8] = inst->m.plant.s[7];
}

void model_set_hidden(tapmp_instance *inst, const double hidden[])
{
    for (int i = 0; i < 6; i++) inst->m.plant.s[i] = hidden[i];
    inst->m.plant.sample = hidden[6];
    inst->m.plant.s[6] = hidden[7];
    inst->m.plant.s[7] = hidden[8];
    publish(inst);
}

static void me_limits(const tapmp_params *p, const tapmp_plant_config *c, double lim[6]);
static int me_state_inside(const double lim[6], const double x[6], double t, char *msg, size_t size);

/* The plant state and sample count of an FMU state, with the outputs X..dB it holds. For a Model Exchange
 * instance the state also lies inside the Model Exchange domain (me_limits). */
int model_check_hidden(const tapmp_instance *state, const double hidden[], char *msg, size_t size)
{
    const char *name = NULL, *allowed = NULL;
    double x = 0.0;
    int bad = tapmp_plant_state_check(hidden, hidden[6], state->reals + VR_X, &name, &x, &allowed);
    if (!tapmp_range_text(bad, name, x, allowed, msg, size)) return 0;
    if (!state->model_exchange) return 1;
    /* a Model Exchange instance's state is its continuous state: inside the same domain as one the host
     * sets (me_limits, from the state's own settings: its model data is not built yet) */
    tapmp_plant_settings s;
    double lim[6];
    MODEL_READ_SETTINGS(state, &s);
    me_limits(&s.p, &s.c, lim);
    return me_state_inside(lim, hidden, state->time, msg, size);
}

/* --- Model Exchange (FMI 2.0): the host integrates the state X, Z, B, dX, dZ, dB itself --- */

void model_me_get_states(const tapmp_instance *inst, double x[])
{
    for (int i = 0; i < 6; i++) x[i] = inst->m.plant.s[i];
}

/* The Model Exchange domain of the state (X, Z, B, dX, dZ, dB), derived from the model's own ranges;
 * a state outside it is no motion of this platform but an integrator's divergence or a host's garbage:
 * - pose: |X|, |Z| <= ME_POSE_LIMIT = 3 m and |B| < pi/2 rad (the kinematic domain). The settings accept
 *   initial poses X0, Z0 in [-1, 1] m (tapmp/interface.py RANGES): the platform's stroke is that
 *   range's width, 2 m, and the domain is the range widened by one stroke on each side.
 * - rates: |dX|, |dZ| <= v_max [m/s] and |dB| <= w_max [rad/s], the initial rates' bound (1e3, the
 *   range of dX0, dZ0, dB0) plus what the largest force the settings allow can add across the domain:
 *   v_max = 1e3 + sqrt(2 (F / m) D), w_max = 1e3 + sqrt(2 (F l / I_y) pi), with D = 2 ME_POSE_LIMIT the
 *   domain's width, m the lightest body (min of m_p, m_1, m_2, m_3), l = (1 + 1/sqrt(3)) L_1 the
 *   longest lever arm of a motor force on B (Eq. 4), and F the sum of every force's bound: three motor
 *   forces (force_limit, or TAPMP_FORCE_CAP without one), the external force steps, three cogging
 *   amplitudes and Coulomb frictions, the weight of every body, the pulling springs stretched across
 *   the domain (2 |k_pull| (D + 4 L_1)) and the attraction at a tenth of its gap (100 attraction_force).
 * Writes the six bounds (the pose's B bound is pi/2, exclusive) into lim. */
#define ME_POSE_LIMIT 3.0
#define ME_RATE0 1e3
static void me_limits(const tapmp_params *p, const tapmp_plant_config *c, double lim[6])
{
    double D = 2.0 * ME_POSE_LIMIT, motor = c->force_limit > 0.0 ? c->force_limit : TAPMP_FORCE_CAP, F = 0.0;
    for (int i = 0; i < 3; i++) F += motor + fabs(c->disturbance_force[i]) + c->cogging_amplitude + c->F_c[i];
    F += (p->m_p + p->m_1 + p->m_2 + p->m_3) * p->g + 2.0 * fabs(c->k_pull) * (D + 4.0 * p->L_1) +
         100.0 * c->attraction_force;
    double m = fmin(fmin(p->m_p, p->m_1), fmin(p->m_2, p->m_3));
    double lever = (1.0 + 0.5773502691896257) * p->L_1;
    lim[0] = lim[1] = ME_POSE_LIMIT;
    lim[2] = 1.5707963267948966;
    lim[3] = lim[4] = ME_RATE0 + sqrt(2.0 * F / m * D);
    lim[5] = ME_RATE0 + sqrt(2.0 * F * lever / p->I_y * 3.141592653589793);
}

/* 1 if the state x is finite and inside the bounds lim (me_limits), else 0 + msg naming the first state
 * that is not, its value at t [s] and its bound. */
static int me_state_inside(const double lim[6], const double x[6], double t, char *msg, size_t size)
{
    static const char *const names[6] = {"plant state X", "plant state Z", "plant state B", "plant state dX",
                                         "plant state dZ", "plant state dB"};
    static const char *const units[6] = {"m", "m", "rad", "m/s", "m/s", "rad/s"};
    for (int i = 0; i < 6; i++) {
        if (i == 2 ? fabs(x[i]) < lim[i] : fabs(x[i]) <= lim[i]) continue;  /* NaN fails both */
        char v[40], b[40], allowed[200];
        if (i == 2) snprintf(allowed, sizeof allowed, "|B| < pi/2 rad (the kinematic domain)");
        else snprintf(allowed, sizeof allowed, "|value| <= %s %s (%s)", tapmp_repr(lim[i], b), units[i],
                      i < 2 ? "the platform's domain: the initial pose's range widened by its stroke" :
                      "the speed the plant's forces can reach across its domain");
        return tapmp_invalid_text(msg, size, names[i], tapmp_repr(x[i], v), allowed, 1, t);
    }
    return 1;
}

/* A state from the host's integrator: finite and inside me_limits, else 0 + msg (me_state_inside). The
 * outputs follow it (the encoder positions quantize the true ones). */
int model_me_set_states(tapmp_instance *inst, const double x[], char *msg, size_t size)
{
    double lim[6];
    me_limits(&inst->m.plant.p, &inst->m.plant.c, lim);
    if (!me_state_inside(lim, x, inst->time, msg, size)) return 0;
    for (int i = 0; i < 6; i++) inst->m.plant.s[i] = x[i];
    publish(inst);
    return 1;
}

/* d/dt of the state at the instance's time, for the forces F1..F3 set now. */
void model_me_derivatives(const tapmp_instance *inst, double dx[])
{
    const double F[3] = {inst->reals[VR_F1], inst->reals[VR_F2], inst->reals[VR_F3]};
    tapmp_plant_derivatives(&inst->m.plant, inst->time, inst->m.plant.s, F, dx);
}

/* The one time event: the external force step at disturbance_time, if it is on and still ahead. */
double model_me_next_event_time(const tapmp_instance *inst)
{
    const tapmp_plant_config *c = &inst->m.plant.c;
    int on = c->disturbance_force[0] != 0.0 || c->disturbance_force[1] != 0.0 || c->disturbance_force[2] != 0.0;
    return on && inst->time < c->disturbance_time ? c->disturbance_time : INFINITY;
}

/* Settings Model Exchange cannot honour: the measurement noise is drawn once per communication
 * step, which Model Exchange does not have; the flexible mode's two states are not among the six
 * continuous states (kept six so that a rigid run's solver sees the same state vector). */
int model_me_check(const tapmp_instance *inst, char *msg, size_t size)
{
    char v[40];
    if (inst->reals[VR_flex_frequency] != 0.0)
        return tapmp_invalid_text(msg, size, "flex_frequency", tapmp_repr(inst->reals[VR_flex_frequency], v),
                                  "0 in Model Exchange (the continuous states are the rigid X, Z, B, dX, dZ, dB; the "
                                  "flexible mode runs in Co-Simulation)", 0, 0.0);
    if (inst->reals[VR_noise_rms] == 0.0) return 1;
    return tapmp_invalid_text(msg, size, "noise_rms", tapmp_repr(inst->reals[VR_noise_rms], v),
                              "0 in Model Exchange (the noise is drawn once per communication step; use "
                              "Co-Simulation)", 0, 0.0);
}
