/* The TAPMP model in C; see tapmp_model.h. Each function names the readable Python function
 * of the same equations; expressions keep its evaluation order (left to right) on purpose, so
 * that both give the same doubles. Compile without -ffast-math and with
 * -ffp-contract=off (no fused multiply-add), as build_native.py does. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>

#include "tapmp_model.h"

/* No fused multiply-add: a*b + c must round twice, as in Python. gcc in a standard mode
 * (-std=c99) and MSVC do not contract by default; clang does unless told here. */
#if defined(__clang__)
#pragma STDC FP_CONTRACT OFF
#elif defined(_MSC_VER)
#pragma fp_contract(off)
#endif

#define S3 TAPMP_S3
#define SQRT3 TAPMP_SQRT3
#define HALF_PI 1.5707963267948966
#define TWO_PI 6.283185307179586

/* kinematics.inverse */
void tapmp_inverse(double X, double Z, double B, double L1, double q[3])
{
    double c = cos(B), s = sin(B);
    q[0] = X + S3 * Z + L1 * (1.0 - c + S3 * s);
    q[1] = X;
    q[2] = X - S3 * Z - L1 * (1.0 - c - S3 * s);
}

/* kinematics.forward */
int tapmp_forward(const double q[3], double L1, double x[3], double *arg)
{
    double a = SQRT3 / (2.0 * L1) * (2.0 * q[1] - q[0] - q[2]);
    *arg = a;
    if (!(fabs(a) < 1.0)) return 0;  /* also NaN */
    double B = -asin(a);
    x[0] = q[1];
    x[1] = 0.5 * SQRT3 * (q[0] - q[2] - 2.0 * L1 + 2.0 * L1 * cos(B));
    x[2] = B;
    return 1;
}

/* kinematics.rotation_column */
void tapmp_rotation_column(double B, double L1, double *a1, double *a3)
{
    double c = cos(B), s = sin(B);
    *a1 = L1 * (S3 * c + s);
    *a3 = L1 * (S3 * c - s);
}

/* kinematics.rotation_column_dB */
static void rotation_column_dB(double B, double L1, double *d1, double *d3)
{
    double c = cos(B), s = sin(B);
    *d1 = L1 * (c - S3 * s);
    *d3 = -L1 * (S3 * s + c);
}

/* kinematics.joint_velocity */
void tapmp_joint_velocity(double B, double dX, double dZ, double dB, double L1, double dq[3])
{
    double a1, a3;
    tapmp_rotation_column(B, L1, &a1, &a3);
    dq[0] = dX + S3 * dZ + a1 * dB;
    dq[1] = dX;
    dq[2] = dX - S3 * dZ + a3 * dB;
}

/* kinematics.task_velocity */
void tapmp_task_velocity(double B, const double dq[3], double L1, double dx[3])
{
    double a1, a3;
    tapmp_rotation_column(B, L1, &a1, &a3);
    double dB = (dq[0] + dq[2] - 2.0 * dq[1]) / (a1 + a3);
    dx[0] = dq[1];
    dx[1] = (dq[0] - dq[1] - a1 * dB) / S3;
    dx[2] = dB;
}

/* kinematics.solve_transpose */
void tapmp_solve_transpose(double B, const double v[3], double L1, double w[3])
{
    double a1, a3;
    tapmp_rotation_column(B, L1, &a1, &a3);
    double d = v[1] / S3;
    double w1 = (v[2] + a3 * d) / (a1 + a3);
    double w3 = w1 - d;
    w[0] = w1;
    w[1] = v[0] - w1 - w3;
    w[2] = w3;
}

/* dynamics.mass_matrix */
void tapmp_mass_matrix(double B, const tapmp_params *p, double M[9])
{
    double a1, a3, m1 = p->m_1, m2 = p->m_2, m3 = p->m_3;
    tapmp_rotation_column(B, p->L_1, &a1, &a3);
    M[0] = p->m_p + m1 + m2 + m3;
    M[1] = M[3] = S3 * (m1 - m3);
    M[2] = M[6] = m1 * a1 + m3 * a3;
    M[4] = p->m_p + (m1 + m3) / 3.0;
    M[5] = M[7] = S3 * (m1 * a1 - m3 * a3);
    M[8] = p->I_y + m1 * a1 * a1 + m3 * a3 * a3;
}

/* dynamics.coriolis_times: C(x, xd) v for a v whose B component is v3 */
static void coriolis_times(double B, double dB, double v3, const tapmp_params *p, double out[3])
{
    double d1, d3, a1, a3;
    rotation_column_dB(B, p->L_1, &d1, &d3);
    tapmp_rotation_column(B, p->L_1, &a1, &a3);
    double w1 = p->m_1 * d1 * dB * v3;
    double w3 = p->m_3 * d3 * dB * v3;
    out[0] = w1 + w3;
    out[1] = S3 * (w1 - w3);
    out[2] = a1 * w1 + a3 * w3;
}

