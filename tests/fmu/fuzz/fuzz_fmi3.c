/* libFuzzer target: one native FMI 3.0 FMU (its sources/all.c, included below, so the
 * target is the FMU's own single translation unit) driven through arbitrary sequences of
 * FMI 3.0 calls: instantiation with odd arguments, get/set with arbitrary value references
 * and counts (value arrays of exactly the count given, so a read or write past them is
 * caught), doStep with any t and h, FMU states got, set, freed, serialized and deserialized
 * from fuzzed bytes, also after their instance was freed, reset, terminate and free twice;
 * Model Exchange instances (the plant's; the others refuse them) and every Model Exchange call with
 * counts and pointers of any kind, and the clock calls (the clocked controller's input clock).
 *
 * The oracle (abort(), so libFuzzer reports a crash): a call that returns OK or Warning leaves every
 * Float64 output finite and inside its declared [min, max]; a Model Exchange state or derivative
 * returned with OK is finite and the state inside the plant's Model Exchange domain (plant.c,
 * me_limits); the clocked controller samples only in an event in which the host ticked its clock
 * (an update without a tick leaves the outputs bit for bit), GetClock never reports a tick the host
 * did not set in this event, and no event is left with a tick it did not handle.
 * Built by tests/fmu/test_fuzz.py with clang -fsanitize=fuzzer,address,undefined. */
#include "all.c"
#include "fuzz_input.h"

#define SLOTS 3
#define STATES 4

static void finding(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    fprintf(stderr, "fuzz_fmi3 oracle: ");
    vfprintf(stderr, fmt, ap);
    fprintf(stderr, "\n");
    va_end(ap);
    abort();
}

/* Every Float64 output of c finite and inside its declared [min, max] after `call` returned OK or Warning. */
static void check_outputs(fmi3Instance c, fmi3Status status, const char *call)
{
    if (status > fmi3Warning) return;
    for (unsigned vr = 0; vr < N_VARS; vr++) {
        if (VARS[vr].causality != 'o' || VARS[vr].type != 'R') continue;
        fmi3Float64 x = NAN;
        if (fmi3GetFloat64(c, &vr, 1, &x, 1) > fmi3Warning) return;
        if (!(isfinite(x) && x >= VARS[vr].min && x <= VARS[vr].max))
            finding("output %s = %g after %s returned %d: allowed is a finite number in [%g, %g]", VARS[vr].name, x,
                    call, (int)status, VARS[vr].min, VARS[vr].max);
    }
}

/* The outputs now (bit for bit comparable), 0 if they cannot be read. */
static int outputs_now(fmi3Instance c, double out[N_VARS])
{
    for (unsigned vr = 0; vr < N_VARS; vr++) {
        out[vr] = 0.0;
        if (VARS[vr].causality == 'o' && VARS[vr].type == 'R' && fmi3GetFloat64(c, &vr, 1, &out[vr], 1) > fmi3Warning)
            return 0;
    }
    return 1;
}

#ifdef MODEL_N_STATES
/* A Model Exchange state (x) or derivative (x = NULL: dx) returned with OK: finite, the state inside the
 * domain the plant states for Model Exchange (me_limits of the model it has built). */
static void check_me(fmi3Instance c, const double *x, const double *dx, size_t n, const char *call)
{
    const tapmp_instance *inst = (const tapmp_instance *)c;
    double lim[6];
    me_limits(&inst->m.plant.p, &inst->m.plant.c, lim);
    for (size_t i = 0; i < n && i < 6; i++) {
        double v = x ? x[i] : dx[i];
        if (!isfinite(v)) finding("%s returned OK with value %zu = %g: allowed is a finite number", call, i, v);
        if (x && !(i == 2 ? fabs(v) < lim[i] : fabs(v) <= lim[i]))
            finding("%s returned OK with state %zu = %g: allowed is |value| <= %g", call, i, v, lim[i]);
    }
}
#endif

