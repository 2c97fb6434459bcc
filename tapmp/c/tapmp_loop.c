/* The FMI-free closed loop in C (declarations and contract in tapmp_loop.h). Each line mirrors
 * a line of tapmp.closed_loop.simulate and of the model methods it calls
 * (ControllerModel.communication_point and sample, PlantModel.step and outputs, reference), in
 * the same order and with the same arithmetic, so that the doubles are the same. */
#include <math.h>
#include <string.h>

#include "tapmp_loop.h"

long tapmp_loop_run(tapmp_plant *pl, const tapmp_params *p, const tapmp_gains *g, int law,
                    int velocity_source, double force_limit, int anti_windup, double anti_windup_time,
                    tapmp_controller_state *st,
                    tapmp_clock *clock, const tapmp_trajectory *tp, double L1_ref, double t0,
                    long k0, long n, double h, int gauss_seidel, tapmp_loop_point *pt,
                    double *rows, int *error)
{
    double out[12], plant_out[15], s_new[TAPMP_PLANT_STATES], arg, kk, steps, missed;
    *error = TAPMP_LOOP_OK;
    for (long i = 0; i < n; i++) {
        long k = k0 + i;
        double t = t0 + (double)k * h;
        /* kept to put back if this step fails: the caller replays it from here */
        tapmp_loop_point pt_before = *pt;
        tapmp_clock clock_before = *clock;
        double F_held[3] = {pt->F[0], pt->F[1], pt->F[2]};
        if (tapmp_clock_at(clock, t, &kk, &steps, &missed)) {
            /* ControllerModel.sample's one finiteness check: sum(ref) + sum(q) + sum(dq_in) */
            double sr = 0.0, sq = 0.0, sd = 0.0;
            for (int j = 0; j < 9; j++) sr += pt->ref[j];
            for (int j = 0; j < 3; j++) sq += pt->q[j];
            for (int j = 0; j < 3; j++) sd += pt->dq[j];
            if (!isfinite(sr + sq + sd)) {
                *error = TAPMP_LOOP_CONTROLLER_INPUT;
                *clock = clock_before;
                return i;
            }
            tapmp_controller_state next;
            if (!tapmp_controller_sample(p, g, law, velocity_source, force_limit, anti_windup, anti_windup_time,
                                         st, steps * clock->T_s, pt->ref, pt->q, pt->dq, 1, out, &next, &arg)) {
                *error = TAPMP_LOOP_CONTROLLER_DOMAIN;
                *clock = clock_before;
                return i;
            }
            tapmp_clock_sampled(clock, kk, steps);
            for (int j = 0; j < 3; j++) pt->F[j] = out[j];
            /* the state is committed only once the plant has stepped too */
            const double *F = gauss_seidel ? pt->F : F_held;
            if (!(isfinite(F[0]) && isfinite(F[1]) && isfinite(F[2]))) {
                *error = TAPMP_LOOP_FORCE;
            } else if (!tapmp_plant_step(pl, t, h, F, s_new)) {
                *error = TAPMP_LOOP_PLANT_DOMAIN;
            }
            if (*error) {
                *pt = pt_before;
                *clock = clock_before;
                return i;
            }
            *st = next;
        } else {
            const double *F = gauss_seidel ? pt->F : F_held;
            if (!(isfinite(F[0]) && isfinite(F[1]) && isfinite(F[2]))) {
                *error = TAPMP_LOOP_FORCE;
            } else if (!tapmp_plant_step(pl, t, h, F, s_new)) {
                *error = TAPMP_LOOP_PLANT_DOMAIN;
            }
            if (*error) {
                *clock = clock_before;
                return i;
            }
        }
        memcpy(pl->s, s_new, sizeof s_new);
        pl->sample += 1.0;
        tapmp_reference(t + h, tp, pt->ref);
        tapmp_plant_outputs(pl, plant_out);
        for (int j = 0; j < 3; j++) {
            pt->q[j] = plant_out[j];
            pt->dq[j] = plant_out[6 + j];
        }
        double *row = rows + i * TAPMP_LOOP_COLUMNS;
        row[0] = t0 + (double)(k + 1) * h;
        memcpy(row + 1, pt->ref, 9 * sizeof(double));
        tapmp_inverse(pt->ref[0], pt->ref[1], pt->ref[2], L1_ref, row + 10);
        memcpy(row + 13, pt->F, 3 * sizeof(double));
        memcpy(row + 16, plant_out, 3 * sizeof(double));
        memcpy(row + 19, plant_out + 3, 3 * sizeof(double));
        memcpy(row + 22, pl->s, 6 * sizeof(double));
    }
    return n;
}
