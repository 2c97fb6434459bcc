/* Pass-through floor of a native TAPMP FMU, for benchmarks/bench_cosim.py: the model hooks
 * of instance.h doing nothing (doStep republishes the current outputs), so a loop of these
 * FMUs costs exactly the FMI calls, the instance layer and the master. Built in place of
 * fmu_plant/plant.c, fmu_controller/controller.c or trajectory.c. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "instance.h"

int model_validate(const tapmp_instance *inst, char *msg, size_t size) { (void)inst, (void)msg, (void)size; return 1; }
void model_setup(tapmp_instance *inst) { (void)inst; }
int model_initial_outputs(tapmp_instance *inst, char *msg, size_t size) { (void)inst, (void)msg, (void)size; return 1; }

int model_step(tapmp_instance *inst, double t, double h, double out[], char *msg, size_t size)
{
    (void)t, (void)h, (void)msg, (void)size;
    memcpy(out, inst->reals + MODEL_OUT_FIRST, MODEL_N_OUT * sizeof *out);
    return 1;
}

void model_get_hidden(const tapmp_instance *inst, double hidden[]) { (void)inst, (void)hidden; }
void model_set_hidden(tapmp_instance *inst, const double hidden[]) { (void)inst, (void)hidden; }
int model_check_hidden(const tapmp_instance *state, const double hidden[], char *msg, size_t size)
{
    (void)state, (void)hidden, (void)msg, (void)size;
    return 1;  /* no hidden state to check */
}

#ifdef MODEL_N_STATES
/* The plant's header offers Model Exchange: the floor model has no dynamics to integrate, so it
 * refuses Model Exchange at initialization (model_me_check) and holds no state. */
void model_me_get_states(const tapmp_instance *inst, double x[])
{
    (void)inst;
    for (int i = 0; i < MODEL_N_STATES; i++) x[i] = 0.0;
}
int model_me_set_states(tapmp_instance *inst, const double x[], char *msg, size_t size)
{
    (void)inst, (void)x, (void)msg, (void)size;
    return 1;
}
void model_me_derivatives(const tapmp_instance *inst, double dx[])
{
    (void)inst;
    for (int i = 0; i < MODEL_N_STATES; i++) dx[i] = 0.0;
}
double model_me_next_event_time(const tapmp_instance *inst) { (void)inst; return INFINITY; }
int model_me_check(const tapmp_instance *inst, char *msg, size_t size)
{
    (void)inst;
    snprintf(msg, size, "the benchmark's floor model has no dynamics for Model Exchange: use Co-Simulation");
    return 0;
}
#endif

#ifdef MODEL_HAS_EVENTS
/* The controller's header declares time events: the floor model schedules none, and an event
 * update republishes the current outputs. */
int model_next_event(const tapmp_instance *inst, double *time) { (void)inst, (void)time; return 0; }
int model_event_update(tapmp_instance *inst, double out[], char *msg, size_t size)
{
    (void)msg, (void)size;
    memcpy(out, inst->reals + MODEL_OUT_FIRST, MODEL_N_OUT * sizeof *out);
    return 1;
}
#endif