static void fuzz_logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    char buf[4096];
    (void)env, (void)status;
    snprintf(buf, sizeof buf, "%s %s", category ? category : "", message ? message : "");
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    fuzz_input in = {data, size};
    fmi3Instance slot[SLOTS] = {0};  /* kept after a free: a stale instance pointer */
    int live[SLOTS] = {0};
    fmi3FMUState states[STATES] = {0};  /* kept after any free: stale state pointers */
    double t[SLOTS] = {0};
    int ticked[SLOTS] = {0};  /* the host set the clock in this event: 1, not: 0, not known (a state set): -1 */
    char name[64], token[128];
    int ops = 0;
    while (in.n && ops++ < 200) {
        /* 255 is the Model Exchange calls: every other byte means the operation it meant before they
         * were added, so the kept inputs (regressions/) replay as they were found */
        unsigned code = fuzz_byte(&in), op = code == 255 ? 22 : code % 22, s = fuzz_byte(&in) % SLOTS, k = fuzz_byte(&in) % STATES;
        fmi3Instance c = slot[s];
        switch (op) {
        case 0: {  /* instantiate, odd arguments included */
            const char *nm = fuzz_string(&in, name, sizeof name, "fuzz");
            const char *tok = fuzz_string(&in, token, sizeof token, INSTANTIATION_TOKEN);
            unsigned flags = fuzz_byte(&in);
            if (live[s]) { fmi3FreeInstance(slot[s]); live[s] = 0; }
            slot[s] = fmi3InstantiateCoSimulation(nm, tok, NULL, flags & 1, (flags >> 1) & 1, (flags >> 2) & 1,
                                                  (flags >> 3) & 1, NULL, 0, NULL,
                                                  (flags >> 4) & 1 ? NULL : fuzz_logger, NULL);
            live[s] = slot[s] != NULL;
            t[s] = 0.0;
            ticked[s] = 0;
            break;
        }
        case 1:  /* free, maybe a second time */
            fmi3FreeInstance(c);
            live[s] = 0;
            break;
        case 2: t[s] = fuzz_double(&in);
            fmi3EnterInitializationMode(c, fuzz_byte(&in) & 1, fuzz_double(&in), t[s], fuzz_byte(&in) & 1,
                                        fuzz_double(&in));
            break;
        case 3: check_outputs(c, fmi3ExitInitializationMode(c), "fmi3ExitInitializationMode"); break;
        case 4: case 5: case 6: case 7: {  /* Float64 / Int32 get and set */
            size_t n = fuzz_count(&in), nv = fuzz_count(&in);
            if (fuzz_byte(&in) & 1) nv = n;
            fmi3ValueReference *vr = malloc((n ? n : 1) * sizeof *vr);
            for (size_t i = 0; i < n; i++) vr[i] = fuzz_vr(&in, N_VARS);
            if (op < 6) {
                fmi3Float64 *v = malloc((nv ? nv : 1) * sizeof *v);
                for (size_t i = 0; i < nv; i++) v[i] = fuzz_double(&in);
                if (op == 4) fmi3SetFloat64(c, vr, n, v, nv);
                else fmi3GetFloat64(c, vr, n, v, nv);
                free(v);
            } else {
                fmi3Int32 *v = malloc((nv ? nv : 1) * sizeof *v);
                for (size_t i = 0; i < nv; i++) v[i] = (fmi3Int32)fuzz_u32(&in);
                if (op == 6) fmi3SetInt32(c, vr, n, v, nv);
                else fmi3GetInt32(c, vr, n, v, nv);
                free(v);
            }
            free(vr);
            break;
        }
        case 8: case 9: {  /* doStep: continuing the last step, or any t */
            double h = fuzz_double(&in), at = op == 8 ? t[s] : fuzz_double(&in);
            fmi3Boolean event, terminate, early;
            fmi3Float64 last = 0.0;
            fmi3Status status = fmi3DoStep(c, at, h, fuzz_byte(&in) & 1, &event, &terminate, &early, &last);
            if (status == fmi3OK) t[s] = last;
            check_outputs(c, status, "fmi3DoStep");
            break;
        }
        case 10: fmi3GetFMUState(c, fuzz_byte(&in) & 1 ? &states[k] : NULL); break;
        case 11:
            check_outputs(c, fmi3SetFMUState(c, states[k]), "fmi3SetFMUState");
            ticked[s] = -1;  /* the state's tick, if any */
            break;
        case 12: fmi3FreeFMUState(c, fuzz_byte(&in) & 1 ? &states[k] : NULL); break;
        case 13: {  /* serialize into a buffer of the size given */
            size_t need = 0, n = fuzz_byte(&in) & 1 ? 0 : (size_t)fuzz_u32(&in) % 200000;
            if (fmi3SerializedFMUStateSize(c, states[k], &need) == fmi3OK && fuzz_byte(&in) & 1) n = need;
            fmi3Byte *bytes = malloc(n ? n : 1);
            if (fmi3SerializeFMUState(c, states[k], bytes, n) == fmi3OK && n && (fuzz_byte(&in) & 1)) {
                size_t at = fuzz_u32(&in) % n;  /* one byte changed, then read back */
                bytes[at] ^= (fmi3Byte)(fuzz_byte(&in) | 1);
                fmi3DeserializeFMUState(c, bytes, n, &states[(k + 1) % STATES]);
            }
            free(bytes);
            break;
        }
        case 14: {  /* deserialize the fuzzer's own bytes */
            size_t n = fuzz_byte(&in) & 1 ? in.n : fuzz_count(&in);
            if (n > in.n) n = in.n;
            fmi3Byte *bytes = malloc(n ? n : 1);
            memcpy(bytes, in.p, n);
            fmi3DeserializeFMUState(c, n || (fuzz_byte(&in) & 1) ? bytes : NULL, n,
                                    fuzz_byte(&in) & 1 ? &states[k] : NULL);
            free(bytes);
            break;
        }
        case 15: fmi3Reset(c); t[s] = 0.0; ticked[s] = 0; break;
        case 16: fmi3Terminate(c); ticked[s] = 0; break;
        case 17: fmi3SetDebugLogging(c, fuzz_byte(&in) & 1, 0, NULL); break;
        case 18: {  /* types this FMU has none of, and interfaces it does not provide */
            fmi3ValueReference vr = fuzz_vr(&in, N_VARS);
            fmi3Boolean b = 0;
            fmi3Float64 x = 0.0;
            size_t n = fuzz_byte(&in) & 1;
            fmi3GetBoolean(c, &vr, n, &b, n);
            fmi3SetFloat32(c, &vr, 0, NULL, 0);
            fmi3GetDirectionalDerivative(c, &vr, n, &vr, n, &x, n, &x, n);
            fmi3EnterEventMode(c);  /* in an event already: the same event, its tick stays */
            fmi3GetClock(c, &vr, n, &b);
            break;
        }
        case 19: {  /* the other instantiation functions; a Model Exchange instance (the plant's) stays */
            const char *tok = fuzz_string(&in, token, sizeof token, INSTANTIATION_TOKEN);
            int me = fuzz_byte(&in) & 1;
            fmi3Instance other = me
                ? fmi3InstantiateModelExchange("me", tok, NULL, 0, 0, NULL, fuzz_logger)
                : fmi3InstantiateScheduledExecution("se", tok, NULL, 0, 0, NULL, fuzz_logger, NULL, NULL, NULL);
            if (me && other) {
                if (live[s]) fmi3FreeInstance(slot[s]);
                slot[s] = other;
                live[s] = 1;
                t[s] = 0.0;
                ticked[s] = 0;
            } else
                fmi3FreeInstance(other);
            break;
        }
        case 20: {  /* a state of one instance handed to another */
            fmi3Instance d = slot[(s + 1) % SLOTS];
            fmi3SetFMUState(d, states[k]);
            size_t need;
            fmi3SerializedFMUStateSize(d, states[k], &need);
            break;
        }
        case 22: {  /* Model Exchange and events: arrays of exactly the count given, pointers maybe NULL */
            size_t n = fuzz_count(&in), count = 0;
            fmi3Float64 *x = malloc((n ? n : 1) * sizeof *x);
            for (size_t i = 0; i < n; i++) x[i] = fuzz_double(&in);
            fmi3Float64 *arg = fuzz_byte(&in) & 1 ? x : NULL;
            fmi3Boolean b[6];
            fmi3Float64 next = 0.0;
            fmi3Status status;
            switch (fuzz_byte(&in) % 15) {
            case 0: check_outputs(c, fmi3SetTime(c, fuzz_double(&in)), "fmi3SetTime"); break;
            case 1:
                status = fmi3SetContinuousStates(c, arg, n);
                check_outputs(c, status, "fmi3SetContinuousStates");
#ifdef MODEL_N_STATES
                if (status == fmi3OK) check_me(c, arg, NULL, n, "fmi3SetContinuousStates");
#endif
                break;
            case 2:
                status = fmi3GetContinuousStates(c, arg, n);
#ifdef MODEL_N_STATES
                if (status == fmi3OK) check_me(c, arg, NULL, n, "fmi3GetContinuousStates");
#endif
                break;
            case 3:
                status = fmi3GetContinuousStateDerivatives(c, arg, n);
#ifdef MODEL_N_STATES
                if (status == fmi3OK) check_me(c, NULL, arg, n, "fmi3GetContinuousStateDerivatives");
#endif
                break;
            case 4: fmi3GetEventIndicators(c, arg, n); break;
            case 5: fmi3GetNominalsOfContinuousStates(c, arg, n); break;
            case 6: fmi3EnterEventMode(c); break;
            case 7: {
                double before[N_VARS], after[N_VARS];
                int known = ticked[s] == 0 && outputs_now(c, before);
                status = fmi3UpdateDiscreteStates(c, b, b + 1, b + 2, b + 3, b + 4, fuzz_byte(&in) & 1 ? &next : NULL);
                check_outputs(c, status, "fmi3UpdateDiscreteStates");
#ifdef MODEL_CLOCK
                /* no tick in this event: the clocked controller holds its command */
                if (status <= fmi3Warning && known && outputs_now(c, after) && memcmp(before, after, sizeof before))
                    finding("fmi3UpdateDiscreteStates returned %d and changed the outputs in an event without a tick",
                            (int)status);
                if (status <= fmi3Warning) ticked[s] = 0;
#else
                (void)known, (void)after;
#endif
                break;
            }
            case 8: fmi3EnterContinuousTimeMode(c); break;
            case 9: fmi3CompletedIntegratorStep(c, fuzz_byte(&in) & 1, fuzz_byte(&in) & 1 ? b : NULL, b + 1); break;
            case 10: fmi3GetNumberOfContinuousStates(c, fuzz_byte(&in) & 1 ? &count : NULL); break;
            case 11: fmi3GetNumberOfEventIndicators(c, fuzz_byte(&in) & 1 ? &count : NULL); break;
            case 12: {  /* tick (or not) the clock, or another value reference */
                fmi3ValueReference vr = fuzz_byte(&in) & 1 ? N_VARS + 1 : fuzz_vr(&in, N_VARS + 2);
                fmi3Clock tick = fuzz_byte(&in) & 1;
                size_t m = fuzz_byte(&in) % 3 ? 1 : 0;
                /* an accepted inactive value takes a tick back (the FMU clears it): none is then pending */
                if (fmi3SetClock(c, &vr, m, &tick) == fmi3OK && m && ticked[s] >= 0) ticked[s] = tick ? 1 : 0;
                break;
            }
            case 13: {
                fmi3ValueReference vr = N_VARS + 1;
                fmi3Clock active = 0;
#ifdef MODEL_CLOCK
                if (fmi3GetClock(c, &vr, 1, &active) == fmi3OK && active && ticked[s] == 0)
                    finding("fmi3GetClock reported a tick the host did not set in this event");
#else
                fmi3GetClock(c, &vr, 1, &active);
#endif
                break;
            }
            default:
                status = fmi3EnterStepMode(c);
#ifdef MODEL_CLOCK
                if (status <= fmi3Warning && ticked[s] > 0)
                    finding("fmi3EnterStepMode returned %d with the tick of this event not handled", (int)status);
#endif
                ticked[s] = 0;  /* left the event, or refused and the tick dropped (or none was set) */
                break;
            }
            free(x);
            break;
        }
        default: {  /* the time variable and an output in one get */
            fmi3ValueReference vr[2] = {N_VARS, fuzz_vr(&in, N_VARS)};
            fmi3Float64 v[2];
            fmi3GetFloat64(c, vr, 2, v, 2);
            break;
        }
        }
    }
    for (int s = 0; s < SLOTS; s++)  /* the instances free whatever states they still hold */
        if (live[s]) fmi3FreeInstance(slot[s]);
    return 0;
}
