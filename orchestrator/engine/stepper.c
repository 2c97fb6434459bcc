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
 * In event mode (FMI 3.0 units instantiated with eventModeUsed, orchestrator.engine.master's
 * _step_events and _handle_events) a macro step is cut at every event inside it, and at each
 * event the event units enter Event Mode, tick their clocks if a tick is due, take their inputs,
 * update their discrete states, publish their outputs and return to Step Mode: the same FMI calls
 * in the same order as the Python loop, so every double is the same.
 *
 * It never decides what a failure means: on a failed call, a suspect output, an unannounced
 * early return or discrete states that do not settle it stops and reports where, and the
 * Python master raises exactly the error its own loop raises.
 * Times are those of orchestrator.engine.clocks, to the bit. No allocation, no I/O.
 *
 * Paced (real-time) runs, orchestrator.engine.pacing: with plan->pace set, every macro step is
 * released no earlier than its release time on CLOCK_MONOTONIC and its completion is compared
 * with its deadline t0_wall + j h / factor (j: paced steps so far plus the slots dropped; an
 * absolute grid, no drift). Statistics go into the pace record, nothing per step into Python;
 * tapmp_advance_paced runs a whole paced run into a ring of row blocks that another thread reads,
 * so Python never runs between steps. */
#define _POSIX_C_SOURCE 200809L  /* clock_nanosleep */
#include <errno.h>
#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <time.h>

typedef int (*get2_t)(void *, const uint32_t *, size_t, double *);
typedef int (*set2_t)(void *, const uint32_t *, size_t, const double *);
typedef int (*step2_t)(void *, double, double, int);
typedef int (*get3_t)(void *, const uint32_t *, size_t, double *, size_t);
typedef int (*set3_t)(void *, const uint32_t *, size_t, const double *, size_t);
typedef int (*step3_t)(void *, double, double, bool, bool *, bool *, bool *, double *);
typedef int (*call3_t)(void *);
typedef int (*clock3_t)(void *, const uint32_t *, size_t, const bool *);
typedef int (*update3_t)(void *, bool *, bool *, bool *, bool *, bool *, double *);

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
    /* FMI 3.0: fmi3DoStep's out-arguments, the Unit's own ctypes objects (instance.Unit._flags) */
    bool *event_needed, *terminate, *early;
    double *last_time;
    /* event units only (instance.Unit: event_mode, next_event, clocks) */
    void *enter_event, *set_clock, *update, *enter_step;  /* fmi3EnterEventMode, SetClock, ... */
    double next_event;             /* in/out: nextEventTime [s], INFINITY if none */
    int64_t clock_k;               /* in/out: index of the next clock tick */
    int64_t n_events;              /* in/out: events handled */
    int32_t n_clocks;              /* input clocks, ticked together */
    const uint32_t *clock_vrs;
    const bool *clock_on;          /* n_clocks times true */
    double clock_t0, clock_interval;
} tapmp_unit;

enum { CLOCK_EXACT = 0, CLOCK_ACCUMULATED = 1, CLOCK_NANOSECONDS = 2 };
enum { DONE = 0, FAIL_CALL = 1, SUSPECT_OUTPUT = 2, FAIL_EVENT = 3, EARLY_RETURN = 4, NOT_SETTLED = 5,
       OVERRUN = 6, STOPPED = 7 };
enum { CALL_SET = 0, CALL_STEP = 1, CALL_GET = 2 };
/* FAIL_EVENT calls, in the order _handle_events makes them */
enum { EV_ENTER = 0, EV_CLOCK = 1, EV_SET = 2, EV_UPDATE = 3, EV_GET = 4, EV_STEP_MODE = 5 };
enum { MAX_UPDATE_ROUNDS = 100 };  /* instance.Unit.update_discrete_states */

enum { POLICY_CONTINUE = 0, POLICY_SKIP = 1, POLICY_ABORT = 2 };
enum { HIST_BINS = 1024, FIRST_OVERRUNS = 16 };

/* A log-linear histogram of signed durations [ns]: |v| < 16 ns one bin per ns, above 16 linear
 * bins per power of two (relative width <= 1/16), negative and non-negative values apart. */
