/* FMI 2.0 co-simulation entry points of a TAPMP FMU: binaries/linux64/<modelIdentifier>.so.
 *
 * This library does not link Python, so any FMI host can load it. On the first
 * fmi2Instantiate it makes sure the Python C API is in the process (a Python host such
 * as FMPy or libcosimpy already has it; a C host gets the libpython recorded at build
 * time in python-env.txt, or $TAPMP_LIBPYTHON, loaded RTLD_GLOBAL so that numpy's
 * extension modules find it too), then loads the Python binding tapmp_fmi2_python.so
 * from the same folder and forwards every call to it: that binding is the native FMUs'
 * runtime (fmu_common/c: fmi2_api.c on the version-neutral files, which refuse a freed or foreign instance)
 * with the Python model operations of python_model.c. Nothing is ever unloaded: the
 * embedded interpreter lives until the process exits (finalizing it while numpy's native
 * libraries are loaded is what crashes hosts at exit). */
#define _GNU_SOURCE  /* dladdr, RTLD_DEFAULT */
#include <pthread.h>

#include "fmi2Functions.h"
#include "python_env.h"

#define BACKEND "tapmp_fmi2_python.so"

/* Every forwarded function: the backend's fmi2<name>. */
#define TAPMP_FORWARDED(X)                                                                     \
    X(Instantiate) X(FreeInstance) X(SetDebugLogging) X(SetupExperiment)                       \
    X(EnterInitializationMode) X(ExitInitializationMode) X(Terminate) X(Reset) X(GetReal)     \
    X(GetInteger) X(GetBoolean) X(GetString) X(SetReal) X(SetInteger) X(SetBoolean)            \
    X(SetString) X(GetFMUstate) X(SetFMUstate) X(FreeFMUstate) X(SerializedFMUstateSize)       \
    X(SerializeFMUstate) X(DeSerializeFMUstate) X(GetDirectionalDerivative)                    \
    X(SetRealInputDerivatives) X(GetRealOutputDerivatives) X(DoStep) X(CancelStep) X(GetStatus) \
    X(GetRealStatus) X(GetIntegerStatus) X(GetBooleanStatus) X(GetStringStatus)

#define TAPMP_POINTER(name) fmi2##name##TYPE *name;
static struct { TAPMP_FORWARDED(TAPMP_POINTER) } backend;
static pthread_mutex_t load_lock = PTHREAD_MUTEX_INITIALIZER;
static int loaded;

static void find_libpython(const char *key, const char *value, void *ctx)
{
    if (strcmp(key, "libpython") == 0) snprintf((char *)ctx, TAPMP_PATH_MAX, "%s", value);
}

/* Loads the backend once; on failure writes the reason to `why` and returns 0. */
static int load_backend(char *why, size_t size)
{
    char dir[TAPMP_PATH_MAX], path[TAPMP_PATH_MAX + 64], libpython[TAPMP_PATH_MAX] = "";
    if (!tapmp_binary_dir((const void *)&load_backend, dir, sizeof dir)) {
        snprintf(why, size, "cannot locate the FMU's binaries folder (dladdr failed)");
        return 0;
    }
    if (!dlsym(RTLD_DEFAULT, "Py_IsInitialized")) {  /* a host without Python in it */
        const char *env = getenv("TAPMP_LIBPYTHON");
        if (env && *env) snprintf(libpython, sizeof libpython, "%s", env);
        else tapmp_read_python_env(dir, find_libpython, libpython);
        if (!libpython[0]) {
            snprintf(why, size, "the host process has no Python and %spython-env.txt names no "
                     "libpython; set TAPMP_LIBPYTHON to a libpython3 shared library", dir);
            return 0;
        }
        if (!dlopen(libpython, RTLD_NOW | RTLD_GLOBAL)) {
            snprintf(why, size, "cannot load libpython '%s' (set TAPMP_LIBPYTHON): %s", libpython,
                     dlerror());
            return 0;
        }
    }
    snprintf(path, sizeof path, "%s%s", dir, BACKEND);
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        snprintf(why, size, "cannot load %s: %s", path, dlerror());
        return 0;
    }
