/* Call sequences that would show a memory defect of the native FMUs, run on one FMU (its
 * sources/all.c, included below) of either FMI version, built with AddressSanitizer and
 * UndefinedBehaviorSanitizer by tests/fmu/test_fmu_memory.py: every value array has exactly the
 * length the call is given, so a read or write past it is a finding; FMU states are still
 * held when their instance is freed (a leak is a finding at exit) and are used after they or
 * their instance were freed (a use after free is a finding). Each call must return the
 * status written beside it. Prints one line per check and "memory_host: all checks passed";
 * exit code 0, 1 at the first unexpected status. */
#include "all.c"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

static int failures;

#define EXPECT(call, status)                                                                         \
    do {                                                                                             \
        int got_ = (int)(call);                                                                      \
        printf("%-70s -> %d\n", #call, got_);                                                        \
        if (got_ != (status)) {                                                                      \
            printf("  unexpected: expected %d\n", (int)(status));                                    \
            failures++;                                                                              \
        }                                                                                            \
    } while (0)

#ifdef fmi3Version
static void host_logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env;
    printf("  [log %d %s] %s\n", (int)status, category, message);
}

static fmi3Instance make(const char *name)
{
    fmi3Instance c = fmi3InstantiateCoSimulation(name, INSTANTIATION_TOKEN, NULL, fmi3False, fmi3False, fmi3False,
                                                 fmi3False, NULL, 0, NULL, host_logger, NULL);
    if (c) fmi3EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0), fmi3ExitInitializationMode(c);
    return c;
}

int main(void)
{
    fmi3Instance a = make("a"), b = make("b");
    if (!a || !b) return 1;
    fmi3ValueReference vr[3] = {MODEL_OUT_FIRST, MODEL_OUT_FIRST + 1, MODEL_OUT_FIRST + 2};
    fmi3Float64 *one = malloc(sizeof *one);  /* room for one value: the call names three */
    fmi3Int32 *ione = malloc(sizeof *ione);
    one[0] = 1.0;
    ione[0] = 0;
    EXPECT(fmi3SetFloat64(a, vr, 3, one, 1), fmi3Error);
    EXPECT(fmi3GetFloat64(a, vr, 3, one, 1), fmi3Error);
    EXPECT(fmi3GetInt32(a, vr, 3, ione, 1), fmi3Error);
    EXPECT(fmi3SetInt32(a, vr, 3, ione, 1), fmi3Error);
    EXPECT(fmi3GetFloat64(a, vr, 3, NULL, 3), fmi3Error);
    EXPECT(fmi3GetFloat64(a, vr, 1, one, 1), fmi3OK);
    free(one);
    free(ione);
    EXPECT(fmi3Reset(a), fmi3OK);
    a = (fmi3FreeInstance(a), make("a"));
    fmi3FMUState s1 = NULL, s2 = NULL, s3 = NULL, sb = NULL;
    EXPECT(fmi3GetFMUState(a, &s1), fmi3OK);
    EXPECT(fmi3GetFMUState(a, &s2), fmi3OK);
    EXPECT(fmi3GetFMUState(b, &sb), fmi3OK);
    EXPECT(fmi3SetFMUState(b, s1), fmi3Error);              /* a state of another instance */
    EXPECT(fmi3GetFMUState(b, &s1), fmi3Error);             /* not NULL and not b's */
    EXPECT(fmi3FreeFMUState(a, &s2), fmi3OK);
    fmi3FMUState stale = s1;
    EXPECT(fmi3FreeFMUState(a, &stale), fmi3OK);
    EXPECT(fmi3SetFMUState(a, s1), fmi3Error);              /* freed: refused without reading it */
    EXPECT(fmi3FreeFMUState(a, &s1), fmi3Error);            /* freed twice */
    EXPECT(fmi3GetFMUState(a, &s1), fmi3Error);
    s1 = NULL;
    EXPECT(fmi3GetFMUState(a, &s1), fmi3OK);
    size_t size = 0;
    EXPECT(fmi3SerializedFMUStateSize(a, s1, &size), fmi3OK);
    EXPECT(fmi3SerializedFMUStateSize(a, s1, NULL), fmi3Error);
    fmi3Byte *bytes = malloc(size);
    EXPECT(fmi3SerializeFMUState(a, s1, bytes, size), fmi3OK);
    EXPECT(fmi3SerializeFMUState(a, s1, bytes, size - 1), fmi3Error);
    EXPECT(fmi3DeserializeFMUState(a, bytes, size, &s3), fmi3OK);
    EXPECT(fmi3DeserializeFMUState(b, bytes, size, &s3), fmi3Error); /* replacing a's state */
    free(bytes);
    fmi3FreeInstance(a);                                     /* s1 and s3 still held: freed here */
    EXPECT(fmi3SetFMUState(b, s3), fmi3Error);              /* a state of a freed instance */
    EXPECT(fmi3FreeFMUState(b, &s3), fmi3Error);
    fmi3FreeInstance(a);                                     /* freed twice: ignored */
    EXPECT(fmi3Terminate(a), fmi3Error);                    /* a freed instance */
    EXPECT(fmi3SetFMUState(b, sb), fmi3OK);
    fmi3FreeInstance(b);                                     /* sb still held */
    printf(failures ? "memory_host: %d unexpected status(es)\n" : "memory_host: all checks passed\n", failures);
    return failures ? 1 : 0;
}
#else
static void host_logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                        fmi2String message, ...)
{
    va_list ap;
    (void)env;
    printf("  [log %s %d %s] ", name ? name : "", (int)status, category);
    va_start(ap, message);
    vprintf(message, ap);
    va_end(ap);
    printf("\n");
}