/* dynamics.solve_sym3: M y = r for a symmetric positive definite M, by its adjugate */
static void solve_sym3(const double M[9], double r1, double r2, double r3, double y[3])
{
    double a = M[0], b = M[1], c = M[2], d = M[4], e = M[5], f = M[8];
    double A11 = d * f - e * e, A12 = c * e - b * f, A13 = b * e - c * d;
    double A22 = a * f - c * c, A23 = b * c - a * e, A33 = a * d - b * b;
    double det = a * A11 + b * A12 + c * A13;
    y[0] = (A11 * r1 + A12 * r2 + A13 * r3) / det;
    y[1] = (A12 * r1 + A22 * r2 + A23 * r3) / det;
    y[2] = (A13 * r1 + A23 * r2 + A33 * r3) / det;
}

/* dynamics.task_acceleration (Eq. 11) */
void tapmp_task_acceleration(double B, double dB, const double u[3], const tapmp_params *p,
                             double xdd[3])
{
    double c[3], M[9];
    coriolis_times(B, dB, dB, p, c);
    tapmp_mass_matrix(B, p, M);
    solve_sym3(M, u[0] - c[0], u[1] - c[1] - p->m_p * p->g, u[2] - c[2], xdd);
}

/* dynamics.generalized_force */
void tapmp_generalized_force(double B, double dB, const double xdd[3], double dBv,
                             const tapmp_params *p, double out[3])
{
    double M[9], c[3];
    tapmp_mass_matrix(B, p, M);
    coriolis_times(B, dB, dBv, p, c);
    out[0] = M[0] * xdd[0] + M[1] * xdd[1] + M[2] * xdd[2] + c[0];
    out[1] = M[1] * xdd[0] + M[4] * xdd[1] + M[5] * xdd[2] + c[1] + p->m_p * p->g;
    out[2] = M[2] * xdd[0] + M[5] * xdd[1] + M[8] * xdd[2] + c[2];
}

/* plant.quantize */
double tapmp_quantize(double q, double resolution)
{
    if (resolution == 0.0) return q;
    return resolution * floor(q / resolution + 0.5);
}

/* plant._splitmix64 */
static uint64_t splitmix64(uint64_t x)
{
    x += 0x9E3779B97F4A7C15ULL;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
    return x ^ (x >> 31);
}

/* plant.noise_sample: Box-Muller on two SplitMix64 outputs; a sample outside [0, 2^53) counts as 0 */
double tapmp_noise_sample(int seed, double sample, int motor)
{
    uint64_t k = sample >= 0.0 && sample < 9007199254740992.0 ? (uint64_t)sample : 0;
    uint64_t key = splitmix64((uint64_t)seed);
    uint64_t n = 2 * (3 * k + (uint64_t)motor);
    double u1 = (double)((splitmix64(key + n) >> 11) + 1) * 0x1p-53;
    double u2 = (double)(splitmix64(key + n + 1) >> 11) * 0x1p-53;
    return sqrt(-2.0 * log(u1)) * cos(TWO_PI * u2);
}

/* One offender of a range check: its name, value and what is allowed; returns `kind`. */
static int offender(const char *n, double x, const char *a, int kind, const char **name, double *value,
                    const char **allowed)
{
    *name = n, *value = x, *allowed = a;
    return kind;
}

/* plant.PlantModel.__init__ (state and reference gaps; ranges are checked by the caller) */
void tapmp_plant_init(tapmp_plant *pl, const double pose0[3], const double rate0[3])
{
    double q[3];
    for (int i = 0; i < 3; i++) {
        pl->s[i] = pose0[i];
        pl->s[3 + i] = rate0[i];
    }
    pl->s[6] = pl->s[7] = 0.0;  /* the flexible mode starts at rest */
    tapmp_inverse(pose0[0], pose0[1], pose0[2], pl->p.L_1, q);
    pl->gap12_0 = q[1] - q[0];
    pl->gap23_0 = q[2] - q[1];
    pl->sample = 0.0;
}

/* plant._attraction: force (gap / g)^2 per pair, g = gap + d; NaN once g <= 0 */
static void attraction(double force, double gap, double d12, double d23, double *a12, double *a23)
{
    double s12 = gap + d12, s23 = gap + d23;
    double r12 = s12 > 0.0 ? gap / s12 : NAN;
    double r23 = s23 > 0.0 ? gap / s23 : NAN;
    *a12 = force * (r12 * r12);
    *a23 = force * (r23 * r23);
}

/* plant.PlantModel._make_rhs: the fused right-hand side (Eq. 2-4, 11-14 with friction
 * pulling, attraction and cogging, and the flexible mode in Z), forces already saturated */
