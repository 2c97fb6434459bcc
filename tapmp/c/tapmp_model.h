/* The TAPMP model in C: kinematics (Eq. 1-4), task-space dynamics (Eq. 5-14), the plant
 * with its non-idealities, the SC-DC (Eq. 15-26), APD-DC (Eq. 38-39) and PID-DC control laws and
 * the reference trajectory, and the ranges of their settings. Plain functions on doubles, SI
 * units, nothing but libm (and snprintf for the texts of the controller's warnings).
 *
 * This is the one implementation of the equations: the native FMUs compile it in, and the
 * Python package (hence the pythonfmu FMUs and the FMI-free loop) calls it through cffi
 * (tapmp/cmodel.py reads the declarations below from this file). The Python modules
 * kinematics.py, dynamics.py, plant.py (derivatives), control.py and trajectory.py write the
 * same equations readably with the paper's numbers, evaluated in the same order;
 * tests/model/test_cmodel.py checks every function on random states against them. */
#ifndef TAPMP_MODEL_H
#define TAPMP_MODEL_H

#include <stddef.h>

/* Linkage of everything that is not an FMI function. Compiled file by file these are
 * ordinary external declarations. The FMU's sources/all.c compiles the whole FMU as one
 * translation unit and defines TAPMP_LINKAGE as static (and TAPMP_DEFINITION, for object
 * definitions, as static), so that only the fmi2 / fmi3 functions have external linkage:
 * several TAPMP source FMUs link into one program without a clash. A static prototype gives
 * the plain function definition that follows internal linkage (C99 6.2.2). */
#ifndef TAPMP_LINKAGE
#define TAPMP_LINKAGE extern
#endif
#ifndef TAPMP_DEFINITION
#define TAPMP_DEFINITION
#endif

#define TAPMP_S3 0.5773502691896257      /* sqrt(3)/3, the slope of the outer links */
#define TAPMP_SQRT3 1.7320508075688772   /* sqrt(3) */

/* Rigid-body parameters (paper Section 5.1): masses [kg], inertia [kg m^2], width [m], g [m/s^2]. */
typedef struct {
    double m_p, m_1, m_2, m_3, I_y, L_1, g;
} tapmp_params;

/* Plant non-idealities (tapmp.plant.PlantConfig), SI units; 0 switches one off. */
typedef struct {
    double encoder_resolution;  /* [m] */
    double c_v[3];              /* viscous friction [N s/m] */
    double F_c[3];              /* Coulomb friction [N] */
    double v_s;                 /* tanh smoothing velocity [m/s] */
    double force_limit;         /* [N] */
    double k_pull;              /* adjacent-mover pulling stiffness [N/m] (< 0: negative stiffness) */
    double attraction_force;    /* adjacent-mover attraction at the initial gap [N] */
    double attraction_gap;      /* clear gap between adjacent movers at the initial pose [m] */
    double cogging_amplitude;   /* force ripple amplitude [N] */
    double cogging_pitch;       /* force ripple period in the motor position [m] */
    double cogging_phase[3];    /* force ripple phase per motor [rad] */
    double disturbance_force[3];  /* external force step per mover [N] */
    double disturbance_time;    /* when the force step starts [s] */
    double noise_rms;           /* measurement noise rms per measured position [m] */
    int substeps;               /* RK4 steps per communication step */
    int noise_seed;             /* seed of the measurement noise */
    double flex_frequency;      /* the platform's flexible mode in Z: natural frequency [Hz], 0 = rigid */
    double flex_damping;        /* its damping ratio [1] */
    double flex_mass;           /* its modal mass [kg], the part of m_p that moves on the mode */
} tapmp_plant_config;

/* The plant's state: X, Z, B, dX, dZ, dB, then the flexible mode's deflection z_f [m] and rate
 * dz_f [m/s] (at rest, 0, while flex_frequency = 0). */
#define TAPMP_PLANT_STATES 8

/* The plant: parameters, settings, reference gaps and the state (X, Z, B, dX, dZ, dB, z_f, dz_f). */
typedef struct {
    tapmp_params p;
    tapmp_plant_config c;
    double gap12_0, gap23_0;
    double s[8];                /* TAPMP_PLANT_STATES (cffi reads no macro here) */
    double sample;              /* completed steps: the index of the measurement noise */
} tapmp_plant;