static const fmi2CallbackFunctions CALLBACKS = {host_logger, NULL, NULL, NULL, NULL};

static fmi2Component make(const char *name)
{
    fmi2Component c = fmi2Instantiate(name, fmi2CoSimulation, INSTANTIATION_TOKEN, NULL, &CALLBACKS, fmi2False,
                                      fmi2False);
    if (c) fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0), fmi2EnterInitializationMode(c),
           fmi2ExitInitializationMode(c);
    return c;
}

int main(void)
{
    fmi2Component a = make("a"), b = make("b");
    if (!a || !b) return 1;
    fmi2ValueReference vr[3] = {MODEL_OUT_FIRST, MODEL_OUT_FIRST + 1, MODEL_OUT_FIRST + 2};
    EXPECT(fmi2GetReal(a, vr, 3, NULL), fmi2Error);
    EXPECT(fmi2SetReal(a, NULL, 3, NULL), fmi2Error);
    EXPECT(fmi2GetRealStatus(a, fmi2LastSuccessfulTime, NULL), fmi2Error);
    fmi2FreeInstance(a);
    a = make("a");
    fmi2FMUstate s1 = NULL, s2 = NULL, s3 = NULL, sb = NULL;
    EXPECT(fmi2GetFMUstate(a, &s1), fmi2OK);
    EXPECT(fmi2GetFMUstate(a, &s2), fmi2OK);
    EXPECT(fmi2GetFMUstate(b, &sb), fmi2OK);
    EXPECT(fmi2SetFMUstate(b, s1), fmi2Error);              /* a state of another instance */
    EXPECT(fmi2GetFMUstate(b, &s1), fmi2Error);
    EXPECT(fmi2FreeFMUstate(a, &s2), fmi2OK);
    fmi2FMUstate stale = s1;
    EXPECT(fmi2FreeFMUstate(a, &stale), fmi2OK);
    EXPECT(fmi2SetFMUstate(a, s1), fmi2Error);              /* freed: refused without reading it */
    EXPECT(fmi2FreeFMUstate(a, &s1), fmi2Error);
    s1 = NULL;
    EXPECT(fmi2GetFMUstate(a, &s1), fmi2OK);
    size_t size = 0;
    EXPECT(fmi2SerializedFMUstateSize(a, s1, &size), fmi2OK);
    fmi2Byte *bytes = malloc(size);
    EXPECT(fmi2SerializeFMUstate(a, s1, bytes, size), fmi2OK);
    EXPECT(fmi2DeSerializeFMUstate(a, bytes, size, &s3), fmi2OK);
    free(bytes);
    fmi2FreeInstance(a);                                     /* s1 and s3 still held: freed here */
    EXPECT(fmi2SetFMUstate(b, s3), fmi2Error);              /* a state of a freed instance */
    fmi2FreeInstance(a);                                     /* freed twice: ignored */
    EXPECT(fmi2DoStep(a, 0.0, 1e-4, fmi2True), fmi2Error);  /* a freed instance */
    EXPECT(fmi2SetFMUstate(b, sb), fmi2OK);
    fmi2FreeInstance(b);                                     /* sb still held */
    printf(failures ? "memory_host: %d unexpected status(es)\n" : "memory_host: all checks passed\n", failures);
    return failures ? 1 : 0;
}
#endif