void tapmp_plant_rhs(const tapmp_plant *pl, const double s[8], const double F[3], double ds[8])
{
    const tapmp_params *p = &pl->p;
    const tapmp_plant_config *c = &pl->c;
    double L1 = p->L_1, m1 = p->m_1, m3 = p->m_3, mpg = p->m_p * p->g;
    double M11 = p->m_p + p->m_1 + p->m_2 + p->m_3;
    double M12 = S3 * (m1 - m3);
    int flex = c->flex_frequency > 0.0;
    double m_f = flex ? c->flex_mass : 0.0;               /* the part of m_p on the mode */
    double M22 = (p->m_p - m_f) + (m1 + m3) / 3.0;        /* m_p - 0.0 is m_p: rigid bits unchanged */
    double X = s[0], Z = s[1], B = s[2], dX = s[3], dZ = s[4], dB = s[5];
    double F1 = F[0], F2 = F[1], F3 = F[2], vs = c->v_s;
    double cB = cos(B), sB = sin(B);
    double a1 = L1 * (S3 * cB + sB);                      /* rotation_column (Eq. 4) */
    double a3 = L1 * (S3 * cB - sB);
    double dq1 = dX + S3 * dZ + a1 * dB;                  /* joint_velocity (Eq. 3) */
    double dq3 = dX - S3 * dZ + a3 * dB;
    F1 -= c->c_v[0] * dq1 + c->F_c[0] * tanh(dq1 / vs);  /* friction */
    F2 -= c->c_v[1] * dX + c->F_c[1] * tanh(dX / vs);
    F3 -= c->c_v[2] * dq3 + c->F_c[2] * tanh(dq3 / vs);
    if (c->k_pull != 0.0 || c->attraction_force != 0.0 || c->cogging_amplitude != 0.0) {
        double q1 = X + S3 * Z + L1 * (1.0 - cB + S3 * sB);   /* inverse (Eq. 2) */
        double q3 = X - S3 * Z - L1 * (1.0 - cB - S3 * sB);
        if (c->k_pull != 0.0) {                           /* mutual pulling */
            double p12 = c->k_pull * (X - q1 - pl->gap12_0);
            double p23 = c->k_pull * (q3 - X - pl->gap23_0);
            F1 += p12;
            F2 += p23 - p12;
            F3 -= p23;
        }
        if (c->attraction_force != 0.0) {                 /* attraction */
            double a12, a23;
            attraction(c->attraction_force, c->attraction_gap, X - q1 - pl->gap12_0,
                       q3 - X - pl->gap23_0, &a12, &a23);
            F1 += a12;
            F2 += a23 - a12;
            F3 -= a23;
        }
        if (c->cogging_amplitude != 0.0) {                /* cogging */
            double A = c->cogging_amplitude, pitch = c->cogging_pitch;
            F1 += A * sin(TWO_PI * q1 / pitch + c->cogging_phase[0]);
            F2 += A * sin(TWO_PI * X / pitch + c->cogging_phase[1]);
            F3 += A * sin(TWO_PI * q3 / pitch + c->cogging_phase[2]);
        }
    }
    double d1 = L1 * (cB - S3 * sB);                      /* rotation_column_dB */
    double d3 = -L1 * (S3 * sB + cB);
    double w1 = m1 * d1 * dB * dB;                        /* C xd */
    double w3 = m3 * d3 * dB * dB;
    double r1 = F1 + F2 + F3 - (w1 + w3);                 /* J^T F - C xd - G (Eq. 11, 14) */
    double r2 = S3 * (F1 - F3) - S3 * (w1 - w3) - mpg;
    double a_f = 0.0;                                     /* the mode's spring-damper force / m_f */
    if (flex) {
        double w_f = TWO_PI * c->flex_frequency;
        a_f = w_f * w_f * s[6] + 2.0 * c->flex_damping * w_f * s[7];
        r2 += m_f * a_f;                                  /* its reaction on the platform in Z */
    }
    double r3 = a1 * F1 + a3 * F3 - (a1 * w1 + a3 * w3);
    double M13 = m1 * a1 + m3 * a3;                       /* exact mass matrix (Eq. 12) */
    double M23 = S3 * (m1 * a1 - m3 * a3);
    double M33 = p->I_y + m1 * a1 * a1 + m3 * a3 * a3;
    double A11 = M22 * M33 - M23 * M23;                   /* adjugate solve */
    double A12 = M13 * M23 - M12 * M33;
    double A13 = M12 * M23 - M13 * M22;
    double A22 = M11 * M33 - M13 * M13;
    double A23 = M12 * M13 - M11 * M23;
    double A33 = M11 * M22 - M12 * M12;
    double det = M11 * A11 + M12 * A12 + M13 * A13;
    ds[0] = dX;
    ds[1] = dZ;
    ds[2] = dB;
    ds[3] = (A11 * r1 + A12 * r2 + A13 * r3) / det;
    ds[4] = (A12 * r1 + A22 * r2 + A23 * r3) / det;
    ds[5] = (A13 * r1 + A23 * r2 + A33 * r3) / det;
    ds[6] = flex ? s[7] : 0.0;                            /* the mode: z_f'' = -Z'' - a_f */
    ds[7] = flex ? -ds[4] - a_f : 0.0;
}

static double saturate(double F, double lim)
{
    if (F < -lim) F = -lim;
    return F > lim ? lim : F;
}