typedef struct {
    int64_t n, min, max;
    int64_t neg[HIST_BINS], pos[HIST_BINS];
} tapmp_hist;

typedef struct {
    int32_t policy;                /* POLICY_* */
    int32_t started;               /* 0 until the first paced step sets t0_wall */
    double period_ns;              /* h / factor [ns] */
    int64_t spin_ns;               /* sleep until this long before a release, then spin */
    int64_t t0_wall;               /* CLOCK_MONOTONIC [ns] of communication point k0 */
    int64_t k0;                    /* the communication point pacing started at */
    int64_t dropped;               /* grid slots dropped (policy skip) */
    int64_t release;               /* the earliest start of the next step [ns] */
    int64_t end;                   /* completion of the last paced step [ns] */
    int64_t due;                   /* deadline of the last paced step [ns] */
    int64_t finish;                /* when tapmp_advance_paced returned [ns] (after the last deadline if DONE) */
    int64_t steps, overruns, longest_run, current_run;
    int64_t n_first;               /* overruns listed in first_k, first_late */
    int64_t first_k[FIRST_OVERRUNS], first_late[FIRST_OVERRUNS];
    int64_t ring_waits;            /* times the stepping waited for the reader of the ring */
    tapmp_hist late, exec;
    int64_t window, n_windows;     /* worst lateness per window of steps */
    int64_t *worst;                /* n_windows, filled with INT64_MIN by the caller */
    int64_t trace_n;               /* per-step arrays (0: none) */
    int64_t *trace_late, *trace_exec;
    int32_t n_inject;              /* test hook: busy-wait inject_ns[i] after step inject_k[i] */
    const int64_t *inject_k, *inject_ns;
    volatile const int32_t *stop;  /* set by another thread: return STOPPED before the next step */
} tapmp_pace;

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
    int32_t event_mode;            /* cut macro steps at events, handle them (master._step_events) */
    int32_t n_event;
    const int32_t *event_order;    /* the event units, indices into units in step order */
    tapmp_pace *pace;              /* NULL: as fast as possible */
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
    double t;           /* FAIL_CALL, FAIL_EVENT: the (sub-)step's start or the event time [s];
                           SUSPECT_OUTPUT inside a macro step: the event time */
    int32_t mid;        /* SUSPECT_OUTPUT: 1 if at an event inside the macro step, else 0 */
    double early, target;  /* EARLY_RETURN: lastSuccessfulTime and the time it should have reached [s] */
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
    if (u->fmi3)
        return ((step3_t)u->step)(u->instance, t, h, true, u->event_needed, u->terminate, u->early, u->last_time);
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

/* The tolerance [s] of the Python loop: 8 ulps of |x|, at least 1e-12 s. */
static double ulps8(double x)
{
    double a = fabs(x), d = 8.0 * (nextafter(a, INFINITY) - a);
    return d > 1e-12 ? d : 1e-12;  /* max(1e-12, d) */
}

/* Exchange the values and step every unit from t by h in the planned ordering
 * (master.CoSimulation._substep). Returns 1 on a failed call (s filled in). */
static int substep(const tapmp_plan *p, tapmp_state *s, double t, double h)
{
    s->n_log = *p->log_count;
    s->t = t;
    int64_t errors = *p->log_errors;
    if (!p->jacobi) {
        for (int32_t i = 0; i < p->n_units; i++) {
            int32_t ui = p->step_order[i];
            tapmp_unit *u = &p->units[ui];
            int worst = 0;
            if (failed(p, s, ui, CALL_SET, set_inputs(u), &worst, errors)
                || failed(p, s, ui, CALL_STEP, do_step(u, t, h), &worst, errors)
                || failed(p, s, ui, CALL_GET, get_outputs(u), &worst, errors))
                return 1;
        }
        return 0;
    }
    for (int32_t i = 0; i < p->n_units; i++) {
        int worst = 0, ui = p->step_order[i];
        if (failed(p, s, ui, CALL_SET, set_inputs(&p->units[ui]), &worst, errors))
            return 1;
    }
    for (int32_t i = 0; i < p->n_units; i++) {
        int worst = 0, ui = p->step_order[i];
        if (failed(p, s, ui, CALL_STEP, do_step(&p->units[ui], t, h), &worst, errors))
            return 1;
    }
    for (int32_t i = 0; i < p->n_units; i++) {
        int worst = 0, ui = p->step_order[i];
        if (failed(p, s, ui, CALL_GET, get_outputs(&p->units[ui]), &worst, errors))
            return 1;
    }
    return 0;
}

