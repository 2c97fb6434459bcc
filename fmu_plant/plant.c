/* Native TAPMP_Plant FMU: maps the FMU variables to the plant of tapmp_model.c, as
 * fmu_plant/TAPMP_Plant.py maps them to tapmp.plant.PlantModel. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "instance.h"

#define R(name) inst->reals[VR_##name]

/* The FMU's settings as the model's tapmp_plant_config. */
static tapmp_plant_config config_of(const tapmp_instance *inst)
{
    return (tapmp_plant_config){R(encoder_resolution), {R(c_v1), R(c_v2), R(c_v3)},
                                {R(F_c1), R(F_c2), R(F_c3)}, R(v_s), R(force_limit), R(k_pull),
                                R(attraction_force), R(attraction_gap), R(cogging_amplitude),
                                R(cogging_pitch), {R(cogging_phase1), R(cogging_phase2), R(cogging_phase3)},
                                {R(disturbance_force1), R(disturbance_force2), R(disturbance_force3)},
                                R(disturbance_time), R(noise_rms), inst->ints[VR_substeps],
                                inst->ints[VR_noise_seed]};
}

/* The model's parameters (tapmp_params). */
static tapmp_params params_of(const tapmp_instance *inst)
{
    return (tapmp_params){R(m_p), R(m_1), R(m_2), R(m_3), R(I_y), R(L_1), R(g)};
}

/* tapmp.params.ModelParams.validated, PlantConfig.validated, PlantModel.__init__ */
int model_validate(const tapmp_instance *inst, char *msg, size_t size)
{
    const char *name = NULL, *allowed = NULL;
    double x = 0.0;
    tapmp_params p = params_of(inst);
    tapmp_plant_config c = config_of(inst);
    const double pose0[3] = {R(X0), R(Z0), R(B0)}, rate0[3] = {R(dX0), R(dZ0), R(dB0)};
    int bad = tapmp_params_check(&p, &name, &x, &allowed);
    if (!bad) bad = tapmp_plant_config_check(&c, &name, &x, &allowed);
    if (!bad) bad = tapmp_initial_state_check(pose0, rate0, &name, &x, &allowed);
    return tapmp_range_text(bad, name, x, allowed, msg, size);
}

static void publish(tapmp_instance *inst)
{
    tapmp_plant_outputs(&inst->m.plant, inst->reals + MODEL_OUT_FIRST);
}

void model_setup(tapmp_instance *inst)
{
    tapmp_plant *pl = &inst->m.plant;
    pl->p = params_of(inst);
    pl->c = config_of(inst);
    double pose0[3] = {R(X0), R(Z0), R(B0)}, rate0[3] = {R(dX0), R(dZ0), R(dB0)};
    tapmp_plant_init(pl, pose0, rate0);
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