/* Controller gains per motor (tapmp.control.Gains) and the PID-DC modal gains
 * (tapmp.control.ModalGains: common mode _c, differential modes _d). */
typedef struct {
    double Lambda_p[3], Lambda_v[3], b[3], D[3], K_T[3];
    double kp_c, kv_c, ki_c, kp_d, kv_d, ki_d;
} tapmp_gains;

/* One axis of a point-to-point move (tapmp.trajectory.AxisPlan): from q0 to q1, sign s,
 * distance D, S-curve phase times Tj, Ta, Tv and end T [s], jerk J, peak acceleration alim,
 * peak velocity vlim. */
typedef struct {
    double q0, q1, s, D, Tj, Ta, Tv, T, J, alim, vlim;
} tapmp_axis_plan;

/* Reference trajectory (tapmp.trajectory.TrajectoryParams): the circle and sinusoid [m, Hz, rad],
 * the profile (0 circle and sinusoid, 1 step, 2 ramp, 3 S-curve), the start of the move [s] and
 * its plan per axis X, Z, B (tapmp_move_plan). */
typedef struct {
    double X_c, Z_c, radius, f_xz, phase_xz, B_amplitude, f_B, phase_B, B_offset;
    int profile;
    double t_move;
    tapmp_axis_plan axis[3];
} tapmp_trajectory;

/* The plant's initial state: pose (X0 [m], Z0 [m], B0 [rad]) and its rates [m/s, m/s, rad/s]. */
typedef struct {
    double pose[3], rate[3];
} tapmp_initial_state;

/* The controller's law (TAPMP_SCDC, TAPMP_APDDC, TAPMP_PIDDC), velocity source (0 backward
 * difference of q, 1 the dq inputs), force command limit [N] (0 = none), sample period [s], and
 * its anti-windup (TAPMP_AW_OFF, TAPMP_AW_CLAMP, TAPMP_AW_BACK) with the back-calculation's
 * tracking time constant [s]. */
typedef struct {
    int law, velocity_source;
    double force_limit, T_s;
    int anti_windup;
    double anti_windup_time;
} tapmp_controller_config;

/* Every setting of each model: one member per parameter of its FMU, named by the column `field`
 * of the settings table (tapmp/interface.py). From that table are generated the FMUs' reading of
 * their variables into these structs (MODEL_READ_SETTINGS in model_vars.h), the Python side's
 * filling by name (tapmp.cmodel.settings) and the range checks below (tapmp_settings.h). */
typedef struct {
    tapmp_params p;
    tapmp_plant_config c;
    tapmp_initial_state x0;
} tapmp_plant_settings;

typedef struct {
    tapmp_params p;
    tapmp_gains g;
    tapmp_controller_config k;
} tapmp_controller_settings;

/* The reference (tapmp.trajectory.TrajectoryParams: circle, sinusoid, profile, move from pose
 * a to pose b, the limits per axis X, Z, B) and the platform width L_1 [m] of q_d. */
typedef struct {
    double X_c, Z_c, radius, f_xz, phase_xz, B_amplitude, f_B, phase_B, B_offset;
    int profile;
    double X_a, Z_a, B_a, X_b, Z_b, B_b, t_move;
    double v_max[3], a_max[3], j_max[3];
    double L_1;
} tapmp_trajectory_settings;

/* --- settings (generated from tapmp/interface.py into tapmp_settings.h) --- */
/* The ranges of a model's settings, in the order of its FMU variables, then the relations
 * between settings (the reference: |B_offset| + B_amplitude < pi/2): 0 if all are allowed, else
 * 1 for a real setting, 2 for an integer one or 3 for a value outside the kinematic domain
 * (Python's KinematicDomainError), with its name, its value and what is allowed (the text of the
 * one-line message "NAME = VALUE is invalid: allowed is ALLOWED"). Every family and the Python
 * model run these, so a value is refused alike everywhere. */
TAPMP_LINKAGE int tapmp_plant_settings_check(const tapmp_plant_settings *s, const char **name, double *value,
                                             const char **allowed);
