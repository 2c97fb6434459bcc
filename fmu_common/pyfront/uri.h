/* The local path of an fmuResourceLocation URI, for the pythonfmu FMUs' binary (python_model.c).
 * Kept apart from Python so that tests/fmu/c_host/uri_host.c can run it under AddressSanitizer. */
#ifndef TAPMP_URI_H
#define TAPMP_URI_H

#include <stddef.h>
#include <string.h>

static int hex_digit(char c)
{
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

/* file:///a%20b/ -> /a b/ (RFC 8089 local file URIs, as FMI 2.0 prescribes) into path (size
 * bytes with the terminating zero). 0 for a URI that is malformed (a '%' not followed by two hex
 * digits, or %00: a path cannot hold a zero byte), that names another host (file://host/x: an
 * authority other than empty or localhost is a remote file, not the relative path host/x) or whose
 * path is empty or does not fit; the URI is never read past its terminating zero. */
static int uri_to_path(const char *uri, char *path, size_t size)
{
    if (strncmp(uri, "file://", 7) == 0) {
        uri += 7;
        if (strncmp(uri, "localhost/", 10) == 0) uri += 9;
        else if (*uri != '/') return 0;  /* an authority that is not this machine */
    } else if (strncmp(uri, "file:", 5) == 0) {
        uri += 5;
    }
    size_t k = 0;
    for (; *uri; uri++) {
        char byte = *uri;
        if (byte == '%') {
            int hi = hex_digit(uri[1]);
            int lo = hi < 0 ? -1 : hex_digit(uri[2]);  /* uri[2] is read only if uri[1] was a digit, not the zero */
            if (lo < 0 || (hi == 0 && lo == 0)) return 0;
            byte = (char)(hi * 16 + lo);
            uri += 2;
        }
        if (k + 1 >= size) return 0;
        path[k++] = byte;
    }
    path[k] = '\0';
    return k > 0;
}

#endif