/* plant.PlantModel.step: classic RK4 with `substeps` steps */
int tapmp_plant_step(const tapmp_plant *pl, double t0, double h, const double F_in[3], double s_new[8])
{
    double F[3] = {F_in[0], F_in[1], F_in[2]};
    double lim = pl->c.force_limit;
    const double *d = pl->c.disturbance_force;
    if (lim > 0.0)
        for (int i = 0; i < 3; i++) F[i] = saturate(F[i], lim);
    if ((d[0] != 0.0 || d[1] != 0.0 || d[2] != 0.0) && t0 >= pl->c.disturbance_time)
        for (int i = 0; i < 3; i++) F[i] += d[i];  /* an external force: not limited by the motor */
    int n = pl->c.substeps;
    double dt = h / n, hdt = 0.5 * dt, dt6 = dt / 6.0;
    enum { N = TAPMP_PLANT_STATES };
    double s[N], k1[N], k2[N], k3[N], k4[N], t[N];
    for (int i = 0; i < N; i++) s[i] = pl->s[i];
    for (int step = 0; step < n; step++) {
        tapmp_plant_rhs(pl, s, F, k1);
        for (int i = 0; i < N; i++) t[i] = s[i] + hdt * k1[i];
        tapmp_plant_rhs(pl, t, F, k2);
        for (int i = 0; i < N; i++) t[i] = s[i] + hdt * k2[i];
        tapmp_plant_rhs(pl, t, F, k3);
        for (int i = 0; i < N; i++) t[i] = s[i] + dt * k3[i];
        tapmp_plant_rhs(pl, t, F, k4);
        for (int i = 0; i < N; i++) s[i] = s[i] + dt6 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    }
    for (int i = 0; i < N; i++) s_new[i] = s[i];
    return fabs(s[2]) < HALF_PI && isfinite(s[0] + s[1] + s[3] + s[4] + s[5] + s[6] + s[7]);
}

/* The right-hand side on the forces tapmp_plant_step integrates with: saturated, then the force
 * step added from disturbance_time on (a discontinuity in time: a Model Exchange host gets it as
 * a time event). */
void tapmp_plant_derivatives(const tapmp_plant *pl, double t, const double s[6], const double F_in[3], double ds[6])
{
    double F[3] = {F_in[0], F_in[1], F_in[2]};
    double s8[TAPMP_PLANT_STATES] = {s[0], s[1], s[2], s[3], s[4], s[5], 0.0, 0.0}, ds8[TAPMP_PLANT_STATES];
    double lim = pl->c.force_limit;
    const double *d = pl->c.disturbance_force;
    if (lim > 0.0)
        for (int i = 0; i < 3; i++) F[i] = saturate(F[i], lim);
    if ((d[0] != 0.0 || d[1] != 0.0 || d[2] != 0.0) && t >= pl->c.disturbance_time)
        for (int i = 0; i < 3; i++) F[i] += d[i];
    tapmp_plant_rhs(pl, s8, F, ds8);
    for (int i = 0; i < 6; i++) ds[i] = ds8[i];
}

/* plant.PlantModel.measured_positions, joint_positions, joint_velocities and the state */
void tapmp_plant_outputs(const tapmp_plant *pl, double out[15])
{
    const double *s = pl->s;
    double L1 = pl->p.L_1;
    tapmp_inverse(s[0], s[1], s[2], L1, out + 3);
    for (int i = 0; i < 3; i++) {
        double q = out[3 + i];
        if (pl->c.noise_rms > 0.0) q = q + pl->c.noise_rms * tapmp_noise_sample(pl->c.noise_seed, pl->sample, i);
        out[i] = tapmp_quantize(q, pl->c.encoder_resolution);
    }
    tapmp_joint_velocity(s[2], s[3], s[4], s[5], L1, out + 6);
    for (int i = 0; i < 6; i++) out[9 + i] = s[i];
}

/* control.feedforward (Eq. 26 / 39) */
int tapmp_feedforward(const double q[3], const double dq[3], const double dx_d[3],
                      const double ddx_d[3], const tapmp_params *p, double u_d[3], double *arg)
{
    double x[3], dx[3], gf[3];
    if (!tapmp_forward(q, p->L_1, x, arg)) return 0;
    double B = x[2];
    tapmp_task_velocity(B, dq, p->L_1, dx);
    tapmp_generalized_force(B, dx[2], ddx_d, dx_d[2], p, gf);
    tapmp_solve_transpose(B, gf, p->L_1, u_d);
    return 1;
}

/* control.scdc_command (Eq. 22-25) */
void tapmp_scdc_command(const double e[3], const double de[3], const double c[3],
                        const double integral_c[3], const double u_d[3], const tapmp_gains *g,
                        double u[3])
{
    for (int i = 0; i < 3; i++) {
        double b = g->b[i];
        double e_c = e[i] + b * integral_c[i];   /* Eq. 22 */
        double de_c = de[i] + b * c[i];          /* Eq. 23 */
        double n = de_c + g->D[i] * e_c;         /* Eq. 24 */
        u[i] = g->K_T[i] * u_d[i] + g->Lambda_v[i] * n + g->Lambda_p[i] * c[i];  /* Eq. 25 */
    }
}