/* One FMI call in Event Mode (master.CoSimulation._call): 1 if it returned above Warning or an
 * error was logged during it (s filled in: the call and its status). */
static int event_failed(const tapmp_plan *p, tapmp_state *s, int32_t unit, int32_t call, int status,
                        int64_t errors, double t)
{
    if (status > 1 || *p->log_errors != errors) {
        s->outcome = FAIL_EVENT;
        s->unit = unit;
        s->call = call;
        s->status = status;
        s->t = t;
        return 1;
    }
    return 0;
}

/* fmi3UpdateDiscreteStates until settled (instance.Unit.update_discrete_states); 1 on failure. */
static int update_discrete_states(const tapmp_plan *p, tapmp_state *s, int32_t ui, double t)
{
    tapmp_unit *u = &p->units[ui];
    int64_t errors = *p->log_errors;
    for (int round = 0; round < MAX_UPDATE_ROUNDS; round++) {
        bool again = false, terminate = false, nominals = false, values = false, defined = false;
        double next = 0.0;
        int status = ((update3_t)u->update)(u->instance, &again, &terminate, &nominals, &values, &defined, &next);
        if (status > 1)  /* fmpy raises at once, before the log is looked at */
            return event_failed(p, s, ui, EV_UPDATE, status, errors, t);
        u->next_event = defined ? next : INFINITY;
        if (u->n_clocks) {  /* the next tick, as the FMU's grid t0 + k T_s computes it */
            double tick = u->clock_t0 + (double)u->clock_k * u->clock_interval;
            if (tick < u->next_event)
                u->next_event = tick;
        }
        if (!again) {
            u->n_events++;
            return event_failed(p, s, ui, EV_UPDATE, status, errors, t);
        }
    }
    s->outcome = NOT_SETTLED;
    s->unit = ui;
    s->t = t;
    return 1;
}

/* The event units that asked for event handling or whose clocks tick at t, in the step order
 * (master.CoSimulation._handle_events). Returns 1 on failure (s filled in). */
static int handle_events(const tapmp_plan *p, tapmp_state *s, double t)
{
    double tol = ulps8(t);
    for (int32_t e = 0; e < p->n_event; e++) {
        int32_t ui = p->event_order[e];
        tapmp_unit *u = &p->units[ui];
        int tick = u->n_clocks > 0 && fabs(t - u->next_event) <= tol;
        if (!(*u->event_needed || tick))
            continue;
        *u->event_needed = false;  /* handled */
        int64_t errors = *p->log_errors;
        if (event_failed(p, s, ui, EV_ENTER, ((call3_t)u->enter_event)(u->instance), errors, t))
            return 1;
        if (tick) {
            errors = *p->log_errors;
            int status = ((clock3_t)u->set_clock)(u->instance, u->clock_vrs, (size_t)u->n_clocks, u->clock_on);
            if (event_failed(p, s, ui, EV_CLOCK, status, errors, t))
                return 1;
            u->clock_k++;
        }
        errors = *p->log_errors;
        if (event_failed(p, s, ui, EV_SET, set_inputs(u), errors, t)
            || update_discrete_states(p, s, ui, t))
            return 1;
        errors = *p->log_errors;
        if (event_failed(p, s, ui, EV_GET, get_outputs(u), errors, t))
            return 1;
        errors = *p->log_errors;
        if (event_failed(p, s, ui, EV_STEP_MODE, ((call3_t)u->enter_step)(u->instance), errors, t))
            return 1;
    }
    return 0;
}

/* One macro step from t (= t_k) to end (= t_{k+1}) in event mode (master.CoSimulation._step_events):
 * the events due at t, then sub-steps ending at each event inside the step, each followed by its
 * event. Returns 1 on failure (s filled in). */
