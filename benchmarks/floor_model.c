/* Pass-through floor of a native TAPMP FMU, for benchmarks/bench_cosim.py: the model hooks
 * of instance.h doing nothing (doStep republishes the current outputs), so a loop of these
 * FMUs costs exactly the FMI calls, the instance layer and the master. Built in place of
 * fmu_plant/plant.c, fmu_controller/controller.c or trajectory.c. */
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