/* control.apd_command (Eq. 38) */
void tapmp_apd_command(const double e[3], const double de[3], const double u_d[3],
                       const tapmp_gains *g, double u[3])
{
    for (int i = 0; i < 3; i++)
        u[i] = g->K_T[i] * u_d[i] + g->Lambda_v[i] * de[i] + g->Lambda_p[i] * e[i];
}

/* control._modal: row i of (k_c Pi_c + k_d Pi_d) x, mean = (x1 + x2 + x3) / 3 */
static double modal(double k_c, double k_d, const double x[3], int i, double mean)
{
    return k_c * mean + k_d * (x[i] - mean);
}

/* control.pid_command */
void tapmp_pid_command(const double e[3], const double de[3], const double integral_e[3],
                       const double u_d[3], const tapmp_gains *g, double u[3])
{
    double me = (e[0] + e[1] + e[2]) / 3.0;
    double mv = (de[0] + de[1] + de[2]) / 3.0;
    double mi = (integral_e[0] + integral_e[1] + integral_e[2]) / 3.0;
    for (int i = 0; i < 3; i++)
        u[i] = g->K_T[i] * u_d[i] + modal(g->kp_c, g->kp_d, e, i, me) + modal(g->kv_c, g->kv_d, de, i, mv)
               + modal(g->ki_c, g->ki_d, integral_e, i, mi);
}

/* The gain of motor i's own integral state in its command, u_i = ... + k_i I_i [command units / (m s)]:
 * Lambda_v D b (SC-DC, Eq. 22-25) or the diagonal of ki_c Pi_c + ki_d Pi_d (PID-DC). PID-DC's integral
 * couples the motors unless ki_c = ki_d; the anti-windup acts on the diagonal, motor by motor. */
static double integral_gain(int law, const tapmp_gains *g, int i)
{
    return law == TAPMP_SCDC ? g->Lambda_v[i] * g->D[i] * g->b[i] : (g->ki_c + 2.0 * g->ki_d) / 3.0;
}

/* The anti-windup of one sample (tapmp_model.h, TAPMP_AW_*) for SC-DC and PID-DC at the force limit
 * lim > 0 [N]: `integral` holds this sample's candidate (before[] plus h x, x the integrated c or e) and
 * u its command. Clamping puts back before[i] for a motor whose force u_i/K_T is beyond lim while its
 * increment drives it further out, and recomputes u; back-calculation moves the integral of a motor
 * beyond lim so that its term takes back the fraction 1 - exp(-h/T_t) of the excess (the exact decay over
 * h of the continuous law dI_term/dt = (u_sat - u)/T_t, which stays below 1 for any h, where h/T_t would
 * overshoot the limit for h > T_t); the output of this sample is saturated either way.
 * SC-DC's integral of c keeps the sum it starts with (c sums to zero, Eq. 21), and no c can change that
 * sum: a common part left in it would never unwind. So SC-DC holds its three integrals together (all, if
 * one motor is to be held) and takes the mean out of the back-calculation's corrections. */
static void unwind(int mode, double lim, double T_t, int law, const tapmp_gains *g, double h, const double e[3],
                   const double de[3], const double c[3], const double before[3], const double u_d[3],
                   double integral[3], double u[3])
{
    const double *x = law == TAPMP_SCDC ? c : e;
    double dI[3] = {0.0, 0.0, 0.0};
    int held = 0;
    for (int i = 0; i < 3; i++) {
        double F = u[i] / g->K_T[i], k = integral_gain(law, g, i);
        if (!(fabs(F) > lim && k > 0.0)) continue;
        if (mode == TAPMP_AW_CLAMP && x[i] * F > 0.0) {
            integral[i] = before[i];
            held = 1;
        } else if (mode == TAPMP_AW_BACK) {
            dI[i] = -expm1(-h / T_t) * (saturate(F, lim) - F) * g->K_T[i] / k;
        }
    }
    if (law == TAPMP_SCDC) {
        double mean = (dI[0] + dI[1] + dI[2]) / 3.0;
        for (int i = 0; i < 3; i++) {
            if (held) integral[i] = before[i];
            else integral[i] += dI[i] - mean;
        }
    } else {
        for (int i = 0; i < 3; i++) integral[i] += dI[i];
    }
    if (held && law == TAPMP_SCDC) tapmp_scdc_command(e, de, c, integral, u_d, g, u);
    else if (held) tapmp_pid_command(e, de, integral, u_d, g, u);
}

