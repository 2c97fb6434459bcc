/* libFuzzer target: serialized FMU states of one native FMI 2.0 FMU (its sources/all.c, included
 * below), seeded by tests/fmu/test_fuzz.py with real states of the model and mutated: each input
 * is the bytes a host hands to fmi2DeSerializeFMUstate. A state the runtime accepts is set and
 * stepped STEPS times from its own time; after the set and after every step that returns OK or
 * Warning every output must be finite and inside its declared min/max (else abort(): a finding).
 * A call that returns Discard, Error or Fatal ends the run: refusing is always allowed. */
#include "all.c"
#include "fuzz_input.h"
#include "fuzz_fmi2_logger.h"

#define STEPS 5

/* Every output finite and inside [min, max] of the variable table, else a finding. */
static void check_outputs(fmi2Component c, const char *when)
{
    for (unsigned vr = 0; vr < N_VARS; vr++) {
        if (VARS[vr].causality != 'o' || VARS[vr].type != 'R') continue;
        fmi2Real x = NAN;
        if (fmi2GetReal(c, &vr, 1, &x) > fmi2Warning) return;
        if (!(isfinite(x) && x >= VARS[vr].min && x <= VARS[vr].max)) {
            fprintf(stderr, "fuzz_states: output %s = %g %s with an OK status: allowed is a finite number in "
                    "[%g, %g]\n", VARS[vr].name, x, when, VARS[vr].min, VARS[vr].max);
            abort();
        }
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    const fmi2CallbackFunctions callbacks = {fuzz_logger, NULL, NULL, NULL, NULL};
    fmi2Component c = fmi2Instantiate("fuzz", fmi2CoSimulation, INSTANTIATION_TOKEN, NULL, &callbacks, fmi2False,
                                      fmi2False);
    if (!c) abort();  /* a valid instantiation never fails */
    fmi2FMUstate state = NULL;
    if (fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) != fmi2OK ||
        fmi2EnterInitializationMode(c) != fmi2OK || fmi2ExitInitializationMode(c) != fmi2OK)
        abort();
    if (fmi2DeSerializeFMUstate(c, (const fmi2Byte *)data, size, &state) == fmi2OK &&
        fmi2SetFMUstate(c, state) == fmi2OK) {
        check_outputs(c, "after fmi2SetFMUstate");
        for (int k = 0; k < STEPS; k++) {
            double t = ((tapmp_instance *)c)->time;  /* the state's time: the step that continues it */
            if (fmi2DoStep(c, t, 1e-4, fmi2True) > fmi2Warning) break;
            check_outputs(c, "after fmi2DoStep");
        }
    }
    fmi2FreeInstance(c);  /* frees the state too */
    return 0;
}
