/*
 * FMI 2.0 co-simulation shim in front of pythonfmu's binary.
 *
 * pythonfmu 0.7 cannot return fmi2Error from Python: a refused doStep becomes
 * fmi2Discard and a Python exception fmi2Fatal (whose code path also corrupts the
 * host interpreter). The TAPMP FMUs therefore never raise; they log bad input at
 * fmi2Error level. This library forwards every FMI call to pythonfmu's library
 * (shipped beside it as <modelIdentifier>_pythonfmu.so) and watches the instance's
 * log: a call during which the instance logged an error returns fmi2Error, as the
 * FMI standard asks for an instance that met invalid input. fmi2Fatal stays fatal.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

typedef struct {
    fmi2Component inner;
    fmi2CallbackFunctions host;  /* the host's callbacks */
    fmi2CallbackFunctions mine;  /* given to the wrapped instance; environment = this struct */
    int error_logged;
} Shim;

#define FMI2_CS_FUNCTIONS(X) \
    X(GetTypesPlatform) X(GetVersion) X(SetDebugLogging) X(Instantiate) X(FreeInstance) \
    X(SetupExperiment) X(EnterInitializationMode) X(ExitInitializationMode) X(Terminate) X(Reset) \
    X(GetReal) X(GetInteger) X(GetBoolean) X(GetString) X(SetReal) X(SetInteger) X(SetBoolean) \
    X(SetString) X(GetFMUstate) X(SetFMUstate) X(FreeFMUstate) X(SerializedFMUstateSize) \
    X(SerializeFMUstate) X(DeSerializeFMUstate) X(GetDirectionalDerivative) \
    X(SetRealInputDerivatives) X(GetRealOutputDerivatives) X(DoStep) X(CancelStep) X(GetStatus) \
    X(GetRealStatus) X(GetIntegerStatus) X(GetBooleanStatus) X(GetStringStatus)

#define DECLARE(NAME) static fmi2##NAME##TYPE *inner_##NAME;
FMI2_CS_FUNCTIONS(DECLARE)

static void *inner_lib;

static int load_inner(const fmi2CallbackFunctions *f, fmi2String instanceName) {
    Dl_info info;
    char path[4096];
    if (inner_lib) return 1;
    if (!dladdr((void *)&load_inner, &info) || !info.dli_fname) return 0;
    size_t n = strlen(info.dli_fname);
    if (n < 3 || n + 16 > sizeof path) return 0;
    memcpy(path, info.dli_fname, n - 3);            /* strip ".so" */
    strcpy(path + n - 3, "_pythonfmu.so");
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        if (f && f->logger) f->logger(f->componentEnvironment, instanceName, fmi2Fatal, "logStatusFatal",
                                      "cannot load %s: %s", path, dlerror());
        return 0;
    }
#define RESOLVE(NAME) inner_##NAME = (fmi2##NAME##TYPE *)dlsym(lib, "fmi2" #NAME);
    FMI2_CS_FUNCTIONS(RESOLVE)
    inner_lib = lib;
    return 1;
}

static void shim_logger(fmi2ComponentEnvironment env, fmi2String instanceName, fmi2Status status,
                        fmi2String category, fmi2String message, ...) {
    Shim *s = (Shim *)env;
    char text[8192];
    va_list ap;
    va_start(ap, message);
    vsnprintf(text, sizeof text, message, ap);
    va_end(ap);
    if (status == fmi2Error || status == fmi2Fatal) s->error_logged = 1;
    if (s->host.logger) s->host.logger(s->host.componentEnvironment, instanceName, status, category, "%s", text);
}

static fmi2Status checked(Shim *s, fmi2Status status) {
    if (s->error_logged && status != fmi2Fatal && status != fmi2Error) return fmi2Error;
    return status;
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    if (!functions || !load_inner(functions, instanceName)) return NULL;
    Shim *s = (Shim *)calloc(1, sizeof(Shim));
    if (!s) return NULL;
    s->host = *functions;
    s->mine = *functions;
    s->mine.logger = shim_logger;
    s->mine.componentEnvironment = s;
    s->inner = inner_Instantiate(instanceName, fmuType, fmuGUID, fmuResourceLocation, &s->mine,
                                 visible, loggingOn);
    if (!s->inner) { free(s); return NULL; }
    return s;
}

