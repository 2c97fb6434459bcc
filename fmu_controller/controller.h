/* Model data of the native TAPMP_Controller FMU (see controller.c). */
#ifndef TAPMP_CONTROLLER_FMU_H
#define TAPMP_CONTROLLER_FMU_H
#include "tapmp_model.h"

typedef struct {
    tapmp_controller_settings s;  /* the parameters (MODEL_READ_SETTINGS) */
    tapmp_controller_state st;
    tapmp_clock clock; /* the sample instants t0 + k T_s, t0 the start time */
} ModelData;

/* integral of c (3), previous q (3), has previous q, t0, k_last, has_sample, warned */
#define MODEL_N_HIDDEN 11
#define MODEL_N_OUT 12              /* F1..F3, u1..u3, e1..e3, es1..es3 */
#define MODEL_OUT_FIRST VR_F1
/* FMI 3.0 with eventModeUsed: every sample instant t0 + k T_s is a time event (controller.c) */
#define MODEL_HAS_EVENTS
/* The clocked controller (TAPMP_ControllerClocked; its model_vars.h defines TAPMP_CLOCKED): the sample
 * instants are the ticks of a periodic input clock of interval T_s that the host activates, not time
 * events of the FMU's own (controller.c) */
#ifdef TAPMP_CLOCKED
#define MODEL_CLOCK
#define MODEL_CLOCK_VR (N_VARS + 1) /* after the independent variable time (N_VARS) */
#define MODEL_CLOCK_NAME "sample_clock"
#endif
#endif
