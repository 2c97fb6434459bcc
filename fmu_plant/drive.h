/* Model data of the native TAPMP_Drive FMU (see drive.c): per motor a computation delay, a current
 * (force) limit, a second-order current loop and a force-constant error between controller and plant. */
#ifndef TAPMP_DRIVE_FMU_H
#define TAPMP_DRIVE_FMU_H

#define DRIVE_MAX_DELAY 3          /* the largest delay_samples (tapmp/interface.py RANGES) */

typedef struct {
    int delay;                      /* delay_samples: communication steps from command to current loop */
    double wn, zeta;                /* natural frequency [rad/s] (0: ideal loop) and damping of the loop */
    double gain[3];                 /* 1 + force_constant_error_i */
    double limit;                   /* force_limit [N] (0: no limit) */
    double past[3][DRIVE_MAX_DELAY];  /* the commands of the last steps, newest first [N] */
    double x[3][2];                 /* the loop's state per motor: force y [N] and dy/dt / wn [N] */
    double h;                       /* the step [s] phi is for (0: none yet) */
    double phi[4][4];               /* exp(M h) of the loop with its input held and its integral (drive.c) */
} ModelData;

#define MODEL_N_HIDDEN 15           /* per motor: the DRIVE_MAX_DELAY past commands and the loop's 2 states */
#define MODEL_N_OUT 3               /* F1..F3 */
#define MODEL_OUT_FIRST VR_F1
#endif
