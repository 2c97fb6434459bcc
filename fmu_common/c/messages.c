/* Messages of the runtime: Python's repr() of a float, logging, the first error, and the texts of a
 * value that is not allowed ("NAME = VALUE is invalid: allowed is ALLOWED"), as tapmp.errors writes
 * them, so both families of FMUs say the same. See instance.h and runtime.h. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "runtime.h"

static const char *const MODE_NAMES[] = {"Instantiated", "Initialization Mode", "Step Mode", "Terminated",
                                         "Event Mode"};

const char *tapmp_mode_name(tapmp_mode mode)
{
    return MODE_NAMES[mode];
}

char *tapmp_repr(double x, char *buf)
{
    if (isnan(x)) return strcpy(buf, "nan");
    if (isinf(x)) return strcpy(buf, x > 0 ? "inf" : "-inf");
    if (x == 0.0) return strcpy(buf, signbit(x) ? "-0.0" : "0.0");
    char e[40];
    for (int p = 1; p <= 17; p++) {  /* the shortest digits that read back as x */
        snprintf(e, sizeof e, "%.*e", p - 1, x);
        if (strtod(e, NULL) == x) break;
    }
    const char *s = e;
    int neg = *s == '-';
    if (neg) s++;
    char digits[24];
    int nd = 0;
    for (; *s && *s != 'e'; s++)
        if (*s != '.') digits[nd++] = *s;
    while (nd > 1 && digits[nd - 1] == '0') nd--;
    digits[nd] = 0;
    int exp10 = atoi(s + 1), decpt = exp10 + 1;
    char *o = buf;
    if (neg) *o++ = '-';
    if (decpt <= -4 || decpt > 16) {  /* Python's switch to scientific notation */
        *o++ = digits[0];
        if (nd > 1) o += sprintf(o, ".%s", digits + 1);
        sprintf(o, "e%c%02d", exp10 < 0 ? '-' : '+', abs(exp10));
    } else if (decpt <= 0) {
        o += sprintf(o, "0.");
        for (int i = 0; i < -decpt; i++) *o++ = '0';
        strcpy(o, digits);
    } else if (decpt >= nd) {
        o += sprintf(o, "%s", digits);
        for (int i = nd; i < decpt; i++) *o++ = '0';
        strcpy(o, ".0");
    } else {
        memcpy(o, digits, (size_t)decpt);
        o += decpt;
        sprintf(o, ".%s", digits + decpt);
    }
    return buf;
}


void tapmp_log(tapmp_instance *inst, int status, const char *category, const char *fmt, ...)
{
    char msg[TAPMP_MESSAGE_MAX];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (status >= ST_ERROR && !inst->failed) {
        inst->failed = 1;
        snprintf(inst->error, sizeof inst->error, "%s", msg);
    }
    if (inst->log && (inst->logging_on || status >= ST_ERROR)) inst->log(inst, status, category, msg);
}

int tapmp_fail(tapmp_instance *inst, const char *fmt, ...)
{
    char msg[TAPMP_MESSAGE_MAX];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    tapmp_log(inst, ST_ERROR, "logStatusError", "%s", msg);
    return ST_ERROR;
}

int tapmp_invalid_text(char *buf, size_t size, const char *name, const char *value,
                       const char *allowed, int has_time, double time)
{
    char at[64] = "";
    if (has_time) snprintf(at, sizeof at, " at t = %.6g s", time);
    snprintf(buf, size, "%s = %s%s is invalid: allowed is %s", name, value, at, allowed);
    return 0;
}

int tapmp_invalid(tapmp_instance *inst, const char *name, const char *value, const char *allowed,
                  int time_in_value)
{
    char msg[TAPMP_MESSAGE_MAX];
    tapmp_invalid_text(msg, sizeof msg, name, value, allowed, time_in_value, inst->time);
    if (time_in_value) return tapmp_fail(inst, "%s", msg);
    return tapmp_fail(inst, "%s (at t = %.6g s)", msg, inst->time);
}

int tapmp_range_text(int kind, const char *name, double value, const char *allowed, char *msg, size_t size)
{
    char v[40];
    if (!kind) return 1;
    /* an integer setting's value may lie outside int (that is why it is refused): printed, not converted */
    if (kind == 2) snprintf(v, sizeof v, "%.0f", value);
    return tapmp_invalid_text(msg, size, name ? name : "a setting", kind == 2 ? v : tapmp_repr(value, v),
                              allowed ? allowed : "a value in its range", 0, 0);
}

int tapmp_unsupported(void *instance, const char *call, const char *why)
{
    tapmp_instance *inst = instance;
    if (!tapmp_alive(inst)) return ST_ERROR;
    return tapmp_fail(inst, "%s%s is not supported: %s", inst->fmi, call, why);
}
