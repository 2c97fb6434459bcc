/* Native TAPMP_Trajectory FMU: the paper's reference (XZ circle, B sinusoid) or a
 * point-to-point move (step, ramp, jerk-limited S-curve), and the motor references by
 * inverse kinematics, as fmu_controller/TAPMP_Trajectory.py. After doStep(t, h) the outputs
 * are the reference at t + h. The move is the C twin of tapmp/trajectory.py (move_plan,
 * _axis): the same expressions in the same order, so both give the same doubles. */
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

/* tapmp.trajectory.scurve_times: phase times of the rest-to-rest S-curve over D > 0. */
static void scurve_times(double D, double V, double A, double J, double *Tj_, double *Ta_, double *Tv_)
{
    double Tj, Ta;
    if (V * J >= A * A) {
        Tj = A / J;
        Ta = Tj + V / A;
    } else {
        Tj = sqrt(V / J);
        Ta = 2.0 * Tj;
    }
    double vlim = J * Tj * (Ta - Tj);
    double Tv = D / vlim - Ta;
    if (Tv >= 0.0) {
        *Tj_ = Tj, *Ta_ = Ta, *Tv_ = Tv;
        return;
    }
    Tj = A / J;
    if (D >= 2.0 * A * A * A / (J * J)) {
        double v = (sqrt(A * A * A * A / (J * J) + 4.0 * D * A) - A * A / J) / 2.0;
        Ta = Tj + v / A;
    } else {
        Tj = pow(D / (2.0 * J), 1.0 / 3.0);
        Ta = 2.0 * Tj;
    }
    *Tj_ = Tj, *Ta_ = Ta, *Tv_ = 0.0;
}

