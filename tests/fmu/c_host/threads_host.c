/* Two threads, each with instances of its own of one native FMU (its sources/all.c, included
 * below, FMI 2.0 or 3.0): FMI lets a host run different instances on different threads at once.
 * Each thread instantiates, initializes, steps, gets, serializes, deserializes, sets and frees
 * states and frees the instance, CYCLES times, so the runtime's shared registry of live
 * instances is changed and read by both threads all the time. Built with ThreadSanitizer by
 * tests/fmu/test_fmu_threads.py: a data race is a finding. Prints "threads_host: all calls OK"
 * and exits 0, or 1 at the first call that does not return OK. */
#include "all.c"

#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>

#define CYCLES 40
#define STEPS 20

static void host_log_text(const char *message) { fprintf(stderr, "  [log] %s\n", message); }

#ifdef fmi3Version
typedef fmi3Instance instance_t;
typedef fmi3FMUState state_t;
static void host_logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env, (void)status, (void)category;
    host_log_text(message);
}
static instance_t make(const char *name)
{
    fmi3Instance c = fmi3InstantiateCoSimulation(name, INSTANTIATION_TOKEN, NULL, fmi3False, fmi3False, fmi3False,
                                                 fmi3False, NULL, 0, NULL, host_logger, NULL);
    if (c && (fmi3EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0) != fmi3OK ||
              fmi3ExitInitializationMode(c) != fmi3OK))
        return fmi3FreeInstance(c), NULL;
    return c;
}
#define DO_STEP(c, t, h) fmi3DoStep(c, t, h, fmi3True, &(fmi3Boolean){0}, &(fmi3Boolean){0}, &(fmi3Boolean){0}, \
                                    &(fmi3Float64){0})
#define GET_STATE fmi3GetFMUState
#define SET_STATE fmi3SetFMUState
#define FREE_STATE fmi3FreeFMUState
#define STATE_SIZE fmi3SerializedFMUStateSize
#define SERIALIZE fmi3SerializeFMUState
#define DESERIALIZE(c, bytes, n, s) fmi3DeserializeFMUState(c, (const fmi3Byte *)(bytes), n, s)
#define FREE_INSTANCE fmi3FreeInstance
typedef fmi3Byte byte_t;
#else
typedef fmi2Component instance_t;
typedef fmi2FMUstate state_t;
static void host_logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env, (void)name, (void)status, (void)category;
    host_log_text(message);
}
static const fmi2CallbackFunctions callbacks = {host_logger, calloc, free, NULL, NULL};
static instance_t make(const char *name)
{
    fmi2Component c = fmi2Instantiate(name, fmi2CoSimulation, INSTANTIATION_TOKEN, NULL, &callbacks, fmi2False,
                                      fmi2False);
    if (c && (fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) != fmi2OK ||
              fmi2EnterInitializationMode(c) != fmi2OK || fmi2ExitInitializationMode(c) != fmi2OK))
        return fmi2FreeInstance(c), NULL;
    return c;
}
#define DO_STEP(c, t, h) fmi2DoStep(c, t, h, fmi2True)
#define GET_STATE fmi2GetFMUstate
#define SET_STATE fmi2SetFMUstate
#define FREE_STATE fmi2FreeFMUstate
#define STATE_SIZE fmi2SerializedFMUstateSize
#define SERIALIZE fmi2SerializeFMUstate
#define DESERIALIZE(c, bytes, n, s) fmi2DeSerializeFMUstate(c, (const fmi2Byte *)(bytes), n, s)
#define FREE_INSTANCE fmi2FreeInstance
typedef fmi2Byte byte_t;
#endif

#define CHECK(call)                                                                                  \
    do {                                                                                             \
        if ((int)(call) != 0) {                                                                      \
            fprintf(stderr, "threads_host: %s returned %d\n", #call, (int)(call));                   \
            return (void *)1;                                                                        \
        }                                                                                            \
    } while (0)

static void *worker(void *arg)
{
    const char *name = arg;
    for (int cycle = 0; cycle < CYCLES; cycle++) {
        instance_t c = make(name);
        if (!c) return (void *)1;
        state_t s = NULL, d = NULL;
        size_t n = 0;
        for (int k = 0; k < STEPS; k++) CHECK(DO_STEP(c, k * 1e-4, 1e-4));
        CHECK(GET_STATE(c, &s));
        CHECK(STATE_SIZE(c, s, &n));
        byte_t *bytes = malloc(n);
        if (!bytes) return (void *)1;
        CHECK(SERIALIZE(c, s, bytes, n));
        CHECK(DESERIALIZE(c, bytes, n, &d));
        free(bytes);
        CHECK(SET_STATE(c, d));
        CHECK(DO_STEP(c, STEPS * 1e-4, 1e-4));
        CHECK(FREE_STATE(c, &s));
        CHECK(FREE_STATE(c, &d));
        FREE_INSTANCE(c);
    }
    return NULL;
}

int main(void)
{
    pthread_t a, b;
    void *ra = (void *)1, *rb = (void *)1;
    if (pthread_create(&a, NULL, worker, "a") || pthread_create(&b, NULL, worker, "b")) return 1;
    pthread_join(a, &ra);
    pthread_join(b, &rb);
    if (ra || rb) return 1;
    printf("threads_host: all calls OK\n");
    return 0;
}
