/* TAPMP_Probe: an FMI 2.0 co-simulation FMU that does nothing but note the wall time at which each
 * fmi2DoStep is called, so that any master's real-time pacing can be measured from outside: put it
 * into an SSP beside the FMUs, unconnected, and every macro step of the master calls it once.
 *
 * At each fmi2DoStep(t, h) it records t [s], h [s] and the wall time [ns] of CLOCK_MONOTONIC. That clock
 * and not CLOCK_REALTIME: only differences within one process are used (lateness against the first
 * doStep), CLOCK_MONOTONIC never jumps when the system clock is set, and it is what the steady clocks a
 * pacing loop uses read on Linux (std::chrono::steady_clock, Python's time.monotonic).
 *
 * The string parameter `file` names the file written at fmi2Terminate (or at fmi2FreeInstance if the
 * master never terminated): one line per doStep "t h wall_ns", t and h in %.17g. It is written to
 * FILE.part and renamed, so a reader sees it whole or not at all. The output `steps` counts the doSteps.
 * Built by benchmarks/probe/probe.py with the project's toolchain. */
#define _POSIX_C_SOURCE 200809L  /* clock_gettime under -std=c99 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2Functions.h"

#define VR_FILE 0
#define VR_STEPS 1

typedef struct {
    double t, h;
    int64_t wall_ns;
} stamp;

typedef struct {
    char *file;
    stamp *stamps;
    size_t n, cap;
    int written;
    fmi2CallbackFunctions cb;
    char name[128];
} probe;

static int64_t wall_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

static void say(probe *p, fmi2Status status, const char *message)
{
    if (p->cb.logger) p->cb.logger(p->cb.componentEnvironment, p->name, status, "logStatusError", "%s", message);
}

static char *copy(const char *text)
{
    char *c = malloc(strlen(text) + 1);
    if (c) strcpy(c, text);
    return c;
}

/* The stamps into p->file (through FILE.part, renamed): fmi2OK, or fmi2Error with a message. */
static fmi2Status write_stamps(probe *p)
{
    if (p->written) return fmi2OK;
    p->written = 1;
    if (!p->file || !*p->file) return fmi2OK;  /* no file named: nothing to keep */
    size_t len = strlen(p->file) + 6;
    char *part = malloc(len), message[512];
    if (!part) return fmi2Error;
    snprintf(part, len, "%s.part", p->file);
    FILE *f = fopen(part, "w");
    int ok = f != NULL;
    for (size_t i = 0; ok && i < p->n; i++)
        ok = fprintf(f, "%.17g %.17g %lld\n", p->stamps[i].t, p->stamps[i].h, (long long)p->stamps[i].wall_ns) > 0;
    if (f && fclose(f) != 0) ok = 0;
    if (ok) ok = rename(part, p->file) == 0;
    else remove(part);
    free(part);
    if (ok) return fmi2OK;
    snprintf(message, sizeof message, "file = '%s' could not be written", p->file);
    say(p, fmi2Error, message);
    return fmi2Error;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String resources,
                              const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean logging)
{
    (void)guid, (void)resources, (void)visible, (void)logging;
    if (type != fmi2CoSimulation) return NULL;
    probe *p = calloc(1, sizeof *p);
    if (!p) return NULL;
    if (cb) p->cb = *cb;
    snprintf(p->name, sizeof p->name, "%s", name ? name : "probe");
    p->file = copy(PROBE_FILE);  /* the start value of `file`, given at compile time */
    p->cap = 1 << 14;
    p->stamps = malloc(p->cap * sizeof *p->stamps);
    if (!p->file || !p->stamps) {
        free(p->file), free(p->stamps), free(p);
        return NULL;
    }
    return p;
}

void fmi2FreeInstance(fmi2Component c)
{
    probe *p = c;
    if (!p) return;
    write_stamps(p);
    free(p->file), free(p->stamps), free(p);
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_prior)
{
    (void)no_prior;
    int64_t now = wall_ns();  /* first: the time the master called */
    probe *p = c;
    if (p->n == p->cap) {
        stamp *more = realloc(p->stamps, 2 * p->cap * sizeof *more);
        if (!more) return fmi2Error;
        p->stamps = more, p->cap *= 2;
    }
    p->stamps[p->n++] = (stamp){t, h, now};
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[])
{
    probe *p = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != VR_FILE) return fmi2Error;
        char *f = copy(v[i] ? v[i] : "");
        if (!f) return fmi2Error;
        free(p->file);
        p->file = f;
    }
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[])
{
    probe *p = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != VR_FILE) return fmi2Error;
        v[i] = p->file;
    }
    return fmi2OK;
}

/* `steps` is a Real: masters that record every output (tapmp's engine) read them all as Real */
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[])
{
    probe *p = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != VR_STEPS) return fmi2Error;
        v[i] = (fmi2Real)p->n;
    }
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) { return write_stamps(c); }

/* the rest of the API: the life cycle accepted, nothing else to get or set */
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[])
{
    (void)c, (void)on, (void)n, (void)cat;
    return fmi2OK;
}
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tol_defined, fmi2Real tol, fmi2Real start,
                               fmi2Boolean stop_defined, fmi2Real stop)
{
    (void)c, (void)tol_defined, (void)tol, (void)start, (void)stop_defined, (void)stop;
    return fmi2OK;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c)
{
    probe *p = c;
    p->n = 0, p->written = 0;
    return fmi2OK;
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[])
{
    (void)c, (void)vr, (void)v;
    return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[])
{
    (void)c, (void)vr, (void)v;
    return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[])
{
    (void)c, (void)vr, (void)v;
    return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[])
{
    (void)c, (void)vr, (void)v;
    return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[])
{
    (void)c, (void)vr, (void)v;
    return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c, (void)s; return fmi2Error; }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { (void)c, (void)s; return fmi2Error; }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c, (void)s; return fmi2Error; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n)
{
    (void)c, (void)s, (void)n;
    return fmi2Error;
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n)
{
    (void)c, (void)s, (void)b, (void)n;
    return fmi2Error;
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s)
{
    (void)c, (void)b, (void)n, (void)s;
    return fmi2Error;
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real dv[], fmi2Real dz[])
{
    (void)c, (void)u, (void)nu, (void)z, (void)nz, (void)dv, (void)dz;
    return fmi2Error;
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real v[])
{
    (void)c, (void)vr, (void)n, (void)order, (void)v;
    return fmi2Error;
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real v[])
{
    (void)c, (void)vr, (void)n, (void)order, (void)v;
    return fmi2Error;
}
fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v)
{
    (void)c, (void)s, (void)v;
    return fmi2Discard;
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v)
{
    (void)c, (void)s, (void)v;
    return fmi2Discard;
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v)
{
    (void)c, (void)s, (void)v;
    return fmi2Discard;
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v)
{
    (void)c, (void)s, (void)v;
    return fmi2Discard;
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v)
{
    (void)c, (void)s, (void)v;
    return fmi2Discard;
}
