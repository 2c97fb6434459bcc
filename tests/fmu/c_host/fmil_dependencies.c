/* Prints the ModelStructure dependencies of FMI 2.0 / 3.0 FMUs as FMI Library (FMIL) reads them:
 *
 *   fmil_dependencies WORKDIR FMU...
 *
 * one line per unknown, "<fmu> O|I <variable>:" followed by the names of the knowns it depends
 * on (O: <Outputs>/<Output>, I: <InitialUnknowns>/<InitialUnknown>), or " ALL" when FMIL
 * reports a dependency on every known (no dependency information). Exit 1 if an FMU cannot
 * be read. WORKDIR must exist. Built and run by tests/fmu/test_dependencies.py against the FMIL in ../shared/tools/fmil. */
#define _POSIX_C_SOURCE 200809L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "fmilib.h"

static void quiet(jm_callbacks *c, jm_string module, jm_log_level_enu_t level, jm_string message)
{
    (void)c;
    if (level <= jm_log_level_warning) fprintf(stderr, "[FMIL %s] %s\n", module, message);
}

static void fmi2_rows(fmi2_import_t *fmu, const char *path, const char *tag, fmi2_import_variable_list_t *unknowns,
                      int initial)
{
    size_t *start = NULL, *dep = NULL;
    char *kind = NULL;
    fmi2_import_variable_list_t *all = fmi2_import_get_variable_list(fmu, 0);
    if (initial) fmi2_import_get_initial_unknowns_dependencies(fmu, &start, &dep, &kind);
    else fmi2_import_get_outputs_dependencies(fmu, &start, &dep, &kind);
    for (size_t i = 0; i < fmi2_import_get_variable_list_size(unknowns); i++) {
        printf("%s %s %s:", path, tag, fmi2_import_get_variable_name(fmi2_import_get_variable(unknowns, i)));
        if (!start) {
            printf(" ALL\n");
            continue;
        }
        for (size_t j = start[i]; j < start[i + 1]; j++) {
            if (dep[j] == 0) printf(" ALL");
            else printf(" %s", fmi2_import_get_variable_name(fmi2_import_get_variable(all, dep[j] - 1)));
        }
        printf("\n");
    }
    fmi2_import_free_variable_list(all);
}

typedef int (*fmi3_deps)(fmi3_import_t *, fmi3_import_variable_t *, size_t *, int *, size_t **, char **);

static void fmi3_rows(fmi3_import_t *fmu, const char *path, const char *tag, fmi3_import_variable_list_t *unknowns,
                      fmi3_deps get)
{
    for (size_t i = 0; i < fmi3_import_get_variable_list_size(unknowns); i++) {
        fmi3_import_variable_t *v = fmi3_import_get_variable(unknowns, i);
        size_t n = 0, *dep = NULL;
        int all = 0;
        char *kind = NULL;
        printf("%s %s %s:", path, tag, fmi3_import_get_variable_name(v));
        if (get(fmu, v, &n, &all, &dep, &kind) != 0) {
            printf(" ERROR\n");
            continue;
        }
        if (n == 0 && all) printf(" ALL");
        for (size_t j = 0; j < n; j++)
            printf(" %s", fmi3_import_get_variable_name(fmi3_import_get_variable_by_vr(fmu, (fmi3_value_reference_t)dep[j])));
        printf("\n");
    }
}

int main(int argc, char **argv)
{
    if (argc < 3) {
        fprintf(stderr, "usage: fmil_dependencies WORKDIR FMU...\n");
        return 2;
    }
    jm_callbacks cb = {malloc, calloc, realloc, free, quiet, jm_log_level_warning, NULL, {0}};
    fmi_import_context_t *ctx = fmi_import_allocate_context(&cb);
    int rc = 0;
    for (int a = 2; a < argc; a++) {
        char dir[4096];
        snprintf(dir, sizeof dir, "%s/%d", argv[1], a);
        mkdir(dir, 0755);  /* FMIL unpacks into an existing folder */
        fmi_version_enu_t version = fmi_import_get_fmi_version(ctx, argv[a], dir);
        if (version == fmi_version_2_0_enu) {
            fmi2_import_t *fmu = fmi2_import_parse_xml(ctx, dir, NULL);
            if (!fmu) { rc = 1; continue; }
            fmi2_import_variable_list_t *outs = fmi2_import_get_outputs_list(fmu);
            fmi2_import_variable_list_t *init = fmi2_import_get_initial_unknowns_list(fmu);
            fmi2_rows(fmu, argv[a], "O", outs, 0);
            fmi2_rows(fmu, argv[a], "I", init, 1);
            fmi2_import_free_variable_list(outs);
            fmi2_import_free_variable_list(init);
            fmi2_import_free(fmu);
        } else if (version == fmi_version_3_0_enu) {
            fmi3_import_t *fmu = fmi3_import_parse_xml(ctx, dir, NULL);
            if (!fmu) { rc = 1; continue; }
            fmi3_import_variable_list_t *outs = fmi3_import_get_outputs_list(fmu);
            fmi3_import_variable_list_t *init = fmi3_import_get_initial_unknowns_list(fmu);
            fmi3_rows(fmu, argv[a], "O", outs, fmi3_import_get_output_dependencies);
            fmi3_rows(fmu, argv[a], "I", init, fmi3_import_get_initial_unknown_dependencies);
            fmi3_import_free_variable_list(outs);
            fmi3_import_free_variable_list(init);
            fmi3_import_free(fmu);
        } else {
            fprintf(stderr, "%s: not an FMI 2.0 or 3.0 FMU\n", argv[a]);
            rc = 1;
        }
    }
    fmi_import_free_context(ctx);
    return rc;
}
