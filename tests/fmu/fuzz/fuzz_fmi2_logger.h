/* The FMI 2.0 logger of the FMI 2.0 fuzz targets (fuzz_fmi2.c, fuzz_states.c): formats every
 * message the FMU logs (fuzz_format), so a format string that reads past its arguments is a
 * sanitizer finding, and prints nothing. Include after all.c and fuzz_input.h. */
#ifndef TAPMP_FUZZ_FMI2_LOGGER_H
#define TAPMP_FUZZ_FMI2_LOGGER_H

static void fuzz_logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                        fmi2String category, fmi2String message, ...)
{
    va_list ap;
    (void)env, (void)instance, (void)status, (void)category;
    va_start(ap, message);
    fuzz_format(message, ap);
    va_end(ap);
}

#endif
