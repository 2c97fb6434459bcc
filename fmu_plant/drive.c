/* Native TAPMP_Drive FMU: the servo drive between the controller and the plant, per motor i:
 *   c_k = F_cmd_i(t_(k-d))                  computation delay of d = delay_samples communication steps
 *   s_k = min(max(c_k, -L), L)              current (force) limit L = force_limit (0: none)
 *   y'' = wn^2 (s - y) - 2 zeta wn y'       current (force) loop, wn = 2 pi current_bandwidth (0: y = s)
 *   F_i = (1 + force_constant_error_i) mean of y over [t_k, t_k + h]
 * doStep(t_k, h) reads F_cmd at t_k and outputs the force of the step it takes, held over it like the
 * controller's command (the plant integrates with it over [t_k, t_k + h]); with d = 0, an ideal loop, no
 * limit and no force-constant error F_i is F_cmd_i, bit for bit. The loop is discretized exactly: s is
 * held over the step (zero-order hold), and exp(M h) of the loop with its input and its mean (phi) is
 * computed once per step size. The variables and their ranges (checked by the runtime) are
 * tapmp/interface.py's DRIVE_VARS. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "instance.h"

#define TWO_PI 6.283185307179586

static void read_settings(const tapmp_instance *inst, ModelData *m)
{
    m->delay = inst->ints[VR_delay_samples];
    m->wn = TWO_PI * inst->reals[VR_current_bandwidth];
    m->zeta = inst->reals[VR_current_damping];
    m->gain[0] = 1.0 + inst->reals[VR_force_constant_error1];
    m->gain[1] = 1.0 + inst->reals[VR_force_constant_error2];
    m->gain[2] = 1.0 + inst->reals[VR_force_constant_error3];
    m->limit = inst->reals[VR_force_limit];
}

/* Every setting's range is the record's min/max, which the runtime checks after this; the delay is checked here
 * first, as the integer it is (the runtime words every range as a number's), since it indexes the buffer. */
int model_validate(const tapmp_instance *inst, char *msg, size_t size)
{
    const tapmp_var *var = &VARS[VR_delay_samples];
    int d = inst->ints[VR_delay_samples];
    if (d >= var->min && d <= var->max && var->max <= DRIVE_MAX_DELAY) return 1;
    char value[24], allowed[64];
    snprintf(value, sizeof value, "%d", d);
    snprintf(allowed, sizeof allowed, "an integer in [%d, %d]", (int)var->min, (int)var->max);
    return tapmp_invalid_text(msg, size, var->name, value, allowed, 0, 0.0);
}

static double limited(const ModelData *m, double c)
{
    return m->limit > 0.0 ? fmin(fmax(c, -m->limit), m->limit) : c;
}

static void mat_mul(double a[4][4], double b[4][4], double out[4][4])
{
    double r[4][4];
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++) {
            r[i][j] = 0.0;
            for (int k = 0; k < 4; k++) r[i][j] += a[i][k] * b[k][j];
        }
    memcpy(out, r, sizeof r);
}

/* phi = exp(M h) for z = (y, y'/wn, s, mean): y' = wn v, v' = wn (s - y) - 2 zeta wn v, s' = 0,
 * mean' = y / h, so that from mean = 0 the last row gives the mean of y over the step. Scaling and squaring
 * with a Taylor series: M h / 2^n has a 1-norm <= 1/2, where 18 terms leave a truncation below 1e-22. */
static void loop_transition(ModelData *m, double h)
{
    const double a = m->wn * h;
    double M[4][4] = {{0.0, a, 0.0, 0.0}, {-a, -2.0 * m->zeta * a, a, 0.0}, {0.0}, {1.0, 0.0, 0.0, 0.0}};
    double norm = 0.0;
    for (int j = 0; j < 4; j++) {
        double col = 0.0;
        for (int i = 0; i < 4; i++) col += fabs(M[i][j]);
        norm = fmax(norm, col);
    }
    int n = norm > 0.5 ? (int)ceil(log2(norm / 0.5)) : 0;
    double scale = ldexp(1.0, -n), term[4][4], sum[4][4];
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++) {
            M[i][j] *= scale;
            term[i][j] = sum[i][j] = i == j;
        }
    for (int k = 1; k <= 18; k++) {
        mat_mul(term, M, term);
        for (int i = 0; i < 4; i++)
            for (int j = 0; j < 4; j++) {
                term[i][j] /= k;
                sum[i][j] += term[i][j];
            }
    }
    for (int k = 0; k < n; k++) mat_mul(sum, sum, sum);
    memcpy(m->phi, sum, sizeof sum);
    m->h = h;
}