/* control.ControllerModel.sample */
int tapmp_controller_sample(const tapmp_params *p, const tapmp_gains *g, int law,
                            int velocity_source, double force_limit, int anti_windup,
                            double anti_windup_time, const tapmp_controller_state *st, double h,
                            const double ref[9], const double q[3], const double dq_in[3], int advance,
                            double out[12], tapmp_controller_state *next, double *arg)
{
    double L1 = p->L_1, q_d[3], dq_d[3], dq[3], e[3], de[3], es[3], u_d[3], u[3];
    double integral[3] = {st->integral[0], st->integral[1], st->integral[2]};
    tapmp_inverse(ref[0], ref[1], ref[2], L1, q_d);
    tapmp_joint_velocity(ref[2], ref[3], ref[4], ref[5], L1, dq_d);
    for (int i = 0; i < 3; i++)
        dq[i] = (velocity_source == 0 && st->has_q_prev && advance) ? (q[i] - st->q_prev[i]) / h
                                                                     : dq_in[i];
    for (int i = 0; i < 3; i++) {
        e[i] = q_d[i] - q[i];       /* Eq. 15 */
        de[i] = dq_d[i] - dq[i];
    }
    es[0] = e[0] - e[1];            /* Eq. 18 */
    es[1] = e[1] - e[2];
    es[2] = e[2] - e[0];
    if (!tapmp_feedforward(q, dq, ref + 3, ref + 6, p, u_d, arg)) return 0;  /* Eq. 26 */
    double c[3] = {es[0] - es[2], es[1] - es[0], es[2] - es[1]};  /* Eq. 21 */
    if (law == TAPMP_SCDC) {
        if (advance)
            for (int i = 0; i < 3; i++) integral[i] = integral[i] + h * c[i];
        tapmp_scdc_command(e, de, c, integral, u_d, g, u);
    } else if (law == TAPMP_PIDDC) {
        if (advance)
            for (int i = 0; i < 3; i++) integral[i] = integral[i] + h * e[i];
        tapmp_pid_command(e, de, integral, u_d, g, u);
    } else {
        tapmp_apd_command(e, de, u_d, g, u);
    }
    if (advance && anti_windup != TAPMP_AW_OFF && force_limit > 0.0 && (law == TAPMP_SCDC || law == TAPMP_PIDDC))
        unwind(anti_windup, force_limit, anti_windup_time, law, g, h, e, de, c, st->integral, u_d, integral, u);
    for (int i = 0; i < 3; i++) {
        double F = u[i] / g->K_T[i];
        out[i] = force_limit > 0.0 ? saturate(F, force_limit) : F;
        out[3 + i] = u[i];
        out[6 + i] = e[i];
        out[9 + i] = es[i];
    }
    if (advance) {
        for (int i = 0; i < 3; i++) {
            next->integral[i] = integral[i];
            next->q_prev[i] = q[i];
        }
        next->has_q_prev = 1;
    } else if (next != st) {
        *next = *st;
    }
    return 1;
}

/* control.sample_index */
int tapmp_sample_index(double t, double t0, double T_s, double *k)
{
    *k = floor((t - t0) / T_s + 0.5);
    return fabs(t - (t0 + *k * T_s)) <= TAPMP_SAMPLE_TOLERANCE * T_s;
}

/* control.ControllerModel.communication_point: sample or hold */
int tapmp_clock_at(tapmp_clock *c, double t, double *k, double *steps, double *missed)
{
    int on_grid = tapmp_sample_index(t, c->t0, c->T_s, k);
    *missed = NAN;
    if (!on_grid || (c->has_sample && *k <= c->k_last)) {
        if (!on_grid && c->has_sample && !c->warned &&
            t > c->t0 + (c->k_last + 1.0 + TAPMP_SAMPLE_TOLERANCE) * c->T_s) {
            c->warned = 1;  /* a due sample instant passed without a communication point on it */
            *missed = c->t0 + (c->k_last + 1.0) * c->T_s;
        }
        return 0;
    }
    /* the first sample integrates over one period, as every later one on an unbroken grid */
    *steps = c->has_sample ? *k - c->k_last : 1.0;
    return 1;
}

int tapmp_clock_sampled(tapmp_clock *c, double k, double steps)
{
    int warn = steps > 1.0 && !c->warned;
    c->k_last = k;
    c->has_sample = 1;
    c->warned = c->warned || warn;
    return warn;
}

/* control.missed_sample_text */
void tapmp_clock_missed_text(const tapmp_clock *c, double t, double due, char *text, size_t size)
{
    snprintf(text, size, "the host's communication points skip sample instants of T_s = %g s: none fell "
             "on the sample instant t = %.9g s; at t = %.9g s the controller holds its command until a "
             "communication point falls on its grid t0 + k T_s", c->T_s, due, t);
}

/* control.skipped_samples_text */
void tapmp_clock_skipped_text(const tapmp_clock *c, double t, double steps, char *text, size_t size)
{
    snprintf(text, size, "the host's communication points skip sample instants of T_s = %g s: the "
             "controller sampled at t = %.9g s, %g s (%.0f T_s) after its previous sample, and uses that "
             "interval for the velocity estimate and the integral (it samples only at communication points "
             "on its grid t0 + k T_s)", c->T_s, t, steps * c->T_s, steps);
}

/* --- the hidden values of an FMU state --- */

/* The largest sample count checked: every whole number up to it is a double. */
#define SAMPLE_COUNT_MAX 9007199254740992.0  /* 2^53 */