#define TAPMP_RESOLVE(name)                                                                    \
    if (!(backend.name = (fmi2##name##TYPE *)dlsym(lib, "fmi2" #name))) {                      \
        snprintf(why, size, "%s lacks fmi2" #name, path);                                       \
        return 0;                                                                              \
    }
    TAPMP_FORWARDED(TAPMP_RESOLVE)
    return 1;
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn)
{
    char why[2 * TAPMP_PATH_MAX] = "";
    pthread_mutex_lock(&load_lock);
    if (!loaded) loaded = load_backend(why, sizeof why);
    pthread_mutex_unlock(&load_lock);
    if (!loaded) {
        if (functions && functions->logger)
            functions->logger(functions->componentEnvironment, instanceName, fmi2Error,
                              "logStatusError", why);
        return NULL;
    }
    return backend.Instantiate(instanceName, fmuType, fmuGUID, fmuResourceLocation, functions, visible,
                               loggingOn);
}

/* Before the first fmi2Instantiate no instance exists: any other call is refused. */
void fmi2FreeInstance(fmi2Component c)
{
    if (loaded) backend.FreeInstance(c);
}

#define TAPMP_FORWARD(name, params, args)                                                      \
    fmi2Status fmi2##name params                                                               \
    {                                                                                          \
        return loaded ? backend.name args : fmi2Error;                                       \
    }

TAPMP_FORWARD(SetDebugLogging, (fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cats[]),
              (c, on, n, cats))
TAPMP_FORWARD(SetupExperiment, (fmi2Component c, fmi2Boolean tolDefined, fmi2Real tol,
                                fmi2Real start, fmi2Boolean stopDefined, fmi2Real stop),
              (c, tolDefined, tol, start, stopDefined, stop))
TAPMP_FORWARD(EnterInitializationMode, (fmi2Component c), (c))
TAPMP_FORWARD(ExitInitializationMode, (fmi2Component c), (c))
TAPMP_FORWARD(Terminate, (fmi2Component c), (c))
TAPMP_FORWARD(Reset, (fmi2Component c), (c))
TAPMP_FORWARD(GetReal, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]),
              (c, vr, n, v))
TAPMP_FORWARD(GetInteger, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]),
              (c, vr, n, v))
TAPMP_FORWARD(GetBoolean, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]),
              (c, vr, n, v))
TAPMP_FORWARD(GetString, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]),
              (c, vr, n, v))
TAPMP_FORWARD(SetReal, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]),
              (c, vr, n, v))
TAPMP_FORWARD(SetInteger, (fmi2Component c, const fmi2ValueReference vr[], size_t n,
                           const fmi2Integer v[]), (c, vr, n, v))
TAPMP_FORWARD(SetBoolean, (fmi2Component c, const fmi2ValueReference vr[], size_t n,
                           const fmi2Boolean v[]), (c, vr, n, v))
TAPMP_FORWARD(SetString, (fmi2Component c, const fmi2ValueReference vr[], size_t n,
                          const fmi2String v[]), (c, vr, n, v))
TAPMP_FORWARD(GetFMUstate, (fmi2Component c, fmi2FMUstate *s), (c, s))
TAPMP_FORWARD(SetFMUstate, (fmi2Component c, fmi2FMUstate s), (c, s))
TAPMP_FORWARD(FreeFMUstate, (fmi2Component c, fmi2FMUstate *s), (c, s))
TAPMP_FORWARD(SerializedFMUstateSize, (fmi2Component c, fmi2FMUstate s, size_t *size), (c, s, size))
TAPMP_FORWARD(SerializeFMUstate, (fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t size),
              (c, s, b, size))
TAPMP_FORWARD(DeSerializeFMUstate, (fmi2Component c, const fmi2Byte b[], size_t size,
                                    fmi2FMUstate *s), (c, b, size, s))
TAPMP_FORWARD(GetDirectionalDerivative, (fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                         const fmi2ValueReference z[], size_t nz,
                                         const fmi2Real dv[], fmi2Real dz[]),
              (c, u, nu, z, nz, dv, dz))
TAPMP_FORWARD(SetRealInputDerivatives, (fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], const fmi2Real v[]),
              (c, vr, n, order, v))
TAPMP_FORWARD(GetRealOutputDerivatives, (fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                         const fmi2Integer order[], fmi2Real v[]),
              (c, vr, n, order, v))
TAPMP_FORWARD(DoStep, (fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior),
              (c, t, h, noSetPrior))
TAPMP_FORWARD(CancelStep, (fmi2Component c), (c))
TAPMP_FORWARD(GetStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Status *v), (c, k, v))
TAPMP_FORWARD(GetRealStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Real *v), (c, k, v))
TAPMP_FORWARD(GetIntegerStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Integer *v), (c, k, v))
TAPMP_FORWARD(GetBooleanStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v), (c, k, v))
TAPMP_FORWARD(GetStringStatus, (fmi2Component c, const fmi2StatusKind k, fmi2String *v), (c, k, v))
