/* The controller's execution time per sample, for benchmarks/bench_controller_time.py: one native
 * TAPMP controller FMU (or the C model's control law alone) driven with recorded inputs, every sample
 * timed with CLOCK_MONOTONIC. Usage:
 *   controller_time MODE PATH INPUTS SAMPLES LAW OUT
 * MODE   fmi2          FMI 2.0 CS: per sample fmi2SetReal (15 inputs), fmi2DoStep(t, h), fmi2GetReal (12 outputs)
 *        fmi3          FMI 3.0 CS, no event mode: the same with fmi3SetFloat64, fmi3DoStep, fmi3GetFloat64
 *        fmi3-event    FMI 3.0 CS in Event Mode: inputs, fmi3DoStep(t, h) (it ends at the time event t + h),
 *                      fmi3EnterEventMode, inputs of t + h, fmi3UpdateDiscreteStates, outputs, fmi3EnterStepMode
 *        fmi3-clocked  the clocked controller: fmi3EnterEventMode, fmi3SetClock, inputs,
 *                      fmi3UpdateDiscreteStates, outputs, fmi3EnterStepMode, fmi3DoStep(t, h)
 *        law           tapmp_controller_sample (tapmp/c/tapmp_model.h) alone, the function the controller
 *                      calls per sample, compiled into this program from the FMU's sources
 * PATH   the unzipped FMU (the fmi modes), or for `law` a file holding the bytes of one
 *        tapmp_controller_settings (the controller's default settings, written by the benchmark)
 * INPUTS rows of 15 doubles (X_d Z_d B_d dX_d dZ_d dB_d ddX_d ddZ_d ddB_d q1 q2 q3 dq1 dq2 dq3), native
 *        byte order; sample n gets row n modulo the number of rows
 * SAMPLES the number of timed samples (1 .. 1e9), h = T_s = 1e-4 s
 * LAW    the controller's `law` setting: 0 SC-DC, 1 APD-DC, 2 PID-DC
 * OUT    written: SAMPLES int64 durations [ns], native byte order
 * One timed sample is every call of the sample (MODE above), from the first input set to the last
 * output read. Prints the last F1..F3 (so that no call can be optimized away). Exit code: 0 on
 * success, 1 on a failed FMI call, 2 on bad usage (one line on stderr naming the argument). */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2Functions.h"
#include "fmi3Functions.h"
#include "tapmp_model.h"

#define N_IN 15
#define N_OUT 12
#define H 1e-4
static const char *IN_NAMES[N_IN] = {"X_d", "Z_d", "B_d", "dX_d", "dZ_d", "dB_d", "ddX_d", "ddZ_d", "ddB_d",
                                     "q1", "q2", "q3", "dq1", "dq2", "dq3"};
static const char *OUT_NAMES[N_OUT] = {"F1", "F2", "F3", "u1", "u2", "u3", "e1", "e2", "e3", "es1", "es2", "es3"};

static int usage(const char *what, const char *value, const char *allowed)
{
    fprintf(stderr, "controller_time: %s = '%s' is invalid: allowed is %s\n", what, value, allowed);
    return 2;
}

static int64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

/* The whole of file `path` (malloc'ed, *size bytes), or NULL. */
static char *slurp(const char *path, size_t *size)
{
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    size_t cap = 1 << 16, n = 0;
    char *buf = malloc(cap + 1);
    for (size_t got; buf && (got = fread(buf + n, 1, cap - n, f)) > 0;) {
        n += got;
        if (n == cap) buf = realloc(buf, (cap *= 2) + 1);
    }
    fclose(f);
    if (buf) buf[n] = '\0';
    *size = n;
    return buf;
}

/* The value of attribute `attr` of the element whose name="..." is `name` (or of the first element
 * `<tag` if name is NULL) in the modelDescription `md`, copied into value. */
static const char *attribute(const char *md, const char *tag, const char *name, const char *attr, char *value,
                             size_t size)
{
    char key[300], akey[64];
    const char *start;
    if (name) {
        snprintf(key, sizeof key, " name=\"%s\"", name);
        const char *at = strstr(md, key);
        if (!at) return NULL;
        for (start = at; start > md && *start != '<'; start--) {}
    } else if (!(start = strstr(md, tag))) {
        return NULL;
    }
    snprintf(akey, sizeof akey, " %s=\"", attr);
    const char *end = strchr(start, '>'), *a = strstr(start, akey);
    if (!a || !end || a > end) return NULL;
    a += strlen(akey);
    const char *q = strchr(a, '"');
    if (!q || (size_t)(q - a) >= size) return NULL;
    memcpy(value, a, (size_t)(q - a));
    value[q - a] = '\0';
    return value;
}