int tapmp_plant_state_check(const double s[6], double sample, const double out[6], const char **name,
                            double *value, const char **allowed)
{
    static const char *const names[6] = {"plant state X", "plant state Z", "plant state B", "plant state dX",
                                         "plant state dZ", "plant state dB"};
    static const char *const outputs[6] = {"output X", "output Z", "output B", "output dX", "output dZ",
                                           "output dB"};
    for (int i = 0; i < 6; i++)
        if (!isfinite(s[i])) return offender(names[i], s[i], "a finite number", 1, name, value, allowed);
    if (!(fabs(s[2]) < HALF_PI))
        return offender(names[2], s[2], "|B| < pi/2 rad (the kinematic domain)", 3, name, value, allowed);
    if (!(sample >= 0.0 && sample <= SAMPLE_COUNT_MAX && sample == floor(sample)))
        return offender("plant sample count", sample, "a whole number in [0, 2^53] (the steps taken)", 1, name,
                        value, allowed);
    /* the outputs X..dB are the state itself (tapmp_plant_outputs): any difference is a forged state */
    for (int i = 0; i < 6; i++)
        if (!(out[i] == s[i]))
            return offender(outputs[i], out[i], "the plant state's value it is computed from (the state and its "
                            "outputs disagree)", 1, name, value, allowed);
    return 0;
}

int tapmp_controller_state_check(const tapmp_params *p, const tapmp_gains *g, int law, double force_limit,
                                 const tapmp_controller_state *st, const tapmp_clock *c, double t,
                                 const char **name, double *value, const char **allowed)
{
    static const char *const integral[3] = {"controller integral1", "controller integral2", "controller integral3"};
    static const char *const q_prev[3] = {"controller previous q1", "controller previous q2",
                                          "controller previous q3"};
    for (int i = 0; i < 3; i++)
        if (!isfinite(st->integral[i])) return offender(integral[i], st->integral[i], "a finite number [m s]", 1,
                                                        name, value, allowed);
    if (st->has_q_prev) {
        for (int i = 0; i < 3; i++)
            if (!isfinite(st->q_prev[i]))
                return offender(q_prev[i], st->q_prev[i], "a finite number [m]", 1, name, value, allowed);
        /* a previous q was a sample that passed tapmp_feedforward's domain check */
        double a = SQRT3 / (2.0 * p->L_1) * (2.0 * st->q_prev[1] - st->q_prev[0] - st->q_prev[2]);
        if (!(fabs(a) < 1.0))
            return offender("sqrt(3)/(2 L1)*(2 q2 - q1 - q3) of the controller's previous q", a,
                            "|value| < 1 (the kinematic domain)", 3, name, value, allowed);
    }
    /* The integral's bound: the force its term of the command commands alone (the command with every
     * error, rate and feedforward zero: Lambda_v D b I / K_T for SC-DC, the modal ki terms / K_T for
     * PID-DC) may not exceed the force limit, or TAPMP_FORCE_CAP with none. Beyond that the integral
     * has wound up past what the motors may be sent: the command sits at the limit whatever the errors
     * do until the integral unwinds, and without a limit it commands forces no setting allows. The
     * scenarios' runs stay near 5 N (1e-8 of the cap). APD-DC has no integral term: finite suffices. */
    if (law == TAPMP_SCDC || law == TAPMP_PIDDC) {
        const double zero[3] = {0.0, 0.0, 0.0};
        double u[3];
        if (law == TAPMP_SCDC) tapmp_scdc_command(zero, zero, zero, st->integral, zero, g, u);
        else tapmp_pid_command(zero, zero, st->integral, zero, g, u);
        double cap = force_limit > 0.0 ? force_limit : TAPMP_FORCE_CAP;
        for (int i = 0; i < 3; i++)
            if (!(fabs(u[i] / g->K_T[i]) <= cap))
                return offender(integral[i], st->integral[i], force_limit > 0.0 ?
                                "an integral whose term alone commands at most force_limit (|u_I/K_T| <= "
                                "force_limit)" :
                                "an integral whose term alone commands at most 1e9 N (|u_I/K_T| <= 1e9 N, the "
                                "largest force_limit, as force_limit = 0)", 1, name, value, allowed);
    }
    double tol = TAPMP_SAMPLE_TOLERANCE * c->T_s;
    if (!(isfinite(c->t0) && c->t0 <= t + tol))
        return offender("controller clock t0", c->t0, "the start time: a finite number <= the state's time", 1,
                        name, value, allowed);
    /* the last instant sampled, t0 + k_last T_s, lies at or before the state's time */
    double k = c->k_last;
    if (!(k >= 0.0 && k == floor(k) && k <= (t - c->t0) / c->T_s + TAPMP_SAMPLE_TOLERANCE))
        return offender("controller clock k_last", k, "a whole number of sample periods with t0 + k_last T_s <= "
                        "the state's time (0 <= k_last <= (t - t0)/T_s)", 1, name, value, allowed);
    return 0;
}

