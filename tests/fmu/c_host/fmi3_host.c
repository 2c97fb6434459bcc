/* A minimal FMI 3.0 co-simulation host in C, with no Python in the process, used by
 * tests/fmu/test_native_hosts.py (the FMI 3.0 twin of fmi2_host.c). Usage:
 *   fmi3_host UNZIPPED_FMU_DIR MODEL_IDENTIFIER STEPS STEP_SIZE [VR=VALUE ...] -- [VR ...]
 * reads the instantiationToken from UNZIPPED_FMU_DIR/modelDescription.xml, loads
 * binaries/x86_64-linux/MODEL_IDENTIFIER.so (Linux, gcc) or
 * binaries\x86_64-windows\MODEL_IDENTIFIER.dll (Windows, mingw-w64; give UNZIPPED_FMU_DIR
 * as a Windows path), calls fmi3InstantiateCoSimulation, sets the Float64 inputs VR=VALUE,
 * fmi3EnterInitializationMode (start time 0), fmi3ExitInitializationMode, does STEPS
 * fmi3DoStep of STEP_SIZE (the n-th from n * STEP_SIZE), prints the Float64 outputs VR
 * after the last step (%.17g, one per line), fmi3Terminate and fmi3FreeInstance. On Linux
 * it also reports on stderr whether a libpython is mapped in the process after
 * instantiation ("libpython loaded: yes" or "libpython loaded: no").
 * Exit code: 0 on success, 1 on any failed call, 2 on bad usage. */
#ifdef _WIN32
#include <windows.h>
#define SEP "\\"
#define BINARIES "binaries\\x86_64-windows"
#define SUFFIX ".dll"
typedef HMODULE lib_t;
#define LIB_OPEN(path) LoadLibraryA(path)
#define LIB_SYM(lib, name) ((void *)GetProcAddress(lib, name))
#else
#define _GNU_SOURCE
#include <dlfcn.h>
#include <link.h>
#define SEP "/"
#define BINARIES "binaries/x86_64-linux"
#define SUFFIX ".so"
typedef void *lib_t;
#define LIB_OPEN(path) dlopen(path, RTLD_NOW | RTLD_LOCAL)
#define LIB_SYM(lib, name) dlsym(lib, name)
#endif
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"

static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env;
    fprintf(stderr, "[c_host %d %s] %s\n", (int)status, category, message);
}

/* The value of attribute `name` (e.g. " instantiationToken=\"") in the file `path`. */
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
    fmi3##name##TYPE *name = (fmi3##name##TYPE *)LIB_SYM(lib, "fmi3" #name);                    \
    if (!name) { fprintf(stderr, "missing fmi3" #name "\n"); return 1; }
#define CHECK(call)                                                                            \
    if ((call) > fmi3Warning) { fprintf(stderr, "%s failed\n", #call); return 1; }

int main(int argc, char **argv)
{
    if (argc < 5) return 2;
#ifndef _WIN32
    if (dlsym(RTLD_DEFAULT, "Py_IsInitialized")) { fprintf(stderr, "Python is in the host\n"); return 2; }
#endif
    char path[4096], resources[4200], md[4200], token[256];
    snprintf(path, sizeof path, "%s" SEP BINARIES SEP "%s" SUFFIX, argv[1], argv[2]);
    snprintf(resources, sizeof resources, "%s" SEP "resources" SEP, argv[1]);
    snprintf(md, sizeof md, "%s" SEP "modelDescription.xml", argv[1]);
    if (!read_attribute(md, " instantiationToken=\"", token, sizeof token)) {
        fprintf(stderr, "no instantiationToken in %s\n", md);
        return 1;
    }
    lib_t lib = LIB_OPEN(path);
#ifdef _WIN32
    if (!lib) { fprintf(stderr, "LoadLibrary %s: error %lu\n", path, (unsigned long)GetLastError()); return 1; }
#else
    if (!lib) { fprintf(stderr, "dlopen: %s\n", dlerror()); return 1; }
#endif
    LOAD(InstantiateCoSimulation) LOAD(EnterInitializationMode) LOAD(ExitInitializationMode)
    LOAD(SetFloat64) LOAD(GetFloat64) LOAD(DoStep) LOAD(Terminate) LOAD(FreeInstance)
    fmi3Instance c = InstantiateCoSimulation("c_host", token, resources, fmi3False, fmi3False, fmi3False,
                                             fmi3False, NULL, 0, NULL, logger, NULL);
    if (!c) { fprintf(stderr, "fmi3InstantiateCoSimulation failed\n"); return 1; }
#ifndef _WIN32
    int python = 0;
    dl_iterate_phdr(find_libpython, &python);
    fprintf(stderr, "libpython loaded: %s\n", python ? "yes" : "no");
#endif
    int steps = atoi(argv[3]), k = 5;
    double h = strtod(argv[4], NULL);
    for (; k < argc && strcmp(argv[k], "--") != 0; k++) {
        fmi3ValueReference vr = (fmi3ValueReference)strtoul(argv[k], NULL, 10);
        const char *eq = strchr(argv[k], '=');
        if (!eq) return 2;
        fmi3Float64 v = strtod(eq + 1, NULL);
        CHECK(SetFloat64(c, &vr, 1, &v, 1));
    }
    CHECK(EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0));
    CHECK(ExitInitializationMode(c));
    for (int n = 0; n < steps; n++) {
        fmi3Boolean event = fmi3False, terminate = fmi3False, early = fmi3False;
        fmi3Float64 last = 0.0;
        CHECK(DoStep(c, n * h, h, fmi3True, &event, &terminate, &early, &last));
        if (terminate || early) { fprintf(stderr, "fmi3DoStep ended the simulation at %g\n", last); return 1; }
    }
    for (k++; k < argc; k++) {
        fmi3ValueReference vr = (fmi3ValueReference)strtoul(argv[k], NULL, 10);
        fmi3Float64 v;
        CHECK(GetFloat64(c, &vr, 1, &v, 1));
        printf("%.17g\n", v);
    }
    CHECK(Terminate(c));
    FreeInstance(c);
    return 0;
}