void fmi2FreeInstance(fmi2Component c) {
    Shim *s = (Shim *)c;
    if (!s) return;
    inner_FreeInstance(s->inner);
    free(s);
}

#define FORWARD(NAME, PARAMS, ARGS) \
    fmi2Status fmi2##NAME PARAMS { \
        Shim *s = (Shim *)c; \
        s->error_logged = 0; \
        return checked(s, inner_##NAME ARGS); \
    }

FORWARD(SetDebugLogging, (fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]), (s->inner, on, n, cat))
FORWARD(SetupExperiment, (fmi2Component c, fmi2Boolean td, fmi2Real tol, fmi2Real t0, fmi2Boolean sd, fmi2Real t1),
        (s->inner, td, tol, t0, sd, t1))
FORWARD(EnterInitializationMode, (fmi2Component c), (s->inner))
FORWARD(ExitInitializationMode, (fmi2Component c), (s->inner))
FORWARD(Terminate, (fmi2Component c), (s->inner))
FORWARD(Reset, (fmi2Component c), (s->inner))
FORWARD(GetReal, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]), (s->inner, vr, n, v))
FORWARD(GetInteger, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]), (s->inner, vr, n, v))
FORWARD(GetBoolean, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]), (s->inner, vr, n, v))
FORWARD(GetString, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]), (s->inner, vr, n, v))
FORWARD(SetReal, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]), (s->inner, vr, n, v))
FORWARD(SetInteger, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]),
        (s->inner, vr, n, v))
FORWARD(SetBoolean, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]),
        (s->inner, vr, n, v))
FORWARD(SetString, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]),
        (s->inner, vr, n, v))
FORWARD(GetFMUstate, (fmi2Component c, fmi2FMUstate *st), (s->inner, st))
FORWARD(SetFMUstate, (fmi2Component c, fmi2FMUstate st), (s->inner, st))
FORWARD(FreeFMUstate, (fmi2Component c, fmi2FMUstate *st), (s->inner, st))
FORWARD(SerializedFMUstateSize, (fmi2Component c, fmi2FMUstate st, size_t *size), (s->inner, st, size))
FORWARD(SerializeFMUstate, (fmi2Component c, fmi2FMUstate st, fmi2Byte b[], size_t size), (s->inner, st, b, size))
FORWARD(DeSerializeFMUstate, (fmi2Component c, const fmi2Byte b[], size_t size, fmi2FMUstate *st),
        (s->inner, b, size, st))
FORWARD(GetDirectionalDerivative, (fmi2Component c, const fmi2ValueReference u[], size_t nu,
        const fmi2ValueReference z[], size_t nz, const fmi2Real dv[], fmi2Real dz[]), (s->inner, u, nu, z, nz, dv, dz))
FORWARD(SetRealInputDerivatives, (fmi2Component c, const fmi2ValueReference vr[], size_t n,
        const fmi2Integer order[], const fmi2Real v[]), (s->inner, vr, n, order, v))
FORWARD(GetRealOutputDerivatives, (fmi2Component c, const fmi2ValueReference vr[], size_t n,
        const fmi2Integer order[], fmi2Real v[]), (s->inner, vr, n, order, v))
FORWARD(DoStep, (fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior), (s->inner, t, h, noSetPrior))
FORWARD(CancelStep, (fmi2Component c), (s->inner))
FORWARD(GetStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Status *v), (s->inner, k, v))
FORWARD(GetRealStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Real *v), (s->inner, k, v))
FORWARD(GetIntegerStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Integer *v), (s->inner, k, v))
FORWARD(GetBooleanStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v), (s->inner, k, v))
FORWARD(GetStringStatus, (fmi2Component c, const fmi2StatusKind k, fmi2String *v), (s->inner, k, v))