/* trajectory.circle_reference */
static void circle_reference(double t, const tapmp_trajectory *tp, double ref[9])
{
    double w = TWO_PI * tp->f_xz, th = w * t + tp->phase_xz;
    double s = sin(th), c = cos(th), R = tp->radius;
    double wb = TWO_PI * tp->f_B, thb = wb * t + tp->phase_B;
    double sb = sin(thb), cb = cos(thb), A = tp->B_amplitude;
    ref[0] = tp->X_c + R * s;
    ref[1] = tp->Z_c + R * c;
    ref[2] = tp->B_offset + A * sb;
    ref[3] = R * w * c;
    ref[4] = -R * w * s;
    ref[5] = A * wb * cb;
    ref[6] = -R * w * w * s;
    ref[7] = -R * w * w * c;
    ref[8] = -A * wb * wb * sb;
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
void tapmp_move_plan(int profile, const double q0s[3], const double q1s[3], const double v_max[3],
                     const double a_max[3], const double j_max[3], tapmp_axis_plan plan[3])
{
    double own[3][4];
    for (int i = 0; i < 3; i++) {
        double D = fabs(q1s[i] - q0s[i]), V = v_max[i];
        if (D == 0.0) {
            own[i][0] = own[i][1] = own[i][2] = own[i][3] = 0.0;
        } else if (profile == 2) {
            own[i][0] = own[i][1] = 0.0;
            own[i][2] = own[i][3] = D / V;
        } else {
            scurve_times(D, V, a_max[i], j_max[i], &own[i][0], &own[i][1], &own[i][2]);
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
        double J = j_max[i] * lam * lam * lam;
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

/* trajectory.reference */
void tapmp_reference(double t, const tapmp_trajectory *tp, double ref[9])
{
    if (tp->profile == 0) {
        circle_reference(t, tp, ref);
        return;
    }
    double tr = t - tp->t_move;
    for (int i = 0; i < 3; i++) {
        double a[3];
        if (tp->profile == 1) {
            a[0] = tr < 0.0 ? tp->axis[i].q0 : tp->axis[i].q1, a[1] = 0.0, a[2] = 0.0;
        } else {
            axis_at(tr, &tp->axis[i], tp->profile, a);
        }
        ref[i] = a[0], ref[3 + i] = a[1], ref[6 + i] = a[2];
    }
}

/* The reference's one relation between settings (tapmp_settings.h calls it after the ranges). */
static int trajectory_domain_check(const tapmp_trajectory_settings *s, const char **name, double *value,
                                   const char **allowed)
{
    if (!(fabs(s->B_offset) + s->B_amplitude < HALF_PI))
        return offender("B_amplitude", s->B_amplitude, "|B_offset| + B_amplitude < pi/2 rad (kinematic domain)", 3,
                        name, value, allowed);
    return 0;
}

/* The plant's one relation between settings: the flexible mode's modal mass is a part of the
 * platform's mass (tapmp_settings.h calls it after the ranges). */
static int plant_flex_check(const tapmp_plant_settings *s, const char **name, double *value, const char **allowed)
{
    if (s->c.flex_frequency > 0.0 && !(s->c.flex_mass < s->p.m_p))
        return offender("flex_mass", s->c.flex_mass, "flex_mass < m_p (the modal mass is a part of the platform's "
                        "mass) while flex_frequency > 0", 1, name, value, allowed);
    return 0;
}

/* The controller's one relation between settings (tapmp_settings.h calls it after the ranges): the
 * anti-windup acts at the controller's own force_limit (it cannot read the plant's), so it needs one. */
static int controller_anti_windup_check(const tapmp_controller_settings *s, const char **name, double *value,
                                        const char **allowed)
{
    if (s->k.anti_windup != TAPMP_AW_OFF && !(s->k.force_limit > 0.0))
        return offender("anti_windup", s->k.anti_windup, "0 (off) while force_limit = 0: the anti-windup acts at the "
                        "controller's own force_limit, which must be > 0 (e.g. the plant's force_limit)", 2, name,
                        value, allowed);
    return 0;
}

/* trajectory._c_trajectory: the settings and the planned move */
void tapmp_trajectory_init(tapmp_trajectory *tp, const tapmp_trajectory_settings *s)
{
    const double a[3] = {s->X_a, s->Z_a, s->B_a}, b[3] = {s->X_b, s->Z_b, s->B_b};
    /* designated: the axis plans, zero here, are filled by tapmp_move_plan below */
    *tp = (tapmp_trajectory){.X_c = s->X_c, .Z_c = s->Z_c, .radius = s->radius, .f_xz = s->f_xz,
                             .phase_xz = s->phase_xz, .B_amplitude = s->B_amplitude, .f_B = s->f_B,
                             .phase_B = s->phase_B, .B_offset = s->B_offset, .profile = s->profile,
                             .t_move = s->t_move};
    tapmp_move_plan(tp->profile, a, b, s->v_max, s->a_max, s->j_max, tp->axis);
}

/* The range checks of every setting, generated from the settings table (tapmp/interface.py). */
#include "tapmp_settings.h"
