/* libFuzzer target: one native FMI 2.0 FMU (its sources/all.c, included below) driven
 * through arbitrary sequences of FMI 2.0 calls, as fuzz_fmi3.c does for FMI 3.0:
 * instantiation with odd arguments, get/set with arbitrary value references and counts
 * (value arrays of exactly the count given), doStep with any t and h, FMU states got, set,
 * freed, serialized and deserialized from fuzzed bytes, also after their instance was
 * freed, reset, terminate and free twice; for the plant, Model Exchange instances and every Model
 * Exchange call with counts and pointers of any kind. Built by tests/fmu/test_fuzz.py with
 * clang -fsanitize=fuzzer,address,undefined. */
#include "all.c"
#include "fuzz_input.h"
#include "fuzz_fmi2_logger.h"

#define SLOTS 3
#define STATES 4

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    fuzz_input in = {data, size};
    fmi2Component slot[SLOTS] = {0};  /* kept after a free: a stale instance pointer */
    int live[SLOTS] = {0};
    fmi2FMUstate states[STATES] = {0};  /* kept after any free: stale state pointers */
    double t[SLOTS] = {0};
    char name[64], guid[128];
    const fmi2CallbackFunctions with_logger = {fuzz_logger, NULL, NULL, NULL, NULL};
    const fmi2CallbackFunctions without = {NULL, NULL, NULL, NULL, NULL};
    int ops = 0;
    while (in.n && ops++ < 200) {
        /* 255 is the Model Exchange calls: every other byte means the operation it meant before they
         * were added, so the kept inputs (regressions/) replay as they were found */
        unsigned code = fuzz_byte(&in), op = code == 255 ? 22 : code % 22, s = fuzz_byte(&in) % SLOTS, k = fuzz_byte(&in) % STATES;
        fmi2Component c = slot[s];
        switch (op) {
        case 0: {  /* instantiate, odd arguments included */
            const char *nm = fuzz_string(&in, name, sizeof name, "fuzz");
            const char *tok = fuzz_string(&in, guid, sizeof guid, INSTANTIATION_TOKEN);
            unsigned flags = fuzz_byte(&in);
            const fmi2CallbackFunctions *cb = flags & 1 ? NULL : (flags & 2 ? &without : &with_logger);
            if (live[s]) { fmi2FreeInstance(slot[s]); live[s] = 0; }
            slot[s] = fmi2Instantiate(nm, (flags & 4) ? fmi2ModelExchange : fmi2CoSimulation, tok, NULL, cb,
                                      (flags >> 3) & 1, (flags >> 4) & 1);
            live[s] = slot[s] != NULL;
            t[s] = 0.0;
            break;
        }
        case 1:  /* free, maybe a second time */
            fmi2FreeInstance(c);
            live[s] = 0;
            break;
        case 2: t[s] = fuzz_double(&in);
            fmi2SetupExperiment(c, fuzz_byte(&in) & 1, fuzz_double(&in), t[s], fuzz_byte(&in) & 1, fuzz_double(&in));
            break;
        case 3: fmi2EnterInitializationMode(c); break;
        case 4: fmi2ExitInitializationMode(c); break;
        case 5: case 6: case 7: case 8: {  /* Real / Integer get and set */
            size_t n = fuzz_count(&in);
            fmi2ValueReference *vr = malloc((n ? n : 1) * sizeof *vr);
            for (size_t i = 0; i < n; i++) vr[i] = fuzz_vr(&in, N_VARS);
            if (op < 7) {
                fmi2Real *v = malloc((n ? n : 1) * sizeof *v);
                for (size_t i = 0; i < n; i++) v[i] = fuzz_double(&in);
                if (op == 5) fmi2SetReal(c, vr, n, v);
                else fmi2GetReal(c, vr, n, v);
                free(v);
            } else {
                fmi2Integer *v = malloc((n ? n : 1) * sizeof *v);
                for (size_t i = 0; i < n; i++) v[i] = (fmi2Integer)fuzz_u32(&in);
                if (op == 7) fmi2SetInteger(c, vr, n, v);
                else fmi2GetInteger(c, vr, n, v);
                free(v);
            }
            free(vr);
            break;
        }
        case 9: case 10: {  /* doStep: continuing the last step, or any t */
            double h = fuzz_double(&in), at = op == 9 ? t[s] : fuzz_double(&in);
            if (fmi2DoStep(c, at, h, fuzz_byte(&in) & 1) == fmi2OK) t[s] = at + h;
            break;
        }
        case 11: fmi2GetFMUstate(c, fuzz_byte(&in) & 1 ? &states[k] : NULL); break;
        case 12: fmi2SetFMUstate(c, states[k]); break;
        case 13: fmi2FreeFMUstate(c, fuzz_byte(&in) & 1 ? &states[k] : NULL); break;
        case 14: {  /* serialize into a buffer of the size given */
            size_t need = 0, n = fuzz_byte(&in) & 1 ? 0 : (size_t)fuzz_u32(&in) % 200000;
            if (fmi2SerializedFMUstateSize(c, states[k], &need) == fmi2OK && fuzz_byte(&in) & 1) n = need;
            fmi2Byte *bytes = malloc(n ? n : 1);
            if (fmi2SerializeFMUstate(c, states[k], bytes, n) == fmi2OK && n && (fuzz_byte(&in) & 1)) {
                size_t at = fuzz_u32(&in) % n;  /* one byte changed, then read back */
                bytes[at] ^= (fmi2Byte)(fuzz_byte(&in) | 1);
                fmi2DeSerializeFMUstate(c, bytes, n, &states[(k + 1) % STATES]);
            }
            free(bytes);
            break;
        }
        case 15: {  /* deserialize the fuzzer's own bytes */
            size_t n = fuzz_byte(&in) & 1 ? in.n : fuzz_count(&in);
            if (n > in.n) n = in.n;
            fmi2Byte *bytes = malloc(n ? n : 1);
            memcpy(bytes, in.p, n);
            fmi2DeSerializeFMUstate(c, n || (fuzz_byte(&in) & 1) ? bytes : NULL, n,
                                    fuzz_byte(&in) & 1 ? &states[k] : NULL);
            free(bytes);
            break;
        }
        case 16: fmi2Reset(c); t[s] = 0.0; break;
        case 17: fmi2Terminate(c); break;
        case 18: fmi2SetDebugLogging(c, fuzz_byte(&in) & 1, 0, NULL); break;
        case 19: {  /* types this FMU has none of, status queries, derivatives */
            fmi2ValueReference vr = fuzz_vr(&in, N_VARS);
            fmi2Boolean b = 0;
            fmi2Real x = 0.0;
            fmi2Integer order = 1;
            size_t n = fuzz_byte(&in) & 1;
            fmi2GetBoolean(c, &vr, n, &b);
            fmi2SetString(c, &vr, 0, NULL);
            fmi2GetDirectionalDerivative(c, &vr, n, &vr, n, &x, &x);
            fmi2SetRealInputDerivatives(c, &vr, n, &order, &x);
            fmi2GetRealStatus(c, (fmi2StatusKind)(fuzz_byte(&in) % 4), &x);
            fmi2GetBooleanStatus(c, (fmi2StatusKind)(fuzz_byte(&in) % 4), &b);
            fmi2CancelStep(c);
            break;
        }
        case 20: {  /* a state of one instance handed to another */
            fmi2Component d = slot[(s + 1) % SLOTS];
            fmi2SetFMUstate(d, states[k]);
            size_t need;
            fmi2SerializedFMUstateSize(d, states[k], &need);
            break;
        }
#ifdef MODEL_N_STATES
        case 22: {  /* Model Exchange: arrays of exactly the count given, pointers maybe NULL */
            size_t n = fuzz_count(&in);
            fmi2Real *x = malloc((n ? n : 1) * sizeof *x);
            for (size_t i = 0; i < n; i++) x[i] = fuzz_double(&in);
            fmi2Real *arg = fuzz_byte(&in) & 1 ? x : NULL;
            fmi2Boolean b[2];
            fmi2EventInfo info;
            switch (fuzz_byte(&in) % 10) {
            case 0: fmi2SetTime(c, fuzz_double(&in)); break;
            case 1: fmi2SetContinuousStates(c, arg, n); break;
            case 2: fmi2GetContinuousStates(c, arg, n); break;
            case 3: fmi2GetDerivatives(c, arg, n); break;
            case 4: fmi2GetEventIndicators(c, arg, n); break;
            case 5: fmi2GetNominalsOfContinuousStates(c, arg, n); break;
            case 6: fmi2EnterEventMode(c); break;
            case 7: fmi2NewDiscreteStates(c, fuzz_byte(&in) & 1 ? &info : NULL); break;
            case 8: fmi2EnterContinuousTimeMode(c); break;
            default: fmi2CompletedIntegratorStep(c, fuzz_byte(&in) & 1, fuzz_byte(&in) & 1 ? b : NULL, b + 1); break;
            }
            free(x);
            break;
        }
#endif
        default: {
            fmi2ValueReference vr[2] = {N_VARS, fuzz_vr(&in, N_VARS)};
            fmi2Real v[2];
            fmi2GetReal(c, vr, 2, v);
            break;
        }
        }
    }
    for (int s = 0; s < SLOTS; s++)  /* the instances free whatever states they still hold */
        if (live[s]) fmi2FreeInstance(slot[s]);
    return 0;
}
