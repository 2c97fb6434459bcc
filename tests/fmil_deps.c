/* fmil_deps.c - print the ModelStructure dependencies of an FMU as FMI Library (FMIL) reads them.
 *
 *   fmil_deps FMU SCRATCH_DIR
 *
 * One line per unknown: "output NAME: KNOWN KNOWN ..." (the <Outputs>/<Output> entries) and
 * "initial NAME: KNOWN ..." (<InitialUnknowns>/<InitialUnknown>), the knowns by variable name;
 * "(all)" where FMIL reports that the unknown depends on every known (no information).
 * FMI 2.0 dependencies are 1-based variable indices, FMI 3.0 dependencies value references;
 * FMIL resolves both here. Exit code 0, or 1 with a message on stderr if FMIL cannot read the FMU.
 * Built by tests/test_fmil.py against ../shared/tools/fmil (FMIL 3.0.4).
 */
#include <stdio.h>
#include <stdlib.h>
#include "fmilib.h"

static void logger(jm_callbacks *c, jm_string module, jm_log_level_enu_t level, jm_string message)
{
    (void)c;
    if (level <= jm_log_level_warning) fprintf(stderr, "[%s] %s: %s\n", jm_log_level_to_string(level), module, message);
}

static void fmi2_print(fmi2_import_t *fmu, const char *what, fmi2_import_variable_list_t *unknowns,
                       fmi2_import_variable_list_t *all, size_t *start, size_t *dependency)
{
    size_t n = fmi2_import_get_variable_list_size(unknowns);
    for (size_t i = 0; i < n; i++) {
        printf("%s %s:", what, fmi2_import_get_variable_name(fmi2_import_get_variable(unknowns, i)));
        if (!start) { printf(" (all)\n"); continue; }
        for (size_t k = start[i]; k < start[i + 1]; k++) {
            if (dependency[k] == 0) printf(" (all)");
            else printf(" %s", fmi2_import_get_variable_name(fmi2_import_get_variable(all, dependency[k] - 1)));
        }
        printf("\n");
    }
    (void)fmu;
}

static int fmi3_print(fmi3_import_t *fmu, const char *what, fmi3_import_variable_list_t *unknowns, int initial)
{
    size_t n = fmi3_import_get_variable_list_size(unknowns);
    for (size_t i = 0; i < n; i++) {
        fmi3_import_variable_t *v = fmi3_import_get_variable(unknowns, i);
        size_t count = 0, *deps = NULL;
        int all = 0;
        char *kinds = NULL;
        int bad = initial ? fmi3_import_get_initial_unknown_dependencies(fmu, v, &count, &all, &deps, &kinds)
                          : fmi3_import_get_output_dependencies(fmu, v, &count, &all, &deps, &kinds);
        if (bad) { fprintf(stderr, "no dependency information for %s\n", fmi3_import_get_variable_name(v)); return 1; }
        printf("%s %s:", what, fmi3_import_get_variable_name(v));
        if (count == 0 && all) printf(" (all)");
        for (size_t k = 0; k < count; k++) {
            fmi3_import_variable_t *known = fmi3_import_get_variable_by_vr(fmu, (fmi3_value_reference_t)deps[k]);
            if (!known) { fprintf(stderr, "unknown value reference %zu\n", deps[k]); return 1; }
            printf(" %s", fmi3_import_get_variable_name(known));
        }
        printf("\n");
    }
    return 0;
}

int main(int argc, char **argv)
{
    if (argc != 3) { fprintf(stderr, "usage: fmil_deps FMU SCRATCH_DIR\n"); return 2; }
    jm_callbacks cb = {0};
    cb.malloc = malloc; cb.calloc = calloc; cb.realloc = realloc; cb.free = free;
    cb.logger = logger; cb.log_level = jm_log_level_warning; cb.context = 0;
    fmi_import_context_t *ctx = fmi_import_allocate_context(&cb);
    fmi_version_enu_t version = fmi_import_get_fmi_version(ctx, argv[1], argv[2]);
    int status = 0;
    if (version == fmi_version_2_0_enu) {
        fmi2_import_t *fmu = fmi2_import_parse_xml(ctx, argv[2], NULL);
        if (!fmu) { fprintf(stderr, "FMIL cannot parse %s\n", argv[1]); return 1; }
        fmi2_import_variable_list_t *all = fmi2_import_get_variable_list(fmu, 0);  /* in the order of the XML */
        fmi2_import_variable_list_t *outputs = fmi2_import_get_outputs_list(fmu);
        fmi2_import_variable_list_t *initial = fmi2_import_get_initial_unknowns_list(fmu);
        size_t *start, *dependency;
        char *kind;
        fmi2_import_get_outputs_dependencies(fmu, &start, &dependency, &kind);
        fmi2_print(fmu, "output", outputs, all, start, dependency);
        fmi2_import_get_initial_unknowns_dependencies(fmu, &start, &dependency, &kind);
        fmi2_print(fmu, "initial", initial, all, start, dependency);
        fmi2_import_free_variable_list(initial);
        fmi2_import_free_variable_list(outputs);
        fmi2_import_free_variable_list(all);
        fmi2_import_free(fmu);
    } else if (version == fmi_version_3_0_enu) {
        fmi3_import_t *fmu = fmi3_import_parse_xml(ctx, argv[2], NULL);
        if (!fmu) { fprintf(stderr, "FMIL cannot parse %s\n", argv[1]); return 1; }
        fmi3_import_variable_list_t *outputs = fmi3_import_get_outputs_list(fmu);
        fmi3_import_variable_list_t *initial = fmi3_import_get_initial_unknowns_list(fmu);
        status = fmi3_print(fmu, "output", outputs, 0) || fmi3_print(fmu, "initial", initial, 1);
        fmi3_import_free_variable_list(initial);
        fmi3_import_free_variable_list(outputs);
        fmi3_import_free(fmu);
    } else {
        fprintf(stderr, "%s: FMI version %s is not 2.0 or 3.0\n", argv[1], fmi_version_to_string(version));
        status = 1;
    }
    fmi_import_free_context(ctx);
    return status;
}
