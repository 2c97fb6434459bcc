/* Model data of the native TAPMP_Controller FMU (see controller.c). */
#ifndef TAPMP_CONTROLLER_FMU_H
#define TAPMP_CONTROLLER_FMU_H
#include "tapmp_model.h"

typedef struct {
    tapmp_params p;
    tapmp_gains g;
    int law, velocity_source;
    double force_limit;
    tapmp_controller_state st;
    double T_s;        /* sample period [s] */
    double t0;         /* first sample instant [s]: the start time */
    double k_last;     /* index of the last sample instant t0 + k T_s (valid if has_sample) */
    int has_sample;    /* a sample was taken in Step Mode */
    int warned;        /* the warning about skipped sample instants was given */
} ModelData;

/* integral of c (3), previous q (3), has previous q, t0, k_last, has_sample, warned */
#define MODEL_N_HIDDEN 11
#define MODEL_N_OUT 12              /* F1..F3, u1..u3, e1..e3, es1..es3 */
#define MODEL_OUT_FIRST VR_F1
#endif