static int step_events(const tapmp_plan *p, tapmp_state *s, double t, double h, double end)
{
    double tol = ulps8(end);
    if (handle_events(p, s, t))
        return 1;
    double now = t;
    for (;;) {
        double next_event = INFINITY;
        for (int32_t e = 0; e < p->n_event; e++) {
            double x = p->units[p->event_order[e]].next_event;
            if (e == 0 || x < next_event)  /* Python's min() */
                next_event = x;
        }
        int inside = next_event < end - tol;
        double target = inside ? next_event : end;
        /* from t_k the step is h as without events, so a run whose events fall on its grid is the same */
        if (substep(p, s, now, now == t && !inside ? h : target - now))
            return 1;
        for (int32_t e = 0; e < p->n_event; e++) {
            int32_t ui = p->event_order[e];
            tapmp_unit *u = &p->units[ui];
            if (*u->early && *u->last_time < target - tol) {
                s->outcome = EARLY_RETURN;
                s->unit = ui;
                s->early = *u->last_time;
                s->target = target;
                return 1;
            }
        }
        now = target;
        if (!inside)
            return 0;
        if (outputs_suspect(p)) {
            s->outcome = SUSPECT_OUTPUT;
            s->mid = 1;
            s->t = now;
            return 1;
        }
        if (handle_events(p, s, now))
            return 1;
    }
}

static int64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

/* Until CLOCK_MONOTONIC reaches target [ns]: sleep to spin_ns before it, then spin. The spin is
 * there because a sleeping thread wakes up tens of microseconds late on a kernel without
 * real-time preemption (docs/performance.md, "Real time"), a good part of the 100 us servo cycle;
 * spinning the last stretch trades CPU for a release within a few hundred ns. */
static void wait_until(int64_t target, int64_t spin_ns)
{
    int64_t wake = target - spin_ns;
    if (now_ns() < wake) {
        struct timespec ts = {(time_t)(wake / 1000000000), (long)(wake % 1000000000)};
        while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR)
            ;
    }
    while (now_ns() < target)
        ;
}

static int hist_bin(int64_t u)
{
    if (u < 16)
        return (int)u;
    int e = 63 - __builtin_clzll((unsigned long long)u);  /* 2^e <= u, e >= 4 */
    int b = 16 + (e - 4) * 16 + (int)((u >> (e - 4)) & 15);
    return b < HIST_BINS ? b : HIST_BINS - 1;
}

static void hist_add(tapmp_hist *h, int64_t v)
{
    if (h->n == 0 || v < h->min)
        h->min = v;
    if (h->n == 0 || v > h->max)
        h->max = v;
    h->n++;
    if (v < 0)
        h->neg[hist_bin(-v)]++;
    else
        h->pos[hist_bin(v)]++;
}

static int64_t deadline(const tapmp_pace *pc, int64_t j)
{
    return pc->t0_wall + (int64_t)llround((double)j * pc->period_ns);  /* from t0_wall: no drift */
}

/* After step k -> k + 1 started at start [ns]: its lateness and execution time into the
 * statistics, the next release by the overrun policy. Returns 1 if the run must stop (abort). */
static int paced_step_done(tapmp_pace *pc, int64_t k, int64_t start)
{
    for (int32_t i = 0; i < pc->n_inject; i++)  /* the test hook: this step takes longer */
        if (pc->inject_k[i] == k + 1)
            wait_until(now_ns() + pc->inject_ns[i], INT64_MAX);
    int64_t done = now_ns(), j = k + 1 - pc->k0 + pc->dropped, due = deadline(pc, j);
    int64_t late = done - due, n = pc->steps++;
    pc->end = done;
    pc->due = due;
    hist_add(&pc->late, late);
    hist_add(&pc->exec, done - start);
    if (n < pc->trace_n) {
        pc->trace_late[n] = late;
        pc->trace_exec[n] = done - start;
    }
    if (pc->window > 0 && n / pc->window < pc->n_windows && late > pc->worst[n / pc->window])
        pc->worst[n / pc->window] = late;
    pc->release = due;  /* continue: a late step's successor starts at once */
    if (late <= 0) {
        pc->current_run = 0;
        return 0;
    }
    pc->overruns++;
    if (++pc->current_run > pc->longest_run)
        pc->longest_run = pc->current_run;
    if (pc->n_first < FIRST_OVERRUNS) {
        pc->first_k[pc->n_first] = k + 1;
        pc->first_late[pc->n_first++] = late;
    }
    if (pc->policy == POLICY_SKIP) {  /* the next slot of the grid still in the future */
        int64_t m = (int64_t)ceil((double)(done - pc->t0_wall) / pc->period_ns) - j;
        if (m < 1)
            m = 1;
        while (deadline(pc, j + m) < done)
            m++;
        pc->dropped += m;
        pc->release = deadline(pc, j + m);
    }
    return pc->policy == POLICY_ABORT;
}