TAPMP_LINKAGE int tapmp_controller_settings_check(const tapmp_controller_settings *s, const char **name,
                                                  double *value, const char **allowed);
TAPMP_LINKAGE int tapmp_trajectory_settings_check(const tapmp_trajectory_settings *s, const char **name,
                                                  double *value, const char **allowed);

/* --- kinematics (tapmp/kinematics.py) --- */
/* Eq. 2: pose (X [m], Z [m], B [rad]) -> motor positions q [m]. */
TAPMP_LINKAGE void tapmp_inverse(double X, double Z, double B, double L1, double q[3]);
/* Eq. 1: q [m] -> pose; returns 0 and the arcsine argument in *arg outside |arg| < 1. */
TAPMP_LINKAGE int tapmp_forward(const double q[3], double L1, double x[3], double *arg);
/* Third column of J (Eq. 4), rows 1 and 3 [m/rad]. */
TAPMP_LINKAGE void tapmp_rotation_column(double B, double L1, double *a1, double *a3);
/* Eq. 3: qdot = J(x) xdot [m/s]. */
TAPMP_LINKAGE void tapmp_joint_velocity(double B, double dX, double dZ, double dB, double L1, double dq[3]);
/* xdot = J^-1 qdot. */
TAPMP_LINKAGE void tapmp_task_velocity(double B, const double dq[3], double L1, double dx[3]);
/* Eq. 14: w = J^-T v, generalized forces [N, N, N m] -> motor forces [N]. */
TAPMP_LINKAGE void tapmp_solve_transpose(double B, const double v[3], double L1, double w[3]);

/* --- dynamics (tapmp/dynamics.py) --- */
/* Exact mass matrix M(x) (Eq. 12, general m_1, m_3), row-major 3x3. */
TAPMP_LINKAGE void tapmp_mass_matrix(double B, const tapmp_params *p, double M[9]);
/* Forward dynamics (Eq. 11): xdd for the generalized force u = J^T F. */
TAPMP_LINKAGE void tapmp_task_acceleration(double B, double dB, const double u[3], const tapmp_params *p,
                             double xdd[3]);
/* Inverse dynamics M xdd + C(x, xd) v + G; dB the B rate, dBv the B component of v. */
TAPMP_LINKAGE void tapmp_generalized_force(double B, double dB, const double xdd[3], double dBv,
                             const tapmp_params *p, double out[3]);

/* --- plant (tapmp/plant.py) --- */
/* Round q [m] to the nearest encoder count of `resolution` [m] (0 = exact). */
TAPMP_LINKAGE double tapmp_quantize(double q, double resolution);
/* Standard normal number for (seed, sample index, motor 0..2), counter-based (plant.noise_sample). */
TAPMP_LINKAGE double tapmp_noise_sample(int seed, double sample, int motor);
/* Set the initial state, the reference gaps of the pulling law and the sample count. */
TAPMP_LINKAGE void tapmp_plant_init(tapmp_plant *pl, const double pose0[3], const double rate0[3]);
/* Right-hand side d/dt (X, Z, B, dX, dZ, dB, z_f, dz_f) for saturated, held forces F [N]. */
TAPMP_LINKAGE void tapmp_plant_rhs(const tapmp_plant *pl, const double s[8], const double F[3],
                                   double ds[8]);
/* Advance from t over h [s] with RK4 and `substeps`; F [N] is saturated here, then the force
 * step is added from disturbance_time on. The new state (8 values) is written to s_new; returns 1 if
 * it is finite with |B| < pi/2, else 0 (state untouched). */
TAPMP_LINKAGE int tapmp_plant_step(const tapmp_plant *pl, double t, double h, const double F[3],
                                   double s_new[8]);
/* Model Exchange: d/dt (X, Z, B, dX, dZ, dB) at t [s] in the rigid state s for the commanded forces F_in [N],
 * saturated and with the force step from disturbance_time on, as tapmp_plant_step applies them over
 * a step starting at t (the flexible mode at rest: Model Exchange refuses flex_frequency > 0). */
TAPMP_LINKAGE void tapmp_plant_derivatives(const tapmp_plant *pl, double t, const double s[6], const double F_in[3],
                                           double ds[6]);