static int vr(const char *md, const char *name, unsigned *out)
{
    char v[32];
    if (!attribute(md, NULL, name, "valueReference", v, sizeof v)) {
        fprintf(stderr, "controller_time: the FMU has no variable %s\n", name);
        return 0;
    }
    *out = (unsigned)strtoul(v, NULL, 10);
    return 1;
}

static void log2(fmi2ComponentEnvironment e, fmi2String n, fmi2Status s, fmi2String c, fmi2String m, ...)
{
    (void)e, (void)c;
    fprintf(stderr, "[%s %d] %s\n", n, (int)s, m);
}

static void log3(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env;
    fprintf(stderr, "[controller %d %s] %s\n", (int)status, category, message);
}

#define SYM(lib, T, name)                                                                  \
    T *name = (T *)dlsym(lib, #name);                                                      \
    if (!name) { fprintf(stderr, "controller_time: the FMU has no " #name "\n"); return 1; }
#define OK(call)                                                                           \
    if ((call) > 1) { fprintf(stderr, "controller_time: %s failed\n", #call); return 1; }

typedef struct {
    const double *rows;
    size_t n_rows;
    long samples;
    int law;
    int64_t *ns;
    double out[N_OUT];
} job;

static const double *row(const job *j, long n) { return j->rows + (size_t)n % j->n_rows * N_IN; }

static int run_fmi2(job *j, const char *dir, const char *md, const char *id)
{
    char path[4200], resources[4200], guid[256];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", dir, id);  /* FMI 2.0's platform folder */
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "controller_time: %s\n", dlerror()); return 1; }
    SYM(lib, fmi2InstantiateTYPE, fmi2Instantiate) SYM(lib, fmi2SetupExperimentTYPE, fmi2SetupExperiment)
    SYM(lib, fmi2EnterInitializationModeTYPE, fmi2EnterInitializationMode)
    SYM(lib, fmi2ExitInitializationModeTYPE, fmi2ExitInitializationMode) SYM(lib, fmi2SetRealTYPE, fmi2SetReal)
    SYM(lib, fmi2GetRealTYPE, fmi2GetReal) SYM(lib, fmi2SetIntegerTYPE, fmi2SetInteger)
    SYM(lib, fmi2DoStepTYPE, fmi2DoStep) SYM(lib, fmi2TerminateTYPE, fmi2Terminate)
    SYM(lib, fmi2FreeInstanceTYPE, fmi2FreeInstance)
    if (!attribute(md, "<fmiModelDescription", NULL, "guid", guid, sizeof guid)) return 2;
    unsigned in[N_IN], out[N_OUT], law;
    for (int i = 0; i < N_IN; i++) if (!vr(md, IN_NAMES[i], &in[i])) return 2;
    for (int i = 0; i < N_OUT; i++) if (!vr(md, OUT_NAMES[i], &out[i])) return 2;
    if (!vr(md, "law", &law)) return 2;
    snprintf(resources, sizeof resources, "file://%s/resources", dir);
    fmi2CallbackFunctions cb = {log2, calloc, free, NULL, NULL};
    fmi2Component c = fmi2Instantiate(id, fmi2CoSimulation, guid, resources, &cb, fmi2False, fmi2False);
    if (!c) { fprintf(stderr, "controller_time: fmi2Instantiate failed\n"); return 1; }
    OK(fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0))
    OK(fmi2SetInteger(c, &law, 1, &j->law))
    OK(fmi2EnterInitializationMode(c))
    OK(fmi2SetReal(c, in, N_IN, row(j, 0)))
    OK(fmi2ExitInitializationMode(c))
    for (long n = 0; n < j->samples; n++) {
        int64_t t0 = now_ns();
        OK(fmi2SetReal(c, in, N_IN, row(j, n)))
        OK(fmi2DoStep(c, n * H, H, fmi2True))
        OK(fmi2GetReal(c, out, N_OUT, j->out))
        j->ns[n] = now_ns() - t0;
    }
    OK(fmi2Terminate(c))
    fmi2FreeInstance(c);
    return 0;
}

static int run_fmi3(job *j, const char *dir, const char *md, const char *id, int event, int clocked)
{
    char path[4200], resources[4200], token[256], v[32];
    snprintf(path, sizeof path, "%s/binaries/x86_64-linux/%s.so", dir, id);
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "controller_time: %s\n", dlerror()); return 1; }
    SYM(lib, fmi3InstantiateCoSimulationTYPE, fmi3InstantiateCoSimulation)
    SYM(lib, fmi3EnterInitializationModeTYPE, fmi3EnterInitializationMode)
    SYM(lib, fmi3ExitInitializationModeTYPE, fmi3ExitInitializationMode) SYM(lib, fmi3SetFloat64TYPE, fmi3SetFloat64)
    SYM(lib, fmi3GetFloat64TYPE, fmi3GetFloat64) SYM(lib, fmi3SetInt32TYPE, fmi3SetInt32)
    SYM(lib, fmi3DoStepTYPE, fmi3DoStep) SYM(lib, fmi3EnterEventModeTYPE, fmi3EnterEventMode)
    SYM(lib, fmi3EnterStepModeTYPE, fmi3EnterStepMode) SYM(lib, fmi3UpdateDiscreteStatesTYPE, fmi3UpdateDiscreteStates)
    SYM(lib, fmi3SetClockTYPE, fmi3SetClock) SYM(lib, fmi3TerminateTYPE, fmi3Terminate)
    SYM(lib, fmi3FreeInstanceTYPE, fmi3FreeInstance)
    if (!attribute(md, "<fmiModelDescription", NULL, "instantiationToken", token, sizeof token)) return 2;
    unsigned in[N_IN], out[N_OUT], law, clock = 0;
    for (int i = 0; i < N_IN; i++) if (!vr(md, IN_NAMES[i], &in[i])) return 2;
    for (int i = 0; i < N_OUT; i++) if (!vr(md, OUT_NAMES[i], &out[i])) return 2;
    if (!vr(md, "law", &law)) return 2;
    if (clocked) {
        if (!attribute(md, "<Clock ", NULL, "valueReference", v, sizeof v)) {
            fprintf(stderr, "controller_time: MODE = 'fmi3-clocked' needs an FMU with a <Clock>\n");
            return 2;
        }
        clock = (unsigned)strtoul(v, NULL, 10);
    }
    snprintf(resources, sizeof resources, "%s/resources/", dir);
    int events = event || clocked;
    fmi3Instance c = fmi3InstantiateCoSimulation(id, token, resources, fmi3False, fmi3False, events ? fmi3True : fmi3False,
                                                 event ? fmi3True : fmi3False, NULL, 0, NULL, log3, NULL);
    if (!c) { fprintf(stderr, "controller_time: fmi3InstantiateCoSimulation failed\n"); return 1; }
    fmi3Int32 law_value = j->law;
    fmi3Boolean again, terminate, nominals, values, defined, handling, early;
    fmi3Float64 next, last;
    fmi3Clock active = fmi3ClockActive;
    OK(fmi3SetInt32(c, &law, 1, &law_value, 1))
    OK(fmi3EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0))
    OK(fmi3SetFloat64(c, in, N_IN, row(j, 0), N_IN))
    OK(fmi3ExitInitializationMode(c))
    if (events) {  /* Event Mode after initialization: the sample (the tick) at t = 0 */
        if (clocked) OK(fmi3SetClock(c, &clock, 1, &active))
        OK(fmi3UpdateDiscreteStates(c, &again, &terminate, &nominals, &values, &defined, &next))
        OK(fmi3EnterStepMode(c))
    }
    for (long n = 0; n < j->samples; n++) {
        int64_t t0 = now_ns();
        if (clocked) {
            if (n > 0) {  /* the tick at n h, then the step over [n h, (n + 1) h] */
                OK(fmi3EnterEventMode(c))
                OK(fmi3SetClock(c, &clock, 1, &active))
                OK(fmi3SetFloat64(c, in, N_IN, row(j, n), N_IN))
                OK(fmi3UpdateDiscreteStates(c, &again, &terminate, &nominals, &values, &defined, &next))
                OK(fmi3GetFloat64(c, out, N_OUT, j->out, N_OUT))
                OK(fmi3EnterStepMode(c))
            }
            OK(fmi3DoStep(c, n * H, H, fmi3True, &handling, &terminate, &early, &last))
        } else {
            OK(fmi3SetFloat64(c, in, N_IN, row(j, n), N_IN))
            OK(fmi3DoStep(c, n * H, H, fmi3True, &handling, &terminate, &early, &last))
            if (event) {  /* the sample instant (n + 1) h ends the step: its event */
                if (!handling) { fprintf(stderr, "controller_time: no time event at t = %g s\n", (n + 1) * H); return 1; }
                OK(fmi3EnterEventMode(c))
                OK(fmi3SetFloat64(c, in, N_IN, row(j, n + 1), N_IN))
                OK(fmi3UpdateDiscreteStates(c, &again, &terminate, &nominals, &values, &defined, &next))
            }
            OK(fmi3GetFloat64(c, out, N_OUT, j->out, N_OUT))
            if (event) OK(fmi3EnterStepMode(c))
        }
        j->ns[n] = now_ns() - t0;
    }
    OK(fmi3Terminate(c))
    fmi3FreeInstance(c);
    return 0;
}

