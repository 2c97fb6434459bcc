/* Reads binaries/<platform>/python-env.txt, written at build time: which Python the FMU
 * runs in when its host process has none (a C host). One "key=value" per line:
 *   libpython=/abs/path/libpython3.X.so.1.0   home=/python/prefix   path=/site-packages/dir
 * (path may repeat). Lines starting with '#' are comments. Shared by both binaries. */
#ifndef TAPMP_PYTHON_ENV_H
#define TAPMP_PYTHON_ENV_H

#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define TAPMP_PATH_MAX 4096

/* Directory holding the shared object that contains `symbol`, with a trailing '/'. */
static int tapmp_binary_dir(const void *symbol, char *dir, size_t size)
{
    Dl_info info;
    if (!dladdr(symbol, &info) || !info.dli_fname) return 0;
    const char *slash = strrchr(info.dli_fname, '/');
    size_t n = slash ? (size_t)(slash - info.dli_fname + 1) : 0;
    if (n + 1 > size) return 0;
    memcpy(dir, info.dli_fname, n);
    dir[n] = '\0';
    return 1;
}

/* Calls visit(key, value, ctx) for every entry of python-env.txt in `dir`; 0 if unreadable. */
static int tapmp_read_python_env(const char *dir, void (*visit)(const char *, const char *, void *),
                                 void *ctx)
{
    char path[TAPMP_PATH_MAX + 32], line[TAPMP_PATH_MAX];
    snprintf(path, sizeof path, "%spython-env.txt", dir);
    FILE *f = fopen(path, "r");
    if (!f) return 0;
    while (fgets(line, sizeof line, f)) {
        line[strcspn(line, "\r\n")] = '\0';
        char *eq = strchr(line, '=');
        if (line[0] == '#' || !eq) continue;
        *eq = '\0';
        visit(line, eq + 1, ctx);
    }
    fclose(f);
    return 1;
}

#endif
