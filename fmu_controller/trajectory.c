/* Native TAPMP_Trajectory FMU: the paper's reference (XZ circle, B sinusoid) and the motor
 * references by inverse kinematics, as fmu_controller/TAPMP_Trajectory.py. After
 * doStep(t, h) the outputs are the reference at t + h. */
#include <math.h>

#include "instance.h"

#define R(name) inst->reals[VR_##name]
#define HALF_PI 1.5707963267948966

static const int TP_VR[9] = {VR_X_c, VR_Z_c, VR_radius, VR_f_xz, VR_phase_xz, VR_B_amplitude, VR_f_B,
                             VR_phase_B, VR_B_offset};

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
    *tp = (tapmp_trajectory){R(X_c), R(Z_c), R(radius), R(f_xz), R(phase_xz), R(B_amplitude), R(f_B),
                             R(phase_B), R(B_offset)};
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
