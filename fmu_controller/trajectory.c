/* Native TAPMP_Trajectory FMU: the paper's reference (XZ circle, B sinusoid) or a
 * point-to-point move (step, ramp, jerk-limited S-curve), and the motor references by
 * inverse kinematics, as fmu_controller/TAPMP_Trajectory.py. After doStep(t, h) the outputs
 * are the reference at t + h. The reference and the move are the C model's (tapmp_reference,
 * tapmp_move_plan in tapmp/c/tapmp_model.c), which the Python package runs too. */
#include <math.h>

#include "instance.h"

#define R(name) inst->reals[VR_##name]

/* TrajectoryParams's fields in order (tapmp_trajectory_check); the profile is the Integer */
static const int SETTING_VR[TAPMP_TRAJECTORY_N] = {
    VR_X_c, VR_Z_c, VR_radius, VR_f_xz, VR_phase_xz, VR_B_amplitude, VR_f_B, VR_phase_B, VR_B_offset, VR_profile,
    VR_X_a, VR_Z_a, VR_B_a, VR_X_b, VR_Z_b, VR_B_b, VR_t_move, VR_v_max_X, VR_v_max_Z, VR_v_max_B, VR_a_max_X,
    VR_a_max_Z, VR_a_max_B, VR_j_max_X, VR_j_max_Z, VR_j_max_B};
enum { PROFILE_INDEX = 9 };

/* errors.require_positive("L_1") and tapmp.trajectory.TrajectoryParams.validated */
int model_validate(const tapmp_instance *inst, char *msg, size_t size)
{
    char v[40];
    double settings[TAPMP_TRAJECTORY_N], x = 0.0;
    const char *name = NULL, *allowed = NULL;
    if (!(isfinite(R(L_1)) && R(L_1) > 0.0))
        return tapmp_invalid_text(msg, size, "L_1", tapmp_repr(R(L_1), v), "a finite number > 0", 0, 0);
    for (int i = 0; i < TAPMP_TRAJECTORY_N; i++)
        settings[i] = i == PROFILE_INDEX ? inst->ints[VR_profile] : inst->reals[SETTING_VR[i]];
    int bad = tapmp_trajectory_check(settings, &name, &x, &allowed);
    return tapmp_range_text(bad, name, x, allowed, msg, size);
}

static void outputs(const tapmp_instance *inst, double t, double out[])
{
    tapmp_reference(t, &inst->m.tp, out);
    tapmp_inverse(out[0], out[1], out[2], inst->m.L_1, out + 9);
}

void model_setup(tapmp_instance *inst)
{
    tapmp_trajectory *tp = &inst->m.tp;
    const double a[3] = {R(X_a), R(Z_a), R(B_a)}, b[3] = {R(X_b), R(Z_b), R(B_b)};
    const double v[3] = {R(v_max_X), R(v_max_Z), R(v_max_B)}, acc[3] = {R(a_max_X), R(a_max_Z), R(a_max_B)};
    const double j[3] = {R(j_max_X), R(j_max_Z), R(j_max_B)};
    /* designated: the axis plans, zero here, are filled by tapmp_move_plan below */
    *tp = (tapmp_trajectory){.X_c = R(X_c), .Z_c = R(Z_c), .radius = R(radius), .f_xz = R(f_xz),
                             .phase_xz = R(phase_xz), .B_amplitude = R(B_amplitude), .f_B = R(f_B),
                             .phase_B = R(phase_B), .B_offset = R(B_offset), .profile = inst->ints[VR_profile],
                             .t_move = R(t_move)};
    tapmp_move_plan(tp->profile, a, b, v, acc, j, tp->axis);
    inst->m.L_1 = R(L_1);
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
