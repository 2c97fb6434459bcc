/* A small FMI 3.0 host in C (Linux) that runs a closed loop of co-simulation FMUs, one of which has a
 * periodic input clock, the way tests/engine/master/test_master_clocks.py's master does with a macro step
 * of one clock interval. Used by tests/fmu/test_controller_clocked_c_host.py. Usage:
 *   fmi3_clocked_loop STEPS DIR:MODEL_IDENTIFIER ... -- SRC.OUTPUT:DST.INPUT ... -- ELEMENT.OUTPUT ...
 * Elements are numbered by their order on the command line (0, 1, ...), the order they leave
 * initialization in. An element whose modelDescription declares a <Clock> (one, the first found) is
 * instantiated with eventModeUsed = true and earlyReturnAllowed = false (it has no time events of its own),
 * the others with both false. Its clock ticks at t0 + k interval (fmi3GetIntervalDecimal after
 * initialization, t0 = 0); the macro step h is that interval.
 *
 * Each macro step from t = n h: first, if n > 0, the tick at t: fmi3EnterEventMode, fmi3SetClock, its inputs
 * (fmi3SetFloat64 from the outputs read last), fmi3UpdateDiscreteStates, its outputs (fmi3GetFloat64),
 * fmi3EnterStepMode; then every element in the step order (the clocked element first, then the others in
 * command-line order): inputs, fmi3DoStep(t, h), outputs. Initialization: every element instantiated and in
 * Initialization Mode, every output read, then per element: inputs, fmi3ExitInitializationMode (the clocked
 * one: the tick at t0 in the Event Mode it is in now, update, fmi3EnterStepMode), outputs.
 *
 * Prints, at t0 and after each step, the time and the requested outputs (%.17g, space separated, one line per
 * time). Exit code: 0 on success, 1 on any failed call, 2 on bad usage. */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"

#define MAX_ELEMENTS 8
#define MAX_LINKS 64
#define MAX_VR 512

typedef struct {
    char dir[2048], id[256], md[1 << 16];
    void *lib;
    fmi3Instance c;
    int clocked;
    fmi3ValueReference clock;
    double cache[MAX_VR];  /* outputs read last, by value reference */
    fmi3InstantiateCoSimulationTYPE *InstantiateCoSimulation;
    fmi3EnterInitializationModeTYPE *EnterInitializationMode;
    fmi3ExitInitializationModeTYPE *ExitInitializationMode;
    fmi3SetFloat64TYPE *SetFloat64;
    fmi3GetFloat64TYPE *GetFloat64;
    fmi3DoStepTYPE *DoStep;
    fmi3EnterEventModeTYPE *EnterEventMode;
    fmi3EnterStepModeTYPE *EnterStepMode;
    fmi3UpdateDiscreteStatesTYPE *UpdateDiscreteStates;
    fmi3SetClockTYPE *SetClock;
    fmi3GetIntervalDecimalTYPE *GetIntervalDecimal;
    fmi3TerminateTYPE *Terminate;
    fmi3FreeInstanceTYPE *FreeInstance;
} element;

typedef struct { int src, dst; fmi3ValueReference out, in; } link;

static element E[MAX_ELEMENTS];
static link L[MAX_LINKS];
static int n_elements, n_links;

static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env;
    fprintf(stderr, "[c_host %d %s] %s\n", (int)status, category, message);
}

/* The value of attribute `attr` (e.g. "valueReference") of the variable element named `name` in md. */
static const char *attribute_of(const char *md, const char *name, const char *attr, char *value, size_t size)
{
    char key[300], akey[64];
    snprintf(key, sizeof key, " name=\"%s\"", name);
    snprintf(akey, sizeof akey, " %s=\"", attr);
    const char *at = strstr(md, key);
    if (!at) return NULL;
    const char *start = at;
    while (start > md && *start != '<') start--;  /* the element's start */
    const char *end = strchr(at, '>');
    const char *a = strstr(start, akey);
    if (!a || !end || a > end) return NULL;
    a += strlen(akey);
    const char *q = strchr(a, '"');
    if (!q || (size_t)(q - a) >= size) return NULL;
    memcpy(value, a, (size_t)(q - a));
    value[q - a] = '\0';
    return value;
}

static int vr_of(const element *e, const char *name, fmi3ValueReference *vr)
{
    char v[32];
    if (!attribute_of(e->md, name, "valueReference", v, sizeof v)) {
        fprintf(stderr, "no variable %s in %s\n", name, e->id);
        return 0;
    }
    *vr = (fmi3ValueReference)strtoul(v, NULL, 10);
    return *vr < MAX_VR;
}

