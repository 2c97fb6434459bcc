/* Model data of the native TAPMP_Trajectory FMU (see trajectory.c). */
#ifndef TAPMP_TRAJECTORY_FMU_H
#define TAPMP_TRAJECTORY_FMU_H
#include "tapmp_model.h"

/* One axis of a point-to-point move (tapmp.trajectory.AxisPlan): from q0 to q1, sign s,
 * distance D, S-curve phase times Tj, Ta, Tv and end T [s], jerk J, peak acceleration alim,
 * peak velocity vlim. */
typedef struct {
    double q0, q1, s, D, Tj, Ta, Tv, T, J, alim, vlim;
} tapmp_axis_plan;

typedef struct {
    tapmp_trajectory tp;
    double L_1;
    int profile;                /* 0 circle and sinusoid, 1 step, 2 ramp, 3 S-curve */
    double t_move;              /* start of the move [s] */
    tapmp_axis_plan axis[3];    /* X, Z, B */
} ModelData;

#define MODEL_N_HIDDEN 0
#define MODEL_N_OUT 12              /* X_d..ddB_d (9), q1_d..q3_d */
#define MODEL_OUT_FIRST VR_X_d
#endif
