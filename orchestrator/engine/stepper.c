/* The compiled stepping core of the tapmp master (orchestrator/engine/stepper.py).
 *
 * fmpy loads the FMUs, instantiates and initializes them; this file runs the macro-step
 * loop of orchestrator.engine.master.CoSimulation.step() on the same instances, calling the
 * FMI 2.0 / 3.0 functions through the pointers of the libraries fmpy loaded:
 * copy outputs to inputs along the planned connections, setReal, doStep, getReal, check
 * the statuses (stop at the first call above Warning or after which an error was logged,
 * the worst status kept) and that every output is finite and inside the envelope, then
 * store the row (time, every element's outputs) into the caller's block.
 *
 * It never decides what a failure means: on a failed call or a suspect output it stops
 * and reports where, and the Python master raises exactly the error its own loop raises.
 * Times are those of orchestrator.engine.clocks, to the bit. No allocation, no I/O. */
#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

typedef int (*get2_t)(void *, const uint32_t *, size_t, double *);
typedef int (*set2_t)(void *, const uint32_t *, size_t, const double *);
typedef int (*step2_t)(void *, double, double, int);
typedef int (*get3_t)(void *, const uint32_t *, size_t, double *, size_t);
typedef int (*set3_t)(void *, const uint32_t *, size_t, const double *, size_t);
typedef int (*step3_t)(void *, double, double, bool, bool *, bool *, bool *, double *);

typedef struct {
    void *instance;
    void *get, *set, *step;        /* fmi2GetReal/SetReal/DoStep or fmi3GetFloat64/SetFloat64/DoStep */
    int32_t fmi3;
    int32_t n_out, n_in;
    const uint32_t *out_vrs;
    double *out;                   /* outputs at the last communication point (the master's array) */
    const uint32_t *in_vrs;
    double *inp;                   /* input values handed to setReal */
    double *const *src;            /* per input: the source's output it copies */
} tapmp_unit;

enum { CLOCK_EXACT = 0, CLOCK_ACCUMULATED = 1, CLOCK_NANOSECONDS = 2 };
enum { DONE = 0, FAIL_CALL = 1, SUSPECT_OUTPUT = 2 };
enum { CALL_SET = 0, CALL_STEP = 1, CALL_GET = 2 };

typedef struct {
    tapmp_unit *units;
    int32_t n_units;
    int32_t jacobi;
    const int32_t *step_order;     /* n_units indices into units */
    int32_t clock;
    double t0, h;
    int64_t t0_ns, h_ns;
    int32_t n_env;                 /* envelope signals: unit, output index, limit */
    const int32_t *env_unit, *env_index;
    const double *env_limit;
    volatile const int64_t *log_count;   /* messages logged so far (the master's logger counts) */
    volatile const int64_t *log_errors;  /* of those, ERROR or FATAL */
} tapmp_plan;

typedef struct {
    int64_t k;          /* in: step to start from; out: the communication point reached */
    double acc_t;       /* accumulated clock: t_k (in and out) */
    int64_t rows;       /* out: rows stored */
    int32_t outcome;    /* out: DONE, FAIL_CALL, SUSPECT_OUTPUT */
    int32_t unit;       /* FAIL_CALL: the unit (index into units) */
    int32_t call;       /* FAIL_CALL: CALL_SET, CALL_STEP or CALL_GET */
    int32_t status;     /* FAIL_CALL: the worst status of the unit's calls in that step */
    int64_t n_log;      /* FAIL_CALL: log_count at the start of the failing step */
} tapmp_state;

static double time_at(const tapmp_plan *p, int64_t k)
{
    if (p->clock == CLOCK_NANOSECONDS)
        return (double)(p->t0_ns + k * p->h_ns) / 1e9;
    return p->t0 + (double)k * p->h;  /* exact; the accumulated clock keeps its own sum */
}

static int set_inputs(tapmp_unit *u)
{
    if (!u->n_in)
        return 0;
    for (int32_t j = 0; j < u->n_in; j++)
        u->inp[j] = *u->src[j];
    if (u->fmi3)
        return ((set3_t)u->set)(u->instance, u->in_vrs, (size_t)u->n_in, u->inp, (size_t)u->n_in);
    return ((set2_t)u->set)(u->instance, u->in_vrs, (size_t)u->n_in, u->inp);
}