/* At rest: every past command the present one, the loop settled on its limited value. */
static void rest(tapmp_instance *inst)
{
    ModelData *m = &inst->m;
    for (int i = 0; i < 3; i++) {
        double u = inst->reals[VR_F_cmd1 + i];
        for (int j = 0; j < DRIVE_MAX_DELAY; j++) m->past[i][j] = u;
        m->x[i][0] = limited(m, u);
        m->x[i][1] = 0.0;
        inst->reals[MODEL_OUT_FIRST + i] = m->gain[i] * m->x[i][0];
    }
}

void model_setup(tapmp_instance *inst)
{
    read_settings(inst, &inst->m);
    inst->m.h = 0.0;
    rest(inst);
}

/* The outputs at the start follow the commands the drive receives then (Initialization Mode). */
int model_initial_outputs(tapmp_instance *inst, char *msg, size_t size)
{
    (void)msg, (void)size;
    rest(inst);
    return 1;
}

int model_step(tapmp_instance *inst, double t, double h, double out[], char *msg, size_t size)
{
    (void)t, (void)msg, (void)size;
    ModelData *m = &inst->m;
    if (m->wn > 0.0 && m->h != h) loop_transition(m, h);
    for (int i = 0; i < 3; i++) {
        double u = inst->reals[VR_F_cmd1 + i];
        double c = m->delay ? m->past[i][m->delay - 1] : u;
        memmove(m->past[i] + 1, m->past[i], (DRIVE_MAX_DELAY - 1) * sizeof(double));
        m->past[i][0] = u;
        double s = limited(m, c), mean = s;
        if (m->wn > 0.0) {
            const double z[4] = {m->x[i][0], m->x[i][1], s, 0.0};
            double next[4];
            for (int r = 0; r < 4; r++)
                next[r] = m->phi[r][0] * z[0] + m->phi[r][1] * z[1] + m->phi[r][2] * z[2];
            m->x[i][0] = next[0];
            m->x[i][1] = next[1];
            mean = next[3];
        } else {
            m->x[i][0] = s;
            m->x[i][1] = 0.0;
        }
        out[i] = m->gain[i] * mean;
    }
    return 1;
}

void model_get_hidden(const tapmp_instance *inst, double hidden[])
{
    for (int i = 0; i < 3; i++) {
        memcpy(hidden + 5 * i, inst->m.past[i], DRIVE_MAX_DELAY * sizeof(double));
        hidden[5 * i + 3] = inst->m.x[i][0];
        hidden[5 * i + 4] = inst->m.x[i][1];
    }
}

void model_set_hidden(tapmp_instance *inst, const double hidden[])
{
    read_settings(inst, &inst->m);
    inst->m.h = 0.0;
    for (int i = 0; i < 3; i++) {
        memcpy(inst->m.past[i], hidden + 5 * i, DRIVE_MAX_DELAY * sizeof(double));
        inst->m.x[i][0] = hidden[5 * i + 3];
        inst->m.x[i][1] = hidden[5 * i + 4];
    }
}

/* The past commands and the loop's states are forces: finite is all they need to be. */
int model_check_hidden(const tapmp_instance *state, const double hidden[], char *msg, size_t size)
{
    (void)state;
    for (int i = 0; i < MODEL_N_HIDDEN; i++) {
        if (isfinite(hidden[i])) continue;
        char v[40];
        return tapmp_invalid_text(msg, size, "drive state", tapmp_repr(hidden[i], v), "finite forces", 0, 0.0);
    }
    return 1;
}