/* Outputs in the FMU's order: q1..q3 (measured: true + noise of this sample, quantized), q_true,
 * dq, X, Z, B, dX, dZ, dB (15). */
TAPMP_LINKAGE void tapmp_plant_outputs(const tapmp_plant *pl, double out[15]);

/* --- control (tapmp/control.py) --- */
enum { TAPMP_SCDC = 0, TAPMP_APDDC = 1, TAPMP_PIDDC = 2 };
/* Dynamics compensation u_d of Eq. 26 / 39 [N]; returns 0 (and *arg) if q leaves Eq. 1's domain. */
TAPMP_LINKAGE int tapmp_feedforward(const double q[3], const double dq[3], const double dx_d[3],
                      const double ddx_d[3], const tapmp_params *p, double u_d[3], double *arg);
/* SC-DC command u of Eq. 22-25. */
TAPMP_LINKAGE void tapmp_scdc_command(const double e[3], const double de[3], const double c[3],
                        const double integral_c[3], const double u_d[3], const tapmp_gains *g,
                        double u[3]);
/* APD-DC command of Eq. 38 (k_p = Lambda_p, k_v = Lambda_v, K_T1 = K_T, Eq. 41). */
TAPMP_LINKAGE void tapmp_apd_command(const double e[3], const double de[3], const double u_d[3],
                       const tapmp_gains *g, double u[3]);

/* PID-DC command u = K_T u_d + K_P e + K_V de + K_I int(e), K = k_c Pi_c + k_d Pi_d. */
TAPMP_LINKAGE void tapmp_pid_command(const double e[3], const double de[3], const double integral_e[3],
                       const double u_d[3], const tapmp_gains *g, double u[3]);


/* The integrals' anti-windup at the controller's force_limit (the setting anti_windup): none; conditional
 * integration (a motor whose command is beyond the limit does not integrate a sample that drives it further
 * out); back-calculation (each sample the integral term of a motor beyond the limit is pulled toward the
 * limit by the fraction 1 - exp(-h / anti_windup_time) of the excess). */
enum { TAPMP_AW_OFF = 0, TAPMP_AW_CLAMP = 1, TAPMP_AW_BACK = 2 };

/* The discrete controller's state between samples. */
typedef struct {
    double integral[3];  /* running integral of c (SC-DC) or e (PID-DC) [m s] */
    double q_prev[3];    /* previous measured positions [m] */
    int has_q_prev;
} tapmp_controller_state;

/* One sample of tapmp.control.ControllerModel.sample: ref (9 values), q, dq_in -> F, u, e,
 * e_s (12 outputs, in that order). `advance` = 0 leaves the state untouched (initialization).
 * anti_windup (TAPMP_AW_*) acts on the integral at force_limit [N] (none without a limit), the
 * back-calculation with the time constant anti_windup_time [s].
 * The new state goes to *next (may equal *st). Returns 0 (and *arg) on a domain error. */
TAPMP_LINKAGE int tapmp_controller_sample(const tapmp_params *p, const tapmp_gains *g, int law,
                            int velocity_source, double force_limit, int anti_windup,
                            double anti_windup_time, const tapmp_controller_state *st, double h, const double ref[9],
                            const double q[3], const double dq_in[3], int advance,
                            double out[12], tapmp_controller_state *next, double *arg);

/* tapmp.control.SAMPLE_TOLERANCE: a communication point within this x T_s of a sample
 * instant t0 + k T_s is that instant. Wide enough for a host that sums its steps (t += h drifts
 * by 1e-7 T_s after 1e5 steps and by 2e-5 T_s after 1e6 steps of 1e-4 s), narrow enough that
 * every host step >= 1e-4 T_s (10 ns at T_s = 0.1 ms) lands off the grid. */
#define TAPMP_SAMPLE_TOLERANCE 1e-4

/* tapmp.control.sample_index: 1 and *k if the communication point t [s] falls on the sample
 * instant t0 + k T_s (within TAPMP_SAMPLE_TOLERANCE T_s), else 0 (between instants). */
TAPMP_LINKAGE int tapmp_sample_index(double t, double t0, double T_s, double *k);

