/* uri_to_path (fmu_common/pyfront/uri.h, the pythonfmu FMUs' fmuResourceLocation) on the URIs
 * given as arguments, each copied into a heap block of exactly its length, so that
 * AddressSanitizer reports any read past the terminating zero. Prints one line per URI:
 * "<uri> -> <path>" or "<uri> -> refused". Built and run by tests/fmu/test_fmu_threads.py. */
#include <stdio.h>
#include <stdlib.h>

#include "uri.h"

int main(int argc, char **argv)
{
    for (int i = 1; i < argc; i++) {
        size_t n = strlen(argv[i]) + 1;
        char *uri = malloc(n), path[64];
        if (!uri) return 1;
        memcpy(uri, argv[i], n);
        if (uri_to_path(uri, path, sizeof path)) printf("%s -> %s\n", argv[i], path);
        else printf("%s -> refused\n", argv[i]);
        free(uri);
    }
    return 0;
}
