/* A minimal FMI 2.0 co-simulation host in C, with no Python in the process, used by
 * tests/fmu/test_c_host.py and tests/fmu/test_native_hosts.py. Usage:
 *   fmi2_host UNZIPPED_FMU_DIR MODEL_IDENTIFIER STEPS STEP_SIZE [VR=VALUE ...] -- [VR ...]
 * reads the GUID from UNZIPPED_FMU_DIR/modelDescription.xml, loads
 * binaries/linux64/MODEL_IDENTIFIER.so (Linux, gcc) or binaries\win64\MODEL_IDENTIFIER.dll
 * (Windows, mingw-w64; give UNZIPPED_FMU_DIR as a Windows path), sets the Real inputs
 * VR=VALUE before initialization, does STEPS doSteps of STEP_SIZE (the n-th from n * STEP_SIZE),
 * prints the Real outputs VR after the last step (%.17g, one per line) and frees the
 * instance. On Linux it also reports on stderr whether a libpython is mapped in the process
 * after fmi2Instantiate ("libpython loaded: yes" or "libpython loaded: no").
 * Exit code: 0 on success, 1 on any failed call, 2 on bad usage. */
#ifdef _WIN32
#include <windows.h>
#define SEP "\\"
#define BINARIES "binaries\\win64"
#define SUFFIX ".dll"
typedef HMODULE lib_t;
#define LIB_OPEN(path) LoadLibraryA(path)
#define LIB_SYM(lib, name) ((void *)GetProcAddress(lib, name))
#else
#define _GNU_SOURCE
#include <dlfcn.h>
#include <link.h>
#define SEP "/"
#define BINARIES "binaries/linux64"
#define SUFFIX ".so"
typedef void *lib_t;
#define LIB_OPEN(path) dlopen(path, RTLD_NOW | RTLD_LOCAL)
#define LIB_SYM(lib, name) dlsym(lib, name)
#endif
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

/* The value of attribute `name` (e.g. " guid=\"") in the file `path`, or "" if absent. */
static int read_attribute(const char *path, const char *name, char *value, size_t size)
{
    value[0] = '\0';
    FILE *f = fopen(path, "rb");
    if (!f) return 0;
    static char text[1 << 20];
    size_t n = fread(text, 1, sizeof text - 1, f);
    fclose(f);
    text[n] = '\0';
    const char *start = strstr(text, name);
    if (!start) return 0;
    start += strlen(name);
    const char *end = strchr(start, '"');
    if (!end || (size_t)(end - start) >= size) return 0;
    memcpy(value, start, (size_t)(end - start));
    value[end - start] = '\0';
    return 1;
}

#ifndef _WIN32
static int find_libpython(struct dl_phdr_info *info, size_t size, void *found)
{
    (void)size;
    if (info->dlpi_name && strstr(info->dlpi_name, "libpython")) *(int *)found = 1;
    return 0;
}
#endif

#define LOAD(name)                                                                             \
    fmi2##name##TYPE *name = (fmi2##name##TYPE *)LIB_SYM(lib, "fmi2" #name);                    \
    if (!name) { fprintf(stderr, "missing fmi2" #name "\n"); return 1; }
#define CHECK(call)                                                                            \
    if ((call) > fmi2Warning) { fprintf(stderr, "%s failed\n", #call); return 1; }

int main(int argc, char **argv)
{
    if (argc < 5) return 2;
#ifndef _WIN32
    if (dlsym(RTLD_DEFAULT, "Py_IsInitialized")) { fprintf(stderr, "Python is in the host\n"); return 2; }
#endif
    char path[4096], uri[4200], md[4200], guid[256];
    snprintf(path, sizeof path, "%s" SEP BINARIES SEP "%s" SUFFIX, argv[1], argv[2]);
    snprintf(uri, sizeof uri, "file://%s/resources", argv[1]);
    snprintf(md, sizeof md, "%s" SEP "modelDescription.xml", argv[1]);
    if (!read_attribute(md, " guid=\"", guid, sizeof guid)) { fprintf(stderr, "no guid in %s\n", md); return 1; }
    lib_t lib = LIB_OPEN(path);
#ifdef _WIN32
    if (!lib) { fprintf(stderr, "LoadLibrary %s: error %lu\n", path, (unsigned long)GetLastError()); return 1; }
#else
    if (!lib) { fprintf(stderr, "dlopen: %s\n", dlerror()); return 1; }
#endif
    LOAD(Instantiate) LOAD(SetupExperiment) LOAD(EnterInitializationMode)
    LOAD(ExitInitializationMode) LOAD(SetReal) LOAD(GetReal) LOAD(DoStep) LOAD(Terminate)
    LOAD(FreeInstance)
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c = Instantiate("c_host", fmi2CoSimulation, guid, uri, &cb, fmi2False, fmi2False);
    if (!c) { fprintf(stderr, "fmi2Instantiate failed\n"); return 1; }
#ifndef _WIN32
    int python = 0;
    dl_iterate_phdr(find_libpython, &python);
    fprintf(stderr, "libpython loaded: %s\n", python ? "yes" : "no");
#endif
    int steps = atoi(argv[3]), k = 5;
    double h = atof(argv[4]);
    for (; k < argc && strcmp(argv[k], "--") != 0; k++) {
        fmi2ValueReference vr = (fmi2ValueReference)strtoul(argv[k], NULL, 10);
        const char *eq = strchr(argv[k], '=');
        if (!eq) return 2;
        fmi2Real v = strtod(eq + 1, NULL);
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