/* "ELEMENT.NAME" -> element index and value reference */
static int endpoint(const char *text, int *el, fmi3ValueReference *vr)
{
    const char *dot = strchr(text, '.');
    if (!dot) return 0;
    *el = atoi(text);
    if (*el < 0 || *el >= n_elements) return 0;
    return vr_of(&E[*el], dot + 1, vr);
}

#define LOAD(e, name)                                                                      \
    if (!((e)->name = (fmi3##name##TYPE *)dlsym((e)->lib, "fmi3" #name))) {                 \
        fprintf(stderr, "missing fmi3" #name " in %s\n", (e)->id); return 0; }
#define CHECK(call)                                                                        \
    if ((call) > fmi3Warning) { fprintf(stderr, "%s failed\n", #call); return 1; }

static int load(element *e)
{
    char path[4096], md[4200];
    snprintf(md, sizeof md, "%s/modelDescription.xml", e->dir);
    FILE *f = fopen(md, "rb");
    if (!f) { fprintf(stderr, "cannot read %s\n", md); return 0; }
    size_t n = fread(e->md, 1, sizeof e->md - 1, f);
    fclose(f);
    e->md[n] = '\0';
    snprintf(path, sizeof path, "%s/binaries/x86_64-linux/%s.so", e->dir, e->id);
    if (!(e->lib = dlopen(path, RTLD_NOW | RTLD_LOCAL))) { fprintf(stderr, "dlopen: %s\n", dlerror()); return 0; }
    LOAD(e, InstantiateCoSimulation) LOAD(e, EnterInitializationMode) LOAD(e, ExitInitializationMode)
    LOAD(e, SetFloat64) LOAD(e, GetFloat64) LOAD(e, DoStep) LOAD(e, EnterEventMode) LOAD(e, EnterStepMode)
    LOAD(e, UpdateDiscreteStates) LOAD(e, SetClock) LOAD(e, GetIntervalDecimal) LOAD(e, Terminate)
    LOAD(e, FreeInstance)
    const char *clock = strstr(e->md, "<Clock ");
    if (clock) {
        char v[32];
        const char *vr = strstr(clock, " valueReference=\"");
        if (!vr || sscanf(vr, " valueReference=\"%31[0-9]", v) != 1) return 0;
        e->clocked = 1;
        e->clock = (fmi3ValueReference)strtoul(v, NULL, 10);
    }
    char token[256];
    const char *t = strstr(e->md, " instantiationToken=\"");
    if (!t || sscanf(t, " instantiationToken=\"%255[^\"]", token) != 1) return 0;
    char resources[4200];
    snprintf(resources, sizeof resources, "%s/resources/", e->dir);
    e->c = e->InstantiateCoSimulation(e->id, token, resources, fmi3False, fmi3True, e->clocked ? fmi3True : fmi3False,
                                      fmi3False, NULL, 0, NULL, logger, NULL);
    if (!e->c) { fprintf(stderr, "fmi3InstantiateCoSimulation of %s failed\n", e->id); return 0; }
    return 1;
}

static fmi3Status inputs(int k)
{
    fmi3Status worst = fmi3OK;
    for (int i = 0; i < n_links; i++) {
        if (L[i].dst != k) continue;
        fmi3Float64 v = E[L[i].src].cache[L[i].out];
        fmi3Status s = E[k].SetFloat64(E[k].c, &L[i].in, 1, &v, 1);
        if (s > worst) worst = s;
    }
    return worst;
}

static fmi3Status outputs(int k, const fmi3ValueReference *extra, int n_extra)
{
    fmi3Status worst = fmi3OK;
    for (int i = 0; i < n_links + n_extra; i++) {
        fmi3ValueReference vr;
        if (i < n_links) {
            if (L[i].src != k) continue;
            vr = L[i].out;
        } else {
            vr = extra[i - n_links];
        }
        fmi3Status s = E[k].GetFloat64(E[k].c, &vr, 1, &E[k].cache[vr], 1);
        if (s > worst) worst = s;
    }
    return worst;
}

/* The tick at the current time: Event Mode, the clock, inputs, update, outputs, Step Mode. */
static int tick(int k, int enter, const fmi3ValueReference *extra, int n_extra)
{
    element *e = &E[k];
    fmi3Clock active = fmi3ClockActive;
    fmi3Boolean again = fmi3False, terminate, nominals, values, defined;
    fmi3Float64 next;
    if (enter) CHECK(e->EnterEventMode(e->c));
    CHECK(e->SetClock(e->c, &e->clock, 1, &active));
    CHECK(inputs(k));
    CHECK(e->UpdateDiscreteStates(e->c, &again, &terminate, &nominals, &values, &defined, &next));
    if (again || terminate) { fprintf(stderr, "fmi3UpdateDiscreteStates asks for more\n"); return 1; }
    CHECK(outputs(k, extra, n_extra));
    CHECK(e->EnterStepMode(e->c));
    return 0;
}

int main(int argc, char **argv)
{
    if (argc < 3) return 2;
    int steps = atoi(argv[1]), a = 2;
    for (; a < argc && strcmp(argv[a], "--") != 0; a++) {
        char *colon = strrchr(argv[a], ':');
        if (!colon || n_elements == MAX_ELEMENTS) return 2;
        element *e = &E[n_elements++];
        snprintf(e->dir, sizeof e->dir, "%.*s", (int)(colon - argv[a]), argv[a]);
        snprintf(e->id, sizeof e->id, "%s", colon + 1);
        if (!load(e)) return 1;
    }
    for (a++; a < argc && strcmp(argv[a], "--") != 0; a++) {  /* SRC.OUT:DST.IN */
        char src[300], *colon = strchr(argv[a], ':');
        if (!colon || n_links == MAX_LINKS) return 2;
        snprintf(src, sizeof src, "%.*s", (int)(colon - argv[a]), argv[a]);
        link *l = &L[n_links++];
        if (!endpoint(src, &l->src, &l->out) || !endpoint(colon + 1, &l->dst, &l->in)) return 2;
    }
    int printed[MAX_VR], printed_el[MAX_VR], n_printed = 0;
    fmi3ValueReference extra[MAX_ELEMENTS][MAX_VR];
    int n_extra[MAX_ELEMENTS] = {0};
    for (a++; a < argc && n_printed < MAX_VR; a++) {
        int el;
        fmi3ValueReference vr;
        if (!endpoint(argv[a], &el, &vr)) return 2;
        printed_el[n_printed] = el;
        printed[n_printed++] = (int)vr;
        extra[el][n_extra[el]++] = vr;
    }
    int clocked = -1;
    for (int k = 0; k < n_elements; k++)
        if (E[k].clocked) clocked = k;
    if (clocked < 0) { fprintf(stderr, "no element has a clock\n"); return 2; }
    /* step order: the clocked element first (it samples the others' outputs of t), then the others (in a
     * loop where only the clocked element reads the others, their order changes nothing) */
    int order[MAX_ELEMENTS], n_order = 0;
    order[n_order++] = clocked;
    for (int k = 0; k < n_elements; k++)
        if (k != clocked) order[n_order++] = k;

    for (int k = 0; k < n_elements; k++)
        CHECK(E[k].EnterInitializationMode(E[k].c, fmi3False, 0.0, 0.0, fmi3False, 0.0));
    for (int k = 0; k < n_elements; k++) CHECK(outputs(k, extra[k], n_extra[k]));
    double h = 0.0;
    for (int k = 0; k < n_elements; k++) {
        CHECK(inputs(k));
        CHECK(E[k].ExitInitializationMode(E[k].c));
        if (k == clocked) {
            fmi3IntervalQualifier q;
            CHECK(E[k].GetIntervalDecimal(E[k].c, &E[k].clock, 1, &h, &q));
            if (tick(k, 0, extra[k], n_extra[k])) return 1;  /* the tick at t0, in the Event Mode after init */
        }
        CHECK(outputs(k, extra[k], n_extra[k]));
    }
    printf("%.17g", 0.0);
    for (int i = 0; i < n_printed; i++) printf(" %.17g", E[printed_el[i]].cache[printed[i]]);
    printf("\n");
    for (int n = 0; n < steps; n++) {
        double t = n * h;  /* t0 + k h, as the clocked FMU's grid and the master's clock compute it */
        if (n > 0 && tick(clocked, 1, extra[clocked], n_extra[clocked])) return 1;
        for (int i = 0; i < n_order; i++) {
            element *e = &E[order[i]];
            fmi3Boolean event = fmi3False, terminate = fmi3False, early = fmi3False;
            fmi3Float64 last = 0.0;
            CHECK(inputs(order[i]));
            CHECK(e->DoStep(e->c, t, h, fmi3True, &event, &terminate, &early, &last));
            if (terminate || early) { fprintf(stderr, "fmi3DoStep of %s stopped at %g\n", e->id, last); return 1; }
            CHECK(outputs(order[i], extra[order[i]], n_extra[order[i]]));
        }
        printf("%.17g", (n + 1) * h);
        for (int i = 0; i < n_printed; i++) printf(" %.17g", E[printed_el[i]].cache[printed[i]]);
        printf("\n");
    }
    for (int k = 0; k < n_elements; k++) {
        CHECK(E[k].Terminate(E[k].c));
        E[k].FreeInstance(E[k].c);
    }
    return 0;
}