/* tapmp.trajectory.move_plan */
static void move_plan(const tapmp_instance *inst, int profile, tapmp_axis_plan plan[3])
{
    const double q0s[3] = {R(X_a), R(Z_a), R(B_a)}, q1s[3] = {R(X_b), R(Z_b), R(B_b)};
    double own[3][4];
    for (int i = 0; i < 3; i++) {
        double D = fabs(q1s[i] - q0s[i]), V = inst->reals[LIMIT_VR[0][i]];
        if (D == 0.0) {
            own[i][0] = own[i][1] = own[i][2] = own[i][3] = 0.0;
        } else if (profile == 2) {
            own[i][0] = own[i][1] = 0.0;
            own[i][2] = own[i][3] = D / V;
        } else {
            scurve_times(D, V, inst->reals[LIMIT_VR[1][i]], inst->reals[LIMIT_VR[2][i]], &own[i][0], &own[i][1],
                         &own[i][2]);
            own[i][3] = 2.0 * own[i][1] + own[i][2];
        }
    }
    double T = own[0][3];
    for (int i = 1; i < 3; i++)
        if (own[i][3] > T) T = own[i][3];
    for (int i = 0; i < 3; i++) {
        tapmp_axis_plan *p = &plan[i];
        double q0 = q0s[i], q1 = q1s[i], D = fabs(q1 - q0);
        *p = (tapmp_axis_plan){q0, q1, q1 >= q0 ? 1.0 : -1.0, D, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
        if (D == 0.0 || profile == 1) continue;
        if (profile == 2) {
            p->Tv = T, p->T = T, p->vlim = D / T;
            continue;
        }
        double lam = own[i][3] / T;
        double Tj = own[i][0] / lam, Ta = own[i][1] / lam;
        double J = inst->reals[LIMIT_VR[2][i]] * lam * lam * lam;
        double alim = J * Tj, vlim = alim * (Ta - Tj);
        double Tv = D / vlim - Ta;
        if (!(Tv > 0.0)) Tv = 0.0;
        p->Tj = Tj, p->Ta = Ta, p->Tv = Tv, p->T = 2.0 * Ta + Tv, p->J = J, p->alim = alim, p->vlim = vlim;
    }
}

/* tapmp.trajectory._axis: position, velocity, acceleration at tr [s] into the move. */
static void axis_at(double tr, const tapmp_axis_plan *p, int profile, double out[3])
{
    double s = p->s, J = p->J, Tj = p->Tj, Ta = p->Ta, T = p->T, alim = p->alim, vlim = p->vlim, q, u;
    if (tr < 0.0) {
        out[0] = p->q0, out[1] = 0.0, out[2] = 0.0;
    } else if (tr >= T) {
        out[0] = p->q1, out[1] = 0.0, out[2] = 0.0;
    } else if (profile == 2) {
        out[0] = p->q0 + s * vlim * tr, out[1] = s * vlim, out[2] = 0.0;
    } else if (tr < Tj) {
        out[0] = p->q0 + s * (J * tr * tr * tr / 6.0), out[1] = s * (J * tr * tr / 2.0), out[2] = s * (J * tr);
    } else if (tr < Ta - Tj) {
        q = alim / 6.0 * (3.0 * tr * tr - 3.0 * Tj * tr + Tj * Tj);
        out[0] = p->q0 + s * q, out[1] = s * (alim * (tr - Tj / 2.0)), out[2] = s * alim;
    } else if (tr < Ta) {
        u = Ta - tr;
        q = vlim * Ta / 2.0 - vlim * u + J * u * u * u / 6.0;
        out[0] = p->q0 + s * q, out[1] = s * (vlim - J * u * u / 2.0), out[2] = s * (J * u);
    } else if (tr < Ta + p->Tv) {
        q = vlim * Ta / 2.0 + vlim * (tr - Ta);
        out[0] = p->q0 + s * q, out[1] = s * vlim, out[2] = 0.0;
    } else if ((u = tr - T + Ta) < Tj) {
        q = vlim * Ta / 2.0 - vlim * u + J * u * u * u / 6.0;
        out[0] = p->q1 - s * q, out[1] = s * (vlim - J * u * u / 2.0), out[2] = -s * (J * u);
    } else if (u < Ta - Tj) {
        q = vlim * Ta / 2.0 - vlim * u + alim / 6.0 * (3.0 * u * u - 3.0 * Tj * u + Tj * Tj);
        out[0] = p->q1 - s * q, out[1] = s * (vlim - alim * (u - Tj / 2.0)), out[2] = -s * alim;
    } else {
        double w = T - tr;
        out[0] = p->q1 - s * (J * w * w * w / 6.0), out[1] = s * (J * w * w / 2.0), out[2] = -s * (J * w);
    }
}

/* tapmp.trajectory.reference */
static void reference(const ModelData *m, double t, double ref[9])
{
    if (m->profile == 0) {
        tapmp_reference(t, &m->tp, ref);
        return;
    }
    double tr = t - m->t_move;
    for (int i = 0; i < 3; i++) {
        double a[3];
        if (m->profile == 1) {
            a[0] = tr < 0.0 ? m->axis[i].q0 : m->axis[i].q1, a[1] = 0.0, a[2] = 0.0;
        } else {
            axis_at(tr, &m->axis[i], m->profile, a);
        }
        ref[i] = a[0], ref[3 + i] = a[1], ref[6 + i] = a[2];
    }
}

static void outputs(const tapmp_instance *inst, double t, double out[])
{
    reference(&inst->m, t, out);
    tapmp_inverse(out[0], out[1], out[2], inst->m.L_1, out + 9);
}

void model_setup(tapmp_instance *inst)
{
    tapmp_trajectory *tp = &inst->m.tp;
    *tp = (tapmp_trajectory){R(X_c), R(Z_c), R(radius), R(f_xz), R(phase_xz), R(B_amplitude), R(f_B),
                             R(phase_B), R(B_offset)};
    inst->m.L_1 = R(L_1);
    inst->m.profile = inst->ints[VR_profile];
    inst->m.t_move = R(t_move);
    move_plan(inst, inst->m.profile, inst->m.axis);
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
