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
    double F[3] = {R(F1), R(F2), R(F3)}, s[6];
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
    for (int i = 0; i < 6; i++) pl->s[i] = s[i];
    pl->sample += 1.0;
    tapmp_plant_outputs(pl, out);
    return 1;
}

void model_get_hidden(const tapmp_instance *inst, double hidden[])
{
    for (int i = 0; i < 6; i++) hidden[i] = inst->m.plant.s[i];
    hidden[6] = inst->m.plant.sample;
}

void model_set_hidden(tapmp_instance *inst, const double hidden[])
{
    for (int i = 0; i < 6; i++) inst->m.plant.s[i] = hidden[i];
    inst->m.plant.sample = hidden[6];
    publish(inst);
}

/* The plant state and sample count of an FMU state, with the outputs X..dB it holds. */
int model_check_hidden(const tapmp_instance *state, const double hidden[], char *msg, size_t size)
{
    const char *name = NULL, *allowed = NULL;
    double x = 0.0;
    int bad = tapmp_plant_state_check(hidden, hidden[6], state->reals + VR_X, &name, &x, &allowed);
    return tapmp_range_text(bad, name, x, allowed, msg, size);
}

/* --- Model Exchange (FMI 2.0): the host integrates the state X, Z, B, dX, dZ, dB itself --- */

void model_me_get_states(const tapmp_instance *inst, double x[])
{
    for (int i = 0; i < 6; i++) x[i] = inst->m.plant.s[i];
}

/* A state from the host's integrator: finite with |B| < pi/2 (the kinematic domain), else 0 + msg.
 * The outputs follow it (the encoder positions quantize the true ones). */
int model_me_set_states(tapmp_instance *inst, const double x[], char *msg, size_t size)
{
    int ok = fabs(x[2]) < 1.5707963267948966;
    for (int i = 0; i < 6; i++) ok = ok && isfinite(x[i]);
    if (!ok) {
        char value[6 * 40 + 16] = "(", v[40];
        for (int i = 0; i < 6; i++)
            snprintf(value + strlen(value), sizeof value - strlen(value), "%s%s", i ? ", " : "", tapmp_repr(x[i], v));
        strcat(value, ")");
        return tapmp_invalid_text(msg, size, "plant state (X, Z, B, dX, dZ, dB)", value,
                                  "finite values with |B| < pi/2 rad", 1, inst->time);
    }
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
 * step, which Model Exchange does not have. */
int model_me_check(const tapmp_instance *inst, char *msg, size_t size)
{
    char v[40];
    if (inst->reals[VR_noise_rms] == 0.0) return 1;
    return tapmp_invalid_text(msg, size, "noise_rms", tapmp_repr(inst->reals[VR_noise_rms], v),
                              "0 in Model Exchange (the noise is drawn once per communication step; use "
                              "Co-Simulation)", 0, 0.0);
}
