/* Native TAPMP_Trajectory FMU: the paper's reference (XZ circle, B sinusoid) or a
 * point-to-point move (step, ramp, jerk-limited S-curve), and the motor references by
 * inverse kinematics, as fmu_controller/TAPMP_Trajectory.py. After doStep(t, h) the outputs
 * are the reference at t + h. The reference and the move are the C model's (tapmp_reference,
 * tapmp_move_plan in tapmp/c/tapmp_model.c), which the Python package runs too. */
#include <math.h>
#include <stdio.h>

#include "instance.h"

#define R(name) inst->reals[VR_##name]
#define HALF_PI 1.5707963267948966

static const int TP_VR[9] = {VR_X_c, VR_Z_c, VR_radius, VR_f_xz, VR_phase_xz, VR_B_amplitude, VR_f_B,
                             VR_phase_B, VR_B_offset};
static const int MOVE_VR[7] = {VR_X_a, VR_Z_a, VR_B_a, VR_X_b, VR_Z_b, VR_B_b, VR_t_move};
/* limits by kind (v, a, j) and axis (X, Z, B), as tapmp.trajectory.LIMIT_NAMES */
static const int LIMIT_VR[3][3] = {{VR_v_max_X, VR_v_max_Z, VR_v_max_B}, {VR_a_max_X, VR_a_max_Z, VR_a_max_B},
                                   {VR_j_max_X, VR_j_max_Z, VR_j_max_B}};

/* errors.require_positive("L_1") and tapmp.trajectory.TrajectoryParams.validated */
int model_validate(const tapmp_instance *inst, char *msg, size_t size)
{
    char v[40];
    if (!(isfinite(R(L_1)) && R(L_1) > 0.0))
        return tapmp_invalid_text(msg, size, "L_1", tapmp_repr(R(L_1), v), "a finite number > 0", 0, 0);
    for (int i = 0; i < 9; i++)
        if (!isfinite(inst->reals[TP_VR[i]]))
            return tapmp_invalid_text(msg, size, VARS[TP_VR[i]].name, tapmp_repr(inst->reals[TP_VR[i]], v),
                                      "a finite number", 0, 0);
    static const int NONNEG[4] = {VR_radius, VR_f_xz, VR_B_amplitude, VR_f_B};
    for (int i = 0; i < 4; i++)
        if (inst->reals[NONNEG[i]] < 0.0)
            return tapmp_invalid_text(msg, size, VARS[NONNEG[i]].name, tapmp_repr(inst->reals[NONNEG[i]], v),
                                      "a finite number >= 0", 0, 0);
    if (!(fabs(R(B_offset)) + R(B_amplitude) < HALF_PI))
        return tapmp_invalid_text(msg, size, "B_amplitude", tapmp_repr(R(B_amplitude), v),
                                  "|B_offset| + B_amplitude < pi/2 rad (kinematic domain)", 0, 0);
    int profile = inst->ints[VR_profile];
    if (profile < 0 || profile > 3) {
        snprintf(v, sizeof v, "%d", profile);
        return tapmp_invalid_text(msg, size, "profile", v,
                                  "0 (circle and sinusoid), 1 (step), 2 (ramp) or 3 (S-curve)", 0, 0);
    }
    for (int i = 0; i < 7; i++)
        if (!isfinite(inst->reals[MOVE_VR[i]]))
            return tapmp_invalid_text(msg, size, VARS[MOVE_VR[i]].name, tapmp_repr(inst->reals[MOVE_VR[i]], v),
                                      "a finite number", 0, 0);
    for (int k = 0; k < 3; k++)
        for (int a = 0; a < 3; a++) {
            double x = inst->reals[LIMIT_VR[k][a]];
            if (!(isfinite(x) && x > 0.0))
                return tapmp_invalid_text(msg, size, VARS[LIMIT_VR[k][a]].name, tapmp_repr(x, v),
                                          "a finite number > 0", 0, 0);
        }
    static const int POSE_B[2] = {VR_B_a, VR_B_b};
    for (int i = 0; i < 2; i++)
        if (!(fabs(inst->reals[POSE_B[i]]) < HALF_PI))
            return tapmp_invalid_text(msg, size, VARS[POSE_B[i]].name, tapmp_repr(inst->reals[POSE_B[i]], v),
                                      "|B| < pi/2 rad (kinematic domain)", 0, 0);
    return 1;
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
