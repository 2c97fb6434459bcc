/* A cascade of second-order IIR sections run over many samples in one call: the high-pass of
 * the effort metric (orchestrator/tool/highpass.py designs it and calls this through cffi;
 * tapmp/cmodel.py reads these declarations from this file). Part of the Python side's library,
 * not of the FMUs. */
#ifndef TAPMP_FILTER_H
#define TAPMP_FILTER_H

#include "tapmp_model.h"

/* Filters `rows` samples of `channels` channels (x: rows x channels, row-major) through
 * `n_sections` sections in transposed direct form II, each sos[6 s .. 6 s + 5] = b0, b1, b2,
 * a0, a1, a2 with a0 = 1, and adds each channel's sum of squared outputs to sumsq[channel].
 * state (n_sections x channels x 2) holds the sections' delays; it is updated in place, so
 * consecutive calls filter one signal block by block. */
TAPMP_LINKAGE void tapmp_sos_sumsq(int n_sections, const double *sos, int channels, double *state,
                                   const double *x, long rows, double *sumsq);

#endif
