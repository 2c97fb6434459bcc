/* Model data of the native TAPMP_Trajectory FMU (see trajectory.c). */
#ifndef TAPMP_TRAJECTORY_FMU_H
#define TAPMP_TRAJECTORY_FMU_H
#include "tapmp_model.h"

typedef struct {
    tapmp_trajectory tp;        /* the reference, with the move planned (tapmp_move_plan) */
    double L_1;
} ModelData;

#define MODEL_N_HIDDEN 0
#define MODEL_N_OUT 12              /* X_d..ddB_d (9), q1_d..q3_d */
#define MODEL_OUT_FIRST VR_X_d
#endif