/* Step from s->k at most n_steps times, storing a row of n_cols doubles per completed step
 * into rows (row-major). Returns s->outcome. */
int tapmp_advance(const tapmp_plan *p, tapmp_state *s, int64_t n_steps, double *rows, int32_t n_cols)
{
    s->rows = 0;
    s->outcome = DONE;
    s->mid = 0;
    tapmp_pace *pc = p->pace;
    for (int64_t n = 0; n < n_steps; n++) {
        int64_t k = s->k, start = 0;
        if (pc) {
            if (*pc->stop) {
                s->outcome = STOPPED;
                return STOPPED;
            }
            if (!pc->started) {
                pc->started = 1;
                pc->k0 = k;
                pc->t0_wall = pc->release = now_ns();
            }
            wait_until(pc->release, pc->spin_ns);
            start = now_ns();
        }
        double t, h;
        if (p->clock == CLOCK_ACCUMULATED) {
            t = s->acc_t;
            h = p->h;
        } else {
            t = time_at(p, k);
            h = p->clock == CLOCK_NANOSECONDS ? time_at(p, k + 1) - t : p->h;
        }
        if (p->event_mode) {
            double end = p->clock == CLOCK_ACCUMULATED ? s->acc_t + p->h : time_at(p, k + 1);
            if (step_events(p, s, t, h, end))
                return s->outcome;
        } else if (substep(p, s, t, h)) {
            return FAIL_CALL;
        }
        s->k = k + 1;
        if (p->clock == CLOCK_ACCUMULATED)
            s->acc_t += p->h;
        int abort = pc ? paced_step_done(pc, k, start) : 0;
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
        if (abort) {
            s->outcome = OVERRUN;
            return OVERRUN;
        }
    }
    return DONE;
}

/* A whole paced run of n_steps: rows into a ring of n_slots blocks of `block` rows each, block j
 * into slot j % n_slots, published by storing j + 1 into *produced once it is whole; a reader on
 * another thread stores into *consumed the blocks it has taken. A full ring waits for the reader
 * (counted in pace->ring_waits: the steps it delays are late like any other). Returns the outcome
 * of the step that stopped it (the rows of that unfinished block: s->rows) or DONE. */
int tapmp_advance_paced(const tapmp_plan *p, tapmp_state *s, int64_t n_steps, double *ring, int32_t n_slots,
                        int64_t block, int32_t n_cols, int64_t *produced, int64_t *consumed)
{
    int64_t done = 0;
    while (done < n_steps) {
        int64_t j = *produced;
        if (j - __atomic_load_n(consumed, __ATOMIC_ACQUIRE) >= n_slots) {
            p->pace->ring_waits++;
            while (j - __atomic_load_n(consumed, __ATOMIC_ACQUIRE) >= n_slots && !*p->pace->stop) {
                struct timespec ts = {0, 20000};
                nanosleep(&ts, NULL);
            }
        }
        int64_t m = n_steps - done < block ? n_steps - done : block;
        int r = tapmp_advance(p, s, m, ring + (size_t)(j % n_slots) * (size_t)block * (size_t)n_cols, n_cols);
        done += s->rows;
        if (r != DONE) {
            p->pace->finish = now_ns();
            return r;
        }
        __atomic_store_n(produced, j + 1, __ATOMIC_RELEASE);
    }
    if (p->pace->started)  /* a run ends no earlier than its last deadline */
        wait_until(p->pace->due, p->pace->spin_ns);
    p->pace->finish = now_ns();  /* here, not in Python: the GIL may keep this thread waiting */
    return DONE;
}
