/* Reading a libFuzzer input as a sequence of FMI calls and their arguments: shared by
 * fuzz_fmi2.c and fuzz_fmi3.c. Every read past the end of the input yields zeros, so any
 * byte string is a valid (possibly short) call sequence. The kept inputs in regressions/
 * are call sequences in this encoding: a change to how the targets read their input makes
 * them replay other sequences, so such a change needs the kept inputs found again. */
#ifndef TAPMP_FUZZ_INPUT_H
#define TAPMP_FUZZ_INPUT_H

#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
    const uint8_t *p;
    size_t n;
} fuzz_input;

static unsigned fuzz_byte(fuzz_input *in)
{
    if (!in->n) return 0;
    in->n--;
    return *in->p++;
}

static uint32_t fuzz_u32(fuzz_input *in)
{
    uint32_t x = 0;
    for (int i = 0; i < 4; i++) x |= (uint32_t)fuzz_byte(in) << (8 * i);
    return x;
}

/* A double: mostly the values that find edges (0, tiny and huge steps, non-finite, the
 * communication step, OMSimulator's last step), else 8 raw bytes. */
static double fuzz_double(fuzz_input *in)
{
    static const double special[] = {0.0, 1e-4, -1e-4, 1.0, -1.0, 5.7e-15, 1e-300, 1e300, -1e300,
                                     DBL_MAX, DBL_MIN, 0.1, 2.5, 1e-9, 3e-5, 0.5};
    unsigned k = fuzz_byte(in);
    if (k < 16) return special[k];
    if (k == 16) return NAN;
    if (k == 17) return INFINITY;
    if (k == 18) return -INFINITY;
    if (k < 128) return (double)((int)k - 64) * 1e-3;
    double x;
    uint8_t b[8];
    for (int i = 0; i < 8; i++) b[i] = (uint8_t)fuzz_byte(in);
    memcpy(&x, b, sizeof x);
    return x;
}

/* A value reference: mostly in or just past the FMU's range, sometimes any 32-bit value. */
static unsigned fuzz_vr(fuzz_input *in, unsigned n_vars)
{
    unsigned k = fuzz_byte(in);
    if (k < 250) return k % (n_vars + 3);
    return fuzz_u32(in);
}

/* A count for an array argument: 0 .. 40 (the arrays passed have exactly that length). */
static size_t fuzz_count(fuzz_input *in) { return fuzz_byte(in) % 41; }

/* A string argument: NULL, empty, short, or the fuzzer's own bytes (NUL-terminated copy). */
static char *fuzz_string(fuzz_input *in, char *buf, size_t size, const char *good)
{
    unsigned k = fuzz_byte(in) % 5;
    if (k == 0) return NULL;
    if (k == 1) return strcpy(buf, "");
    if (k == 2 && good) return strcpy(buf, good);
    size_t len = fuzz_byte(in) % size;
    for (size_t i = 0; i < len; i++) {
        buf[i] = (char)fuzz_byte(in);
        if (!buf[i]) buf[i] = 'x';
    }
    buf[len] = 0;
    return buf;
}

/* Logged messages are formatted, so a bad format or argument shows up, and dropped (the
 * FMI 2.0 targets' logger calls it: fuzz_fmi2_logger.h; FMI 3.0 messages come formatted). */
static void fuzz_format(const char *fmt, va_list ap)
{
    char buf[4096];
    vsnprintf(buf, sizeof buf, fmt ? fmt : "", ap);
}

#endif
