/* The TAPMP closed loop of native FMI 2.0 FMUs stepped from C, with no Python in the
 * process: the cost of the co-simulation without a Python master, for
 * benchmarks/bench_cosim.py. Usage:
 *   c_master TRAJECTORY_DIR CONTROLLER_DIR PLANT_DIR STEPS ORDERING(gs|jacobi) [all]
 * (unzipped FMUs). Connections as in TAPMP.ssp (tapmp/interface.py): trajectory X_d..ddB_d
 * -> controller, plant q1..q3, dq1..dq3 -> controller, controller F1..F3 -> plant; the plant
 * starts on the reference (X0..dB0 = the trajectory's first outputs). With "all", every
 * output of every FMU is read after each step (39 values, as a master that records them all;
 * else only the 18 the connections need). Prints the wall
 * seconds of the stepping loop and the last true motor positions. */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2Functions.h"

typedef struct {
    void *lib;
    fmi2Component c;
    fmi2GetRealTYPE *get;
    fmi2SetRealTYPE *set;
    fmi2DoStepTYPE *step;
} unit;

static void logger(fmi2ComponentEnvironment e, fmi2String n, fmi2Status s, fmi2String c, fmi2String m, ...)
{
    (void)e, (void)c;
    va_list ap;
    va_start(ap, m);
    fprintf(stderr, "[%s %d] ", n, (int)s);
    vfprintf(stderr, m, ap);
    fputc('\n', stderr);
    va_end(ap);
}

static char *guid_of(const char *dir)
{
    static char guid[3][128];
    static int k;
    char path[4096], buf[1 << 16];
    snprintf(path, sizeof path, "%s/modelDescription.xml", dir);
    FILE *f = fopen(path, "r");
    if (!f) return NULL;
    size_t n = fread(buf, 1, sizeof buf - 1, f);
    fclose(f);
    buf[n] = 0;
    char *g = strstr(buf, "guid=\"");
    if (!g) return NULL;
    g += 6;
    char *end = strchr(g, '"');
    k = (k + 1) % 3;
    snprintf(guid[k], sizeof guid[k], "%.*s", (int)(end - g), g);
    return guid[k];
}

static int load(unit *u, const char *dir, const char *model, const fmi2CallbackFunctions *cb)
{
    char path[4096];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", dir, model);
    if (!(u->lib = dlopen(path, RTLD_NOW | RTLD_LOCAL))) return fprintf(stderr, "%s\n", dlerror()), 0;
    fmi2InstantiateTYPE *inst = (fmi2InstantiateTYPE *)dlsym(u->lib, "fmi2Instantiate");
    fmi2SetupExperimentTYPE *setup = (fmi2SetupExperimentTYPE *)dlsym(u->lib, "fmi2SetupExperiment");
    fmi2EnterInitializationModeTYPE *enter = (fmi2EnterInitializationModeTYPE *)dlsym(u->lib, "fmi2EnterInitializationMode");
    u->get = (fmi2GetRealTYPE *)dlsym(u->lib, "fmi2GetReal");
    u->set = (fmi2SetRealTYPE *)dlsym(u->lib, "fmi2SetReal");
    u->step = (fmi2DoStepTYPE *)dlsym(u->lib, "fmi2DoStep");
    u->c = inst(model, fmi2CoSimulation, guid_of(dir), "file:///", cb, fmi2False, fmi2False);
    return u->c && setup(u->c, fmi2False, 0.0, 0.0, fmi2False, 0.0) == fmi2OK && enter(u->c) == fmi2OK;
}

static int exit_init(unit *u)
{
    fmi2ExitInitializationModeTYPE *f = (fmi2ExitInitializationModeTYPE *)dlsym(u->lib, "fmi2ExitInitializationMode");
    return f(u->c) == fmi2OK;
}

