/* FMI 3.0's clock functions of a native TAPMP FMU: the periodic input clock of a model with MODEL_CLOCK
 * (the clocked controller; events.c, tapmp_set_clock ...), where fmi3Clock is a bool and the runtime
 * takes ints; a model without clocks accepts them for no clock only. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "runtime.h"
#include "fmi3Functions.h"

#ifdef MODEL_CLOCK
#define CLOCK_MAX 64  /* values per call: the FMU has one clock, a host passes it once or a few times */
static int clock_count(tapmp_instance *inst, const char *call, size_t n)
{
    if (n <= CLOCK_MAX) return ST_OK;
    return tapmp_fail(inst, "fmi3%s: nValueReferences = %zu is invalid: allowed is at most %d (this FMU has one "
                      "clock, " MODEL_CLOCK_NAME ")", call, n, CLOCK_MAX);
}

fmi3Status fmi3GetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Clock v[])
{
    INSTANCE(c, fmi3Error);
    int values[CLOCK_MAX];
    int status = clock_count(inst, "GetClock", n);
    if (status == ST_OK) status = tapmp_get_clock(inst, vr, n, v ? values : NULL);
    for (size_t i = 0; status == ST_OK && i < n; i++) v[i] = values[i] ? fmi3ClockActive : fmi3ClockInactive;
    return (fmi3Status)status;
}

fmi3Status fmi3SetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Clock v[])
{
    INSTANCE(c, fmi3Error);
    int values[CLOCK_MAX];
    int status = clock_count(inst, "SetClock", n);
    if (status != ST_OK) return (fmi3Status)status;
    for (size_t i = 0; v && i < n; i++) values[i] = v[i] != fmi3ClockInactive;
    return (fmi3Status)tapmp_set_clock(inst, vr, n, v ? values : NULL);
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 interval[],
                                  fmi3IntervalQualifier qualifier[])
{
    INSTANCE(c, fmi3Error);
    int q[CLOCK_MAX];
    int status = clock_count(inst, "GetIntervalDecimal", n);
    if (status == ST_OK) status = tapmp_get_interval(inst, vr, n, interval, q);
    for (size_t i = 0; status == ST_OK && qualifier && i < n; i++)
        qualifier[i] = q[i] == 2 ? fmi3IntervalChanged : fmi3IntervalUnchanged;
    return (fmi3Status)status;
}

/* The interval as counter / resolution [s]: T_s = 1 / resolution when that is exact (0.0001 s = 1/10000),
 * else the error: a fraction would round the period the controller uses. */
static int interval_fraction(tapmp_instance *inst, double T, fmi3UInt64 *counter, fmi3UInt64 *resolution)
{
    double r = nearbyint(1.0 / T);
    if (r >= 1.0 && r < 1e15 && 1.0 / r == T) {
        *counter = 1;
        *resolution = (fmi3UInt64)r;
        return ST_OK;
    }
    char v[40];
    return tapmp_invalid(inst, "T_s (as a fraction)", tapmp_repr(T, v), "a period 1/n s, n an integer, for "
                         "fmi3GetIntervalFraction (fmi3GetIntervalDecimal gives any T_s)", 0);
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3UInt64 counter[],
                                   fmi3UInt64 resolution[], fmi3IntervalQualifier qualifier[])
{
    INSTANCE(c, fmi3Error);
    double interval[CLOCK_MAX];
    int q[CLOCK_MAX];
    int status = clock_count(inst, "GetIntervalFraction", n);
    if (status == ST_OK && n && (!counter || !resolution))
        status = tapmp_fail(inst, "fmi3GetIntervalFraction: counters and resolutions must not be NULL");
    if (status == ST_OK) status = tapmp_get_interval(inst, vr, n, interval, q);
    for (size_t i = 0; status == ST_OK && i < n; i++) {
        status = interval_fraction(inst, interval[i], &counter[i], &resolution[i]);
        if (qualifier) qualifier[i] = q[i] == 2 ? fmi3IntervalChanged : fmi3IntervalUnchanged;
    }
    return (fmi3Status)status;
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n,
                                  const fmi3Float64 interval[])
{
    INSTANCE(c, fmi3Error);
    return (fmi3Status)tapmp_set_interval(inst, vr, n, interval);
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n,
                                   const fmi3UInt64 counter[], const fmi3UInt64 resolution[])
{
    INSTANCE(c, fmi3Error);
    double interval[CLOCK_MAX];
    int status = clock_count(inst, "SetIntervalFraction", n);
    if (status == ST_OK && n && (!counter || !resolution))
        status = tapmp_fail(inst, "fmi3SetIntervalFraction: counters and resolutions must not be NULL");
    for (size_t i = 0; status == ST_OK && i < n; i++)
        interval[i] = resolution[i] ? (double)counter[i] / (double)resolution[i] : INFINITY;
    return (fmi3Status)(status == ST_OK ? tapmp_set_interval(inst, vr, n, interval) : status);
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 shift[])
{
    INSTANCE(c, fmi3Error);
    return (fmi3Status)tapmp_get_shift(inst, vr, n, shift);
}

fmi3Status fmi3GetShiftFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3UInt64 counter[],
                                fmi3UInt64 resolution[])
{
    INSTANCE(c, fmi3Error);
    double shift[CLOCK_MAX];
    int status = clock_count(inst, "GetShiftFraction", n);
    if (status == ST_OK && n && (!counter || !resolution))
        status = tapmp_fail(inst, "fmi3GetShiftFraction: counters and resolutions must not be NULL");
    if (status == ST_OK) status = tapmp_get_shift(inst, vr, n, shift);
    for (size_t i = 0; status == ST_OK && i < n; i++) counter[i] = 0, resolution[i] = 1;
    return (fmi3Status)status;
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Float64 shift[])
{
    INSTANCE(c, fmi3Error);
    return (fmi3Status)tapmp_set_shift(inst, vr, n, shift);
}

fmi3Status fmi3SetShiftFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 counter[],
                                const fmi3UInt64 resolution[])
{
    INSTANCE(c, fmi3Error);
    double shift[CLOCK_MAX];
    int status = clock_count(inst, "SetShiftFraction", n);
    if (status == ST_OK && n && (!counter || !resolution))
        status = tapmp_fail(inst, "fmi3SetShiftFraction: counters and resolutions must not be NULL");
    for (size_t i = 0; status == ST_OK && i < n; i++)
        shift[i] = resolution[i] ? (double)counter[i] / (double)resolution[i] : INFINITY;
    return (fmi3Status)(status == ST_OK ? tapmp_set_shift(inst, vr, n, shift) : status);
}
#else
fmi3Status fmi3GetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Clock v[])
{
    (void)vr, (void)v;
    return n ? (fmi3Status)tapmp_unsupported(c, "GetClock", "this FMU has no clocks") : fmi3OK;
}

fmi3Status fmi3SetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Clock v[])
{
    (void)vr, (void)v;
    return n ? (fmi3Status)tapmp_unsupported(c, "SetClock", "this FMU has no clocks") : fmi3OK;
}
#endif
