/* What the runtime's C files share (internal: the model files see only instance.h). The runtime by
 * concern: messages.c (messages, Python's repr), instance.c (life cycle, registry, the allowed-call
 * table, doStep), values.c (get and set), events.c (FMI 3.0 Event Mode and the input clock),
 * fmu_state.c (FMU states and their serialization), model_exchange.c (Model Exchange); fmi2_api.c
 * and fmi3_api.c (with fmi3_clocks.c and fmi3_model_exchange.c) map the FMI functions onto them.
 * A function declared here with TAPMP_LINKAGE is defined without `static` in its file, so it has
 * internal linkage in the one translation unit all.c and external linkage compiled file by file. */
#ifndef TAPMP_RUNTIME_H
#define TAPMP_RUNTIME_H

#include "instance.h"

/* The modes of a Model Exchange instance after initialization (MODE_STEP with me_continuous), as
 * bits of a Model Exchange operation's allowed modes. */
enum { ME_INIT = 1, ME_EVENT = 2, ME_CONTINUOUS = 4 };
#define ME_AFTER_INIT (ME_EVENT | ME_CONTINUOUS)
#define ME_ANY (ME_INIT | ME_EVENT | ME_CONTINUOUS)

/* A Co-Simulation mode as a bit of an operation's allowed modes. */
#define IN(mode) (1u << (mode))
#define IN_ANY (IN(MODE_INSTANTIATED) | IN(MODE_INITIALIZATION) | IN(MODE_STEP) | IN(MODE_TERMINATED) | IN(MODE_EVENT))

/* The operations of the allowed-call table (instance.c, RULES): one row each, with the call's
 * name in each FMI version and the modes it is allowed in. */
typedef enum {
    OP_SETUP_EXPERIMENT, OP_ENTER_INITIALIZATION, OP_EXIT_INITIALIZATION, OP_DO_STEP, OP_TERMINATE, OP_RESET,
    OP_GET_REAL, OP_GET_INTEGER, OP_SET_REAL, OP_SET_INTEGER, OP_GET_DERIVATIVE_VALUE,
    OP_GET_STATE, OP_SET_STATE, OP_FREE_STATE, OP_STATE_SIZE, OP_SERIALIZE, OP_DESERIALIZE,
    OP_ENTER_EVENT_MODE, OP_UPDATE_DISCRETE_STATES, OP_ENTER_STEP_MODE,
    OP_SET_CLOCK, OP_GET_CLOCK, OP_GET_INTERVAL, OP_SET_INTERVAL, OP_GET_SHIFT, OP_SET_SHIFT,
    OP_ME_SET_TIME, OP_ME_SET_STATES, OP_ME_GET_STATES, OP_ME_GET_DERIVATIVES, OP_ME_EVENT_INDICATORS,
    OP_ME_NOMINALS, OP_ME_ENTER_EVENT_MODE, OP_ME_ENTER_CONTINUOUS_TIME_MODE, OP_ME_COMPLETED_INTEGRATOR_STEP,
    OP_ME_UPDATE,
    OP_COUNT
} tapmp_op;

/* ST_OK if `op` may run now (the instance's kind and mode, see RULES), else the logged refusal. */
TAPMP_LINKAGE int tapmp_allowed(tapmp_instance *inst, tapmp_op op);
/* The call's name without the fmi2 / fmi3 prefix, as this instance's FMI version spells it. */
TAPMP_LINKAGE const char *tapmp_call(const tapmp_instance *inst, tapmp_op op);

/* The check at the top of every operation: return the refusal if the call is not allowed now. */
#define ALLOW(inst, op)                                  \
    do {                                                 \
        int allowed_status_ = tapmp_allowed((inst), (op)); \
        if (allowed_status_ != ST_OK) return allowed_status_; \
    } while (0)
/* The same for a call on n values: one on no values touches nothing and is allowed in any mode. */
#define ALLOW_VALUES(inst, op, n)                                      \
    do {                                                               \
        int allowed_status_ = (n) ? tapmp_allowed((inst), (op)) : ST_OK; \
        if (allowed_status_ != ST_OK) return allowed_status_;          \
    } while (0)

/* The name of a mode in messages. */
TAPMP_LINKAGE const char *tapmp_mode_name(tapmp_mode mode);
/* The FMI API functions' instance: `inst` from c, or `error` returned for a NULL, freed or
 * foreign instance (the registry, instance.c). */
#define INSTANCE(c, error)                     \
    tapmp_instance *inst = (tapmp_instance *)(c); \
    if (!tapmp_alive(inst)) return error
/* ST_ERROR for a call this FMU does not support, with "fmi2X is not supported: why" (`call` X
 * without the prefix) logged if `instance` is a live instance. */
TAPMP_LINKAGE int tapmp_unsupported(void *instance, const char *call, const char *why);

/* The tolerance [s] of a communication point or accepted time near `time` (instance.c). */
TAPMP_LINKAGE double tapmp_time_tolerance(double time);
/* The declared ranges of the parameters: 1, or 0 + msg naming the first one outside. */
TAPMP_LINKAGE int tapmp_check_ranges(const tapmp_instance *inst, char *msg, size_t size);
/* After outputs were published at t [s]: if one is not finite, put back `saved` (the outputs
 * before) and write the message naming the first such output; 0 then. */
TAPMP_LINKAGE int tapmp_outputs_finite(tapmp_instance *inst, const double saved[], double t, char *msg, size_t size);
/* The arrays of a get or set: n value references and nv values (ST_OK or the logged error). */
TAPMP_LINKAGE int tapmp_check_arrays(tapmp_instance *inst, const char *call, const unsigned vr[], size_t n,
                                     const void *v, size_t nv);

/* The allowed text of an output that overflowed. */
#define OVERFLOW "a finite number (the output overflowed; check the inputs and parameters)"

#endif
