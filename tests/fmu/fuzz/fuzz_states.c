/* libFuzzer target: serialized FMU states of one native FMI 2.0 FMU (its sources/all.c, included
 * below), seeded by tests/fmu/test_fuzz.py with real states of the model and mutated: each input
 * is the bytes a host hands to fmi2DeSerializeFMUstate. A state the runtime accepts is set and
 * stepped STEPS times from its own time; after the set and after every step that returns OK or
 * Warning every output must be finite and inside its declared min/max (else abort(): a finding).
 * The plant's bytes are also handed to a Model Exchange instance: a state it accepts must lie inside the
 * plant's Model Exchange domain (plant.c, me_limits), and a few explicit Euler steps through
 * fmi2GetDerivatives, fmi2SetTime and fmi2SetContinuousStates follow, every derivative returned with
 * OK finite, every state and output accepted with OK checked as above.
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

#ifdef MODEL_N_STATES
/* The Model Exchange state c holds: finite and inside the domain of the model it has built, else a finding. */
static void check_me_state(fmi2Component c, const char *when)
{
    const tapmp_instance *inst = (const tapmp_instance *)c;
    double x[MODEL_N_STATES], lim[6];
    if (fmi2GetContinuousStates(c, x, MODEL_N_STATES) > fmi2Warning) return;
    me_limits(&inst->m.plant.p, &inst->m.plant.c, lim);
    for (int i = 0; i < MODEL_N_STATES; i++)
        if (!(isfinite(x[i]) && (i == 2 ? fabs(x[i]) < lim[i] : fabs(x[i]) <= lim[i]))) {
            fprintf(stderr, "fuzz_states: Model Exchange state %d = %g %s with an OK status: allowed is |value| <= "
                    "%g\n", i, x[i], when, lim[i]);
            abort();
        }
}

static void drive_model_exchange(const uint8_t *data, size_t size, const fmi2CallbackFunctions *callbacks)
{
    fmi2Component c = fmi2Instantiate("fuzz-me", fmi2ModelExchange, INSTANTIATION_TOKEN, NULL, callbacks, fmi2False,
                                      fmi2False);
    if (!c) abort();
    fmi2FMUstate state = NULL;
    if (fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) != fmi2OK ||
        fmi2EnterInitializationMode(c) != fmi2OK || fmi2ExitInitializationMode(c) != fmi2OK)
        abort();
    if (fmi2DeSerializeFMUstate(c, (const fmi2Byte *)data, size, &state) == fmi2OK &&
        fmi2SetFMUstate(c, state) == fmi2OK) {
        check_outputs(c, "after fmi2SetFMUstate (Model Exchange)");
        check_me_state(c, "after fmi2SetFMUstate");
        const tapmp_instance *inst = (const tapmp_instance *)c;
        if (inst->me_continuous || fmi2EnterContinuousTimeMode(c) == fmi2OK) {
            for (int k = 0; k < STEPS; k++) {
                double x[MODEL_N_STATES], dx[MODEL_N_STATES];
                if (fmi2GetContinuousStates(c, x, MODEL_N_STATES) > fmi2Warning ||
                    fmi2GetDerivatives(c, dx, MODEL_N_STATES) > fmi2Warning)
                    break;
                for (int i = 0; i < MODEL_N_STATES; i++) {
                    if (!isfinite(dx[i])) {
                        fprintf(stderr, "fuzz_states: derivative %d = %g with an OK status\n", i, dx[i]);
                        abort();
                    }
                    x[i] += 1e-4 * dx[i];
                }
                if (fmi2SetTime(c, inst->time + 1e-4) > fmi2Warning ||
                    fmi2SetContinuousStates(c, x, MODEL_N_STATES) > fmi2Warning)
                    break;
                check_outputs(c, "after fmi2SetContinuousStates");
                check_me_state(c, "after fmi2SetContinuousStates");
                fmi2Boolean event = fmi2False, terminate = fmi2False;
                if (fmi2CompletedIntegratorStep(c, fmi2True, &event, &terminate) > fmi2Warning) break;
            }
        }
    }
    fmi2FreeInstance(c);  /* frees the state too */
}
#endif

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
#ifdef MODEL_N_STATES
    drive_model_exchange(data, size, &callbacks);
#endif
    return 0;
}
