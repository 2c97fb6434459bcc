/* Model data of the native TAPMP_Plant FMU (see plant.c). */
#ifndef TAPMP_PLANT_FMU_H
#define TAPMP_PLANT_FMU_H
#include "tapmp_model.h"

typedef struct {
    tapmp_plant plant;
} ModelData;

#define MODEL_N_HIDDEN 9            /* the state X, Z, B, dX, dZ, dB, the sample count, z_f, dz_f */
#define MODEL_N_OUT 15              /* q1..q3, q1_true..q3_true, dq1..dq3, X, Z, B, dX, dZ, dB */
#define MODEL_OUT_FIRST VR_q1
/* Model Exchange: the continuous states X, Z, B, dX, dZ, dB (fmi2_api.c, plant.c's model_me_* hooks) */
#define MODEL_N_STATES 6
#endif
