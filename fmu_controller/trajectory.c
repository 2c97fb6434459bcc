/* Native TAPMP_Trajectory FMU: the paper's reference (XZ circle, B sinusoid) or a
 * point-to-point move (step, ramp, jerk-limited S-curve), and the motor references by
 * inverse kinematics, as fmu_controller/TAPMP_Trajectory.py. After doStep(t, h) the outputs
 * are the reference at t + h. The reference and the move are the C model's (tapmp_reference,
 * tapmp_move_plan in tapmp/c/tapmp_model.c), which the Python package runs too. */
#include "instance.h"

/* Every parameter into the model's settings struct (generated from tapmp/interface.py) and its
 * range check: tapmp.trajectory.TrajectoryParams.validated runs the same. */
int model_validate(const tapmp_instance *inst, char *msg, size_t size)
{
    const char *name = NULL, *allowed = NULL;
    double x = 0.0;
    tapmp_trajectory_settings s;
    MODEL_READ_SETTINGS(inst, &s);
    return tapmp_range_text(tapmp_trajectory_settings_check(&s, &name, &x, &allowed), name, x, allowed, msg,
                            size);
}

static void outputs(const tapmp_instance *inst, double t, double out[])
{
    tapmp_reference(t, &inst->m.tp, out);
    tapmp_inverse(out[0], out[1], out[2], inst->m.L_1, out + 9);
}

void model_setup(tapmp_instance *inst)
{
    tapmp_trajectory_settings s;
    MODEL_READ_SETTINGS(inst, &s);
    tapmp_trajectory_init(&inst->m.tp, &s);
    inst->m.L_1 = s.L_1;
    outputs(inst, inst->time, inst->reals + MODEL_OUT_FIRST);
}

int model_initial_outputs(tapmp_instance *inst, char *msg, size_t size)
{
    (void)inst, (void)msg, (void)size;
    return 1;
}

int model_step(tapmp_instance *inst, double t, double h, double out[], char *msg, size_t size)
{
    (void)msg, (void)size;
    outputs(inst, t + h, out);
    return 1;
}

void model_get_hidden(const tapmp_instance *inst, double hidden[]) { (void)inst, (void)hidden; }

void model_set_hidden(tapmp_instance *inst, const double hidden[]) { (void)inst, (void)hidden; }

/* The reference has no hidden state: its outputs are a function of the time alone. */
int model_check_hidden(const tapmp_instance *state, const double hidden[], char *msg, size_t size)
{
    (void)state, (void)hidden, (void)msg, (void)size;
    return 1;
}