int main(int argc, char **argv)
{
    if (argc != 6 && !(argc == 7 && strcmp(argv[6], "all") == 0))
        return fprintf(stderr, "usage: c_master TRAJ CTRL PLANT STEPS gs|jacobi [all]\n"), 2;
    int all = argc == 7;
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    unit tr, ct, pl;
    long steps = atol(argv[4]);
    int gs = strcmp(argv[5], "gs") == 0;
    if (!load(&tr, argv[1], "TAPMP_Trajectory", &cb) || !load(&ct, argv[2], "TAPMP_Controller", &cb) ||
        !load(&pl, argv[3], "TAPMP_Plant", &cb)) return 1;
    /* value references (tapmp/interface.py): trajectory outputs 0..11; controller inputs
     * X_d..ddB_d 0..8, q 9..11, dq 12..14, outputs F 15..17; plant F 0..2, q 3..5,
     * q_true 6..8, dq 9..11, X..dB 12..17, X0..B0 and dX0..dB0 parameters 25..30 */
    const fmi2ValueReference ref_vr[9] = {0, 1, 2, 3, 4, 5, 6, 7, 8}, q_vr[6] = {3, 4, 5, 9, 10, 11},
                             cq_vr[6] = {9, 10, 11, 12, 13, 14}, F_vr[3] = {15, 16, 17}, pF_vr[3] = {0, 1, 2},
                             init_vr[6] = {25, 26, 27, 28, 29, 30}, qt_vr[3] = {6, 7, 8};
    /* every output: trajectory 0..11, controller 15..26, plant 3..17 */
    const fmi2ValueReference tr_all[12] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11},
                             ct_all[12] = {15, 16, 17, 18, 19, 20, 21, 22, 23, 24, 25, 26},
                             pl_all[15] = {3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17};
    double ref[9], q[6], F[3], qt[3], tr_out[12], ct_out[12], pl_out[15];
    tr.get(tr.c, ref_vr, 9, ref);
    double init[6] = {ref[0], ref[1], ref[2], ref[3], ref[4], ref[5]};
    if (pl.set(pl.c, init_vr, 6, init) != fmi2OK) return 1;
    pl.get(pl.c, q_vr, 6, q);
    ct.set(ct.c, ref_vr, 9, ref);
    ct.set(ct.c, cq_vr, 6, q);
    if (!exit_init(&tr) || !exit_init(&ct)) return 1;
    ct.get(ct.c, F_vr, 3, F);
    pl.set(pl.c, pF_vr, 3, F);
    if (!exit_init(&pl)) return 1;
    pl.get(pl.c, q_vr, 6, q);
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    const double h = 1e-4;
    for (long k = 0; k < steps; k++) {
        double t = k * h;
        ct.set(ct.c, ref_vr, 9, ref);
        ct.set(ct.c, cq_vr, 6, q);
        if (gs) {
            if (ct.step(ct.c, t, h, fmi2True) != fmi2OK) return 1;
            ct.get(ct.c, F_vr, 3, F);
            pl.set(pl.c, pF_vr, 3, F);
            if (pl.step(pl.c, t, h, fmi2True) != fmi2OK || tr.step(tr.c, t, h, fmi2True) != fmi2OK) return 1;
        } else {
            pl.set(pl.c, pF_vr, 3, F);
            if (tr.step(tr.c, t, h, fmi2True) != fmi2OK || ct.step(ct.c, t, h, fmi2True) != fmi2OK ||
                pl.step(pl.c, t, h, fmi2True) != fmi2OK) return 1;
            ct.get(ct.c, F_vr, 3, F);
        }
        if (all) {
            tr.get(tr.c, tr_all, 12, tr_out);
            ct.get(ct.c, ct_all, 12, ct_out);
            pl.get(pl.c, pl_all, 15, pl_out);
            memcpy(ref, tr_out, sizeof ref);
            memcpy(q, pl_out, 3 * sizeof(double));
            memcpy(q + 3, pl_out + 6, 3 * sizeof(double));
        } else {
            tr.get(tr.c, ref_vr, 9, ref);
            pl.get(pl.c, q_vr, 6, q);
        }
    }
    clock_gettime(CLOCK_MONOTONIC, &t1);
    pl.get(pl.c, qt_vr, 3, qt);
    printf("%.6f\n%.17g %.17g %.17g\n", (t1.tv_sec - t0.tv_sec) + 1e-9 * (t1.tv_nsec - t0.tv_nsec), qt[0], qt[1], qt[2]);
    return 0;
}
