/* Second-order sections over a block of samples (declarations and contract in tapmp_filter.h). */
#include "tapmp_filter.h"

void tapmp_sos_sumsq(int n_sections, const double *sos, int channels, double *state,
                     const double *x, long rows, double *sumsq)
{
    for (int c = 0; c < channels; c++) {
        double acc = 0.0;
        for (long r = 0; r < rows; r++) {
            double v = x[r * channels + c];
            for (int s = 0; s < n_sections; s++) {
                const double *k = sos + 6 * s;
                double *z = state + 2 * (s * channels + c);
                double y = k[0] * v + z[0];
                z[0] = k[1] * v - k[4] * y + z[1];
                z[1] = k[2] * v - k[5] * y;
                v = y;
            }
            acc += v * v;
        }
        sumsq[c] += acc;
    }
}