/* The controller's own clock: sample instants t0 + k T_s [s], the last one sampled (k_last,
 * valid if has_sample) and whether the one warning about skipped instants was given. */
typedef struct {
    double t0, T_s, k_last;
    int has_sample, warned;
} tapmp_clock;

/* What the controller does at the communication point t [s] (a host's doStep(t, h)): 1 to
 * sample, at the instant *k, *steps sample periods after the previous sample (1 for the
 * first); 0 to hold its outputs (t is between instants or sampled already). *missed is the
 * sample instant [s] that passed without a communication point on it, the first time a hold
 * finds one (the clock then counts its warning as given), else NaN. */
TAPMP_LINKAGE int tapmp_clock_at(tapmp_clock *c, double t, double *k, double *steps, double *missed);
/* Record the sample taken at instant k, `steps` periods after the previous one; 1 if it
 * skipped instants and the warning was not given yet (the clock now counts it as given). */
TAPMP_LINKAGE int tapmp_clock_sampled(tapmp_clock *c, double k, double steps);
/* The warning texts (at most `size` bytes with the terminating zero): the communication point t
 * [s] held past the sample instant `due` [s]; the sample at t taken `steps` periods after the
 * previous one. */
TAPMP_LINKAGE void tapmp_clock_missed_text(const tapmp_clock *c, double t, double due, char *text, size_t size);
TAPMP_LINKAGE void tapmp_clock_skipped_text(const tapmp_clock *c, double t, double steps, char *text, size_t size);

/* --- the hidden values of an FMU state (fmu_common/c/fmu_state.c checks a state whole before it
 * applies any of it) --- */
/* TAPMP_FORCE_CAP [N]: the largest force limit a setting may ask for (force_limit's declared maximum
 * in tapmp/interface.py), the cap of an integral's force when the controller has no limit. */
#define TAPMP_FORCE_CAP 1e9
/* A plant state s (X, Z, B, dX, dZ, dB) [m, m, rad, m/s, m/s, rad/s] with its sample count, and the
 * outputs X..dB the same FMU state holds (out, 6 values): every value finite, |B| < pi/2 (3: outside
 * the kinematic domain), the sample count a whole number in [0, 2^53], every output equal to the
 * state value it is computed from. Returned and reported as the settings checks are. */
TAPMP_LINKAGE int tapmp_plant_state_check(const double s[6], double sample, const double out[6], const char **name,
                                          double *value, const char **allowed);
/* A controller's loop state and clock at the communication point t [s], for its settings (p, g, law,
 * force_limit [N], the clock's T_s [s]): every value finite; the previous q [m] inside the kinematic
 * domain (3); the integral [m s] no larger than the force its term alone commands, |F_I| <= the force
 * limit (TAPMP_FORCE_CAP without one); t0 <= t; k_last a whole number with t0 + k_last T_s <= t
 * (within TAPMP_SAMPLE_TOLERANCE T_s). Returned and reported as the settings checks are. */
TAPMP_LINKAGE int tapmp_controller_state_check(const tapmp_params *p, const tapmp_gains *g, int law,
                                               double force_limit, const tapmp_controller_state *st,
                                               const tapmp_clock *c, double t, const char **name,
                                               double *value, const char **allowed);

/* --- trajectory (tapmp/trajectory.py) --- */
/* The move of `profile` (1, 2 or 3) from pose a to pose b (X, Z, B) with the limits per axis
 * v_max, a_max, j_max, every axis ending when the slowest does (move_plan). */
TAPMP_LINKAGE void tapmp_move_plan(int profile, const double a[3], const double b[3], const double v_max[3],
                                   const double a_max[3], const double j_max[3], tapmp_axis_plan plan[3]);
/* The reference of the settings s: the circle and sinusoid, or the move planned (tapmp_move_plan). */
TAPMP_LINKAGE void tapmp_trajectory_init(tapmp_trajectory *tp, const tapmp_trajectory_settings *s);
/* Desired pose and its first and second derivatives at t [s] (9 values). */
TAPMP_LINKAGE void tapmp_reference(double t, const tapmp_trajectory *tp, double ref[9]);

#endif
