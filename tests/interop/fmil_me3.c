/* An FMI 3.0 Model Exchange host on FMI Library (FMIL 3.0.4, ../shared/tools/fmil), compiled by
 * tests/interop/test_model_exchange.py: FMIL loads the FMU for Model Exchange, and the host integrates
 * its continuous states with the classic fixed-step RK4 (the Co-Simulation plant's method, one step
 * per output interval), through FMIL's wrappers of the FMI 3.0 Model Exchange functions.
 *
 *   fmil_me3 FMU UNPACK_DIR OUT.csv STOP H
 *
 * OUT.csv: time and the continuous states at 0, H, ..., STOP. FMIL's own log messages go to stderr
 * as "[FMIL] LEVEL MODULE: MESSAGE"; a failed call prints "error: CALL failed" and exits 1; a time
 * event inside the run (the FMU's nextEventTime) exits 1 too (this host does not handle one). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmilib.h"

static void logger(jm_callbacks *c, jm_string module, jm_log_level_enu_t level, jm_string message)
{
    (void)c;
    if (level <= jm_log_level_warning)
        fprintf(stderr, "[FMIL me3] %s %s: %s\n", jm_log_level_to_string(level), module, message);
}

static void fmu_log(fmi3_instance_environment_t env, fmi3_status_t status, fmi3_string_t category,
                    fmi3_string_t message)
{
    (void)env;
    if (status != fmi3_status_ok) fprintf(stderr, "[FMU] %d %s: %s\n", (int)status, category, message);
}

#define CALL(x) do { if ((x) != fmi3_status_ok) { fprintf(stderr, "error: %s failed\n", #x); return 1; } } while (0)

static fmi3_import_t *fmu;
static size_t nx;

/* dx = f(t, x) through the FMU */
static int rhs(double t, const double *x, double *dx)
{
    CALL(fmi3_import_set_time(fmu, t));
    CALL(fmi3_import_set_continuous_states(fmu, x, nx));
    CALL(fmi3_import_get_derivatives(fmu, dx, nx));
    return 0;
}

int main(int argc, char **argv)
{
    if (argc != 6) {
        fprintf(stderr, "usage: fmil_me3 FMU UNPACK_DIR OUT.csv STOP H\n");
        return 2;
    }
    double stop = atof(argv[4]), h = atof(argv[5]);
    jm_callbacks cb = {malloc, calloc, realloc, free, logger, jm_log_level_warning, NULL, ""};
    fmi_import_context_t *ctx = fmi_import_allocate_context(&cb);
    if (fmi_import_get_fmi_version(ctx, argv[1], argv[2]) != fmi_version_3_0_enu) {
        fprintf(stderr, "error: not an FMI 3.0 FMU\n");
        return 1;
    }
    fmu = fmi3_import_parse_xml(ctx, argv[2], NULL);
    if (!fmu) return 1;
    if (!(fmi3_import_get_fmu_kind(fmu) & fmi3_fmu_kind_me)) {
        fprintf(stderr, "error: FMIL finds no Model Exchange interface\n");
        return 1;
    }
    fmi3_import_variable_list_t *ders = fmi3_import_get_continuous_state_derivatives_list(fmu);
    size_t n_ders = fmi3_import_get_variable_list_size(ders);
    printf("kind ModelExchange and CoSimulation: %s, model identifiers ME %s CS %s, state derivatives %zu\n",
           (fmi3_import_get_fmu_kind(fmu) & fmi3_fmu_kind_cs) ? "yes" : "no", fmi3_import_get_model_identifier_ME(fmu),
           fmi3_import_get_model_identifier_CS(fmu), n_ders);
    if (fmi3_import_create_dllfmu(fmu, fmi3_fmu_kind_me, NULL, fmu_log) != jm_status_success) {
        fprintf(stderr, "error: create_dllfmu: %s\n", fmi3_import_get_last_error(fmu));
        return 1;
    }
    if (fmi3_import_instantiate_model_exchange(fmu, "me", NULL, fmi3_false, fmi3_true) != jm_status_success) {
        fprintf(stderr, "error: instantiate_model_exchange failed\n");
        return 1;
    }
    CALL(fmi3_import_get_number_of_continuous_states(fmu, &nx));
    printf("continuous states %zu\n", nx);
    if (nx != n_ders || nx == 0) return 1;
    CALL(fmi3_import_enter_initialization_mode(fmu, fmi3_false, 0.0, 0.0, fmi3_true, stop));
    CALL(fmi3_import_exit_initialization_mode(fmu));
    fmi3_boolean_t again = fmi3_true, terminate, nominals, values, defined;
    fmi3_float64_t next = 0.0;
    while (again) CALL(fmi3_import_update_discrete_states(fmu, &again, &terminate, &nominals, &values, &defined, &next));
    if (defined && next <= stop) {
        fprintf(stderr, "error: a time event at t = %g s: this host handles none\n", next);
        return 1;
    }
    CALL(fmi3_import_enter_continuous_time_mode(fmu));
    double *x = calloc(nx, sizeof *x), *k1 = calloc(nx, sizeof *x), *k2 = calloc(nx, sizeof *x);
    double *k3 = calloc(nx, sizeof *x), *k4 = calloc(nx, sizeof *x), *tmp = calloc(nx, sizeof *x);
    CALL(fmi3_import_get_continuous_states(fmu, x, nx));
    FILE *out = fopen(argv[3], "w");
    long n = lround(stop / h);
    for (long k = 0; k <= n; k++) {
        double t = k * h;
        fprintf(out, "%.17g", t);
        for (size_t i = 0; i < nx; i++) fprintf(out, ",%.17g", x[i]);
        fprintf(out, "\n");
        if (k == n) break;
        if (rhs(t, x, k1)) return 1;
        for (size_t i = 0; i < nx; i++) tmp[i] = x[i] + 0.5 * h * k1[i];
        if (rhs(t + 0.5 * h, tmp, k2)) return 1;
        for (size_t i = 0; i < nx; i++) tmp[i] = x[i] + 0.5 * h * k2[i];
        if (rhs(t + 0.5 * h, tmp, k3)) return 1;
        for (size_t i = 0; i < nx; i++) tmp[i] = x[i] + h * k3[i];
        if (rhs(t + h, tmp, k4)) return 1;
        for (size_t i = 0; i < nx; i++) x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        CALL(fmi3_import_set_time(fmu, t + h));
        CALL(fmi3_import_set_continuous_states(fmu, x, nx));
        fmi3_boolean_t enter_event, stop_now;
        CALL(fmi3_import_completed_integrator_step(fmu, fmi3_true, &enter_event, &stop_now));
        if (enter_event || stop_now) {
            fprintf(stderr, "error: completedIntegratorStep asks for an event at t = %g s\n", t + h);
            return 1;
        }
    }
    fclose(out);
    CALL(fmi3_import_terminate(fmu));
    fmi3_import_free_instance(fmu);
    fmi3_import_destroy_dllfmu(fmu);
    fmi3_import_free_variable_list(ders);
    fmi3_import_free(fmu);
    fmi_import_free_context(ctx);
    free(x), free(k1), free(k2), free(k3), free(k4), free(tmp);
    printf("FMIL Model Exchange run: %ld RK4 steps\n", n);
    return 0;
}
