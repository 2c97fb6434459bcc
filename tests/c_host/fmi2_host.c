/* A minimal FMI 2.0 co-simulation host in C, with no Python in the process, used by
 * tests/test_c_host.py. Usage:
 *   fmi2_host UNZIPPED_FMU_DIR MODEL_IDENTIFIER STEPS STEP_SIZE [VR=VALUE ...] -- [VR ...]
 * sets the Real inputs VR=VALUE before initialization, does STEPS doSteps of STEP_SIZE,
 * prints the Real outputs VR after the last step (%.17g, one per line) and frees the
 * instance. Exit code: 0 on success, 1 on any failed call, 2 on bad usage. */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   fmi2String category, fmi2String message, ...)
{
    (void)env;
    va_list ap;
    va_start(ap, message);
    fprintf(stderr, "[%s %d %s] ", name, (int)status, category);
    vfprintf(stderr, message, ap);
    fputc('\n', stderr);
    va_end(ap);
}

#define LOAD(name)                                                                             \
    fmi2##name##TYPE *name = (fmi2##name##TYPE *)dlsym(lib, "fmi2" #name);                      \
    if (!name) { fprintf(stderr, "missing fmi2" #name "\n"); return 1; }
#define CHECK(call)                                                                            \
    if ((call) > fmi2Warning) { fprintf(stderr, "%s failed\n", #call); return 1; }

int main(int argc, char **argv)
{
    if (argc < 5) return 2;
    if (dlsym(RTLD_DEFAULT, "Py_IsInitialized")) { fprintf(stderr, "Python is in the host\n"); return 2; }
    char path[4096], uri[4200];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", argv[1], argv[2]);
    snprintf(uri, sizeof uri, "file://%s/resources", argv[1]);
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "dlopen: %s\n", dlerror()); return 1; }
    LOAD(Instantiate) LOAD(SetupExperiment) LOAD(EnterInitializationMode)
    LOAD(ExitInitializationMode) LOAD(SetReal) LOAD(GetReal) LOAD(DoStep) LOAD(Terminate)
    LOAD(FreeInstance)
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c = Instantiate("c_host", fmi2CoSimulation, "", uri, &cb, fmi2False, fmi2False);
    if (!c) { fprintf(stderr, "fmi2Instantiate failed\n"); return 1; }
    int steps = atoi(argv[3]), k = 5;
    double h = atof(argv[4]);
    for (; k < argc && strcmp(argv[k], "--") != 0; k++) {
        fmi2ValueReference vr = (fmi2ValueReference)strtoul(argv[k], NULL, 10);
        fmi2Real v = atof(strchr(argv[k], '=') + 1);
        CHECK(SetReal(c, &vr, 1, &v));
    }
    CHECK(SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0));
    CHECK(EnterInitializationMode(c));
    CHECK(ExitInitializationMode(c));
    for (int n = 0; n < steps; n++) CHECK(DoStep(c, n * h, h, fmi2True));
    for (k++; k < argc; k++) {
        fmi2ValueReference vr = (fmi2ValueReference)strtoul(argv[k], NULL, 10);
        fmi2Real v;
        CHECK(GetReal(c, &vr, 1, &v));
        printf("%.17g\n", v);
    }
    CHECK(Terminate(c));
    FreeInstance(c);
    return 0;
}
