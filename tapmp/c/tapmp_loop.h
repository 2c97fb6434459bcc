/* The FMI-free closed loop in C: trajectory -> controller -> plant stepped N macro steps in one
 * call, the same calls in the same order as tapmp.closed_loop.simulate (the readable Python
 * reference), so both give the same doubles. Python runs it through cffi (tapmp/cmodel.py reads
 * these declarations from this file, as it reads tapmp_model.h). */
#ifndef TAPMP_LOOP_H
#define TAPMP_LOOP_H

#include "tapmp_model.h"

/* Doubles per communication point written by tapmp_loop_run, in this order: t [s], the reference
 * (X_d, Z_d, B_d and their first and second derivatives, 9), q_d = IK(X_d, Z_d, B_d) [m] (3), the
 * command F [N] (3), the measured positions q [m] (3), the true positions [m] (3), the plant state
 * (X, Z, B, dX, dZ, dB) (6). */
#define TAPMP_LOOP_COLUMNS 28

/* What stopped tapmp_loop_run before its last step (its return value is the steps completed). */
enum {
    TAPMP_LOOP_OK = 0,
    TAPMP_LOOP_CONTROLLER_INPUT = 1,   /* an input of the controller's sample is not finite */
    TAPMP_LOOP_CONTROLLER_DOMAIN = 2,  /* the measured positions left the domain of Eq. 1 */
    TAPMP_LOOP_FORCE = 3,              /* the force the plant is given is not finite */
    TAPMP_LOOP_PLANT_DOMAIN = 4        /* the plant's state left |B| < pi/2 or stopped being finite */
};

/* The values that carry from one communication point to the next: the command F held [N] and
 * the reference, measured positions [m] and motor rates [m/s] at the current point. */
typedef struct {
    double F[3], ref[9], q[3], dq[3];
} tapmp_loop_point;

/* Macro steps k = k0 .. k0 + n - 1 of size h [s] from t0 [s] (t = t0 + k h): the controller's
 * clock decides sample or hold (tapmp_clock_at), a sample runs tapmp_controller_sample over
 * `steps` x T_s, the plant steps with the new command (gauss_seidel = 1) or the one held before
 * (0), the reference is taken at t + h and the plant's outputs read. After each step its row
 * (TAPMP_LOOP_COLUMNS doubles, q_d with the trajectory's platform width L1_ref [m]) goes to
 * rows. The plant, the controller's state and clock and *pt are updated in place. Returns the
 * steps completed; if fewer than n, *error says why and everything is as it was before the
 * failing step (so the caller can replay that step and report it). */
TAPMP_LINKAGE long tapmp_loop_run(tapmp_plant *pl, const tapmp_params *p, const tapmp_gains *g, int law,
                                  int velocity_source, double force_limit, int anti_windup,
                                  double anti_windup_time, tapmp_controller_state *st,
                                  tapmp_clock *clock, const tapmp_trajectory *tp, double L1_ref, double t0,
                                  long k0, long n, double h, int gauss_seidel, tapmp_loop_point *pt,
                                  double *rows, int *error);

#endif