static int run_law(job *j, const char *settings_file)
{
    size_t size;
    char *bytes = slurp(settings_file, &size);
    if (!bytes) return usage("PATH", settings_file, "a readable file of controller settings");
    if (size != sizeof(tapmp_controller_settings)) {
        fprintf(stderr, "controller_time: PATH = '%s' is invalid: allowed is a file of %zu bytes (one "
                "tapmp_controller_settings), it has %zu\n", settings_file, sizeof(tapmp_controller_settings), size);
        return 2;
    }
    tapmp_controller_settings s;
    memcpy(&s, bytes, sizeof s);
    free(bytes);
    s.k.law = j->law;
    const char *name, *allowed;
    double value;
    if (tapmp_controller_settings_check(&s, &name, &value, &allowed)) {
        fprintf(stderr, "controller_time: %s = %g is invalid: allowed is %s\n", name, value, allowed);
        return 2;
    }
    tapmp_controller_state st = {{0, 0, 0}, {0, 0, 0}, 0};
    double arg;
    const double *r = row(j, 0);
    if (!tapmp_controller_sample(&s.p, &s.g, s.k.law, s.k.velocity_source, s.k.force_limit, s.k.anti_windup,
                                 s.k.anti_windup_time, &st, s.k.T_s, r, r + 9, r + 12, 0, j->out, &st, &arg))
        return 1;
    for (long n = 0; n < j->samples; n++) {
        r = row(j, n);
        int64_t t0 = now_ns();
        int ok = tapmp_controller_sample(&s.p, &s.g, s.k.law, s.k.velocity_source, s.k.force_limit, s.k.anti_windup,
                                         s.k.anti_windup_time, &st, s.k.T_s, r, r + 9, r + 12, 1, j->out, &st, &arg);
        j->ns[n] = now_ns() - t0;
        if (!ok) { fprintf(stderr, "controller_time: the sample at t = %g s left the kinematic domain\n", n * H); return 1; }
    }
    return 0;
}