static int do_step(tapmp_unit *u, double t, double h)
{
    if (u->fmi3) {
        bool event = false, terminate = false, early = false;
        double last = 0.0;
        return ((step3_t)u->step)(u->instance, t, h, true, &event, &terminate, &early, &last);
    }
    return ((step2_t)u->step)(u->instance, t, h, 1);
}

static int get_outputs(tapmp_unit *u)
{
    if (u->fmi3)
        return ((get3_t)u->get)(u->instance, u->out_vrs, (size_t)u->n_out, u->out, (size_t)u->n_out);
    return ((get2_t)u->get)(u->instance, u->out_vrs, (size_t)u->n_out, u->out);
}

/* One call's outcome: 1 if the step must stop (a status above Warning, or an error logged). */
static int failed(const tapmp_plan *p, tapmp_state *s, int32_t unit, int32_t call, int status,
                  int *worst, int64_t errors)
{
    if (status > *worst)
        *worst = status;
    if (status > 1 || *p->log_errors != errors) {
        s->outcome = FAIL_CALL;
        s->unit = unit;
        s->call = call;
        s->status = *worst;
        return 1;
    }
    return 0;
}

static int outputs_suspect(const tapmp_plan *p)
{
    for (int32_t i = 0; i < p->n_units; i++) {
        const tapmp_unit *u = &p->units[i];
        for (int32_t j = 0; j < u->n_out; j++)
            if (!isfinite(u->out[j]))
                return 1;
    }
    for (int32_t e = 0; e < p->n_env; e++) {
        double v = p->units[p->env_unit[e]].out[p->env_index[e]], lim = p->env_limit[e];
        if (!(-lim <= v && v <= lim))
            return 1;
    }
    return 0;
}

/* Step from s->k at most n_steps times, storing a row of n_cols doubles per completed step
 * into rows (row-major). Returns s->outcome. */
int tapmp_advance(const tapmp_plan *p, tapmp_state *s, int64_t n_steps, double *rows, int32_t n_cols)
{
    s->rows = 0;
    s->outcome = DONE;
    for (int64_t n = 0; n < n_steps; n++) {
        int64_t k = s->k;
        double t, h;
        if (p->clock == CLOCK_ACCUMULATED) {
            t = s->acc_t;
            h = p->h;
        } else {
            t = time_at(p, k);
            h = p->clock == CLOCK_NANOSECONDS ? time_at(p, k + 1) - t : p->h;
        }
        s->n_log = *p->log_count;
        int64_t errors = *p->log_errors;
        if (!p->jacobi) {
            for (int32_t i = 0; i < p->n_units; i++) {
                int32_t ui = p->step_order[i];
                tapmp_unit *u = &p->units[ui];
                int worst = 0;
                if (failed(p, s, ui, CALL_SET, set_inputs(u), &worst, errors)
                    || failed(p, s, ui, CALL_STEP, do_step(u, t, h), &worst, errors)
                    || failed(p, s, ui, CALL_GET, get_outputs(u), &worst, errors))
                    return FAIL_CALL;
            }
        } else {
            for (int32_t i = 0; i < p->n_units; i++) {
                int worst = 0, ui = p->step_order[i];
                if (failed(p, s, ui, CALL_SET, set_inputs(&p->units[ui]), &worst, errors))
                    return FAIL_CALL;
            }
            for (int32_t i = 0; i < p->n_units; i++) {
                int worst = 0, ui = p->step_order[i];
                if (failed(p, s, ui, CALL_STEP, do_step(&p->units[ui], t, h), &worst, errors))
                    return FAIL_CALL;
            }
            for (int32_t i = 0; i < p->n_units; i++) {
                int worst = 0, ui = p->step_order[i];
                if (failed(p, s, ui, CALL_GET, get_outputs(&p->units[ui]), &worst, errors))
                    return FAIL_CALL;
            }
        }
        s->k = k + 1;
        if (p->clock == CLOCK_ACCUMULATED)
            s->acc_t += p->h;
        if (outputs_suspect(p)) {
            s->outcome = SUSPECT_OUTPUT;
            return SUSPECT_OUTPUT;
        }
        double *row = rows + (size_t)s->rows * (size_t)n_cols;
        row[0] = p->clock == CLOCK_ACCUMULATED ? s->acc_t : time_at(p, s->k);
        int32_t c = 1;
        for (int32_t i = 0; i < p->n_units; i++) {
            const tapmp_unit *u = &p->units[i];
            for (int32_t j = 0; j < u->n_out; j++)
                row[c++] = u->out[j];
        }
        s->rows++;
    }
    return DONE;
}