int main(int argc, char **argv)
{
    if (argc != 7) {
        fprintf(stderr, "usage: controller_time MODE PATH INPUTS SAMPLES LAW OUT (%d arguments given, 6 needed)\n",
                argc - 1);
        return 2;
    }
    const char *mode = argv[1], *path = argv[2];
    static const char *MODES[] = {"fmi2", "fmi3", "fmi3-event", "fmi3-clocked", "law"};
    int m = -1;
    for (int i = 0; i < 5; i++) if (strcmp(mode, MODES[i]) == 0) m = i;
    if (m < 0) return usage("MODE", mode, "one of fmi2, fmi3, fmi3-event, fmi3-clocked, law");
    char *end;
    errno = 0;
    long samples = strtol(argv[4], &end, 10);
    if (errno || *end || end == argv[4] || samples < 1 || samples > 1000000000L)
        return usage("SAMPLES", argv[4], "an integer in [1, 1000000000]");
    long law = strtol(argv[5], &end, 10);
    if (*end || end == argv[5] || law < TAPMP_SCDC || law > TAPMP_PIDDC)
        return usage("LAW", argv[5], "0 (SC-DC), 1 (APD-DC) or 2 (PID-DC)");
    size_t size;
    char *inputs = slurp(argv[3], &size);
    if (!inputs || size == 0 || size % (N_IN * sizeof(double)))
        return usage("INPUTS", argv[3], "a file of rows of 15 doubles, at least one row");
    job j = {(const double *)inputs, size / (N_IN * sizeof(double)), samples, (int)law, NULL, {0}};
    if (!(j.ns = malloc((size_t)samples * sizeof *j.ns))) { fprintf(stderr, "controller_time: out of memory\n"); return 1; }
    int rc;
    if (m == 4) {
        rc = run_law(&j, path);
    } else {
        char md_path[4200], id[256];
        snprintf(md_path, sizeof md_path, "%s/modelDescription.xml", path);
        char *md = slurp(md_path, &size);
        if (!md) return usage("PATH", path, "an unzipped FMU (a folder with modelDescription.xml)");
        int v3 = strstr(md, "fmiVersion=\"3.0\"") != NULL;
        if ((m == 0) == v3)
            return usage("PATH", path, m == 0 ? "an FMI 2.0 FMU for MODE fmi2" : "an FMI 3.0 FMU for the fmi3 modes");
        if (!attribute(md, "<CoSimulation", NULL, "modelIdentifier", id, sizeof id))
            return usage("PATH", path, "a co-simulation FMU");
        rc = m == 0 ? run_fmi2(&j, path, md, id) : run_fmi3(&j, path, md, id, m == 2, m == 3);
        free(md);
    }
    if (rc) return rc;
    /* written only after a whole run: a failed run leaves no file of durations */
    FILE *out = fopen(argv[6], "wb");
    if (!out) return usage("OUT", argv[6], "a file that can be written");
    if (fwrite(j.ns, sizeof *j.ns, (size_t)samples, out) != (size_t)samples) rc = 1;
    if (fclose(out) != 0) rc = 1;
    if (rc == 0) printf("%.17g %.17g %.17g\n", j.out[0], j.out[1], j.out[2]);
    return rc;
}
