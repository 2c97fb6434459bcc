/* Python binding of the TAPMP FMUs (tapmp_fmi2_python.so), loaded by fmi2_front.c.
 *
 * One instance = one Python object of the FMU's TapmpSlave subclass (fmu_common/slave.py).
 * Variable values live in two Python arrays (array('d') and array('i'), indexed by value
 * reference) that this library reads and writes directly through the buffer protocol,
 * so fmi2GetReal, fmi2GetInteger and fmi2SetReal of inputs never enter Python; doStep,
 * parameters, initialization and FMU states call one method of the slave each.
 *
 * Initial unknowns: in Initialization Mode a master may set inputs and parameters and read
 * the outputs before fmi2ExitInitializationMode (fmpy's container runtime copies every
 * connection once that way; Ecos sets parameters there). So a set in Initialization Mode
 * marks the outputs stale, and the next get recomputes them first (one Python call,
 * slave.fmi2_update_initial_unknowns); in Step Mode gets stay Python-free.
 *
 * Status codes: every slave method returns an fmi2Status, plus FLAG_LOGS when it queued
 * log messages; a Python exception (a bug, never bad input) becomes fmi2Error with the
 * exception logged. Error and warning messages always reach the logger; others only with
 * debug logging on. Nothing here terminates or finalizes the interpreter. */
#define _GNU_SOURCE  /* dladdr */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <pthread.h>

#include "fmi2FunctionTypes.h"
#include "python_env.h"

#define EXPORT __attribute__((visibility("default")))
#define FLAG_LOGS 8

typedef struct {
    PyObject *slave, *do_step;
    Py_buffer reals, ints;      /* slave.reals (float64) and slave.ints (int32) */
    PyObject *kinds;            /* bytes, one per value reference: i p o (Real) I (Integer) */
    Py_ssize_t n;
    fmi2CallbackLogger logger;
    fmi2ComponentEnvironment env;
    char *name;
    int logging_on;
    int init_mode;              /* the slave is in Initialization Mode (see sync_mode) */
    int stale;                  /* a value was set in Initialization Mode since the last get */
    int terminated;             /* in Terminated: sets go to the slave, which refuses them */
} Instance;

/* The logger's message is a printf format (FMI 2.0), so a literal '%' is passed as "%%". */
static void emit(Instance *I, fmi2Status status, const char *category, const char *msg)
{
    char escaped[2048];
    size_t k = 0;
    if (!I->logger || (status < fmi2Warning && !I->logging_on)) return;
    for (; *msg && k + 2 < sizeof escaped; msg++) {
        if (*msg == '%') escaped[k++] = '%';
        escaped[k++] = *msg;
    }
    escaped[k] = '\0';
    I->logger(I->env, I->name, status, category, escaped);
}

static void log_c(Instance *I, fmi2Status status, const char *fmt, ...)
{
    char msg[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    emit(I, status, status >= fmi2Error ? "logStatusError" : "logAll", msg);
}

/* Logs the pending Python exception at fmi2Error and clears it. GIL held. */
static void log_exception(Instance *I, const char *where)
{
    PyObject *type, *value, *tb;
    PyErr_Fetch(&type, &value, &tb);
    PyErr_NormalizeException(&type, &value, &tb);
    PyObject *text = value ? PyObject_Str(value) : NULL;
    const char *msg = text ? PyUnicode_AsUTF8(text) : NULL;
    const char *tname = type ? ((PyTypeObject *)type)->tp_name : "?";
    if (!msg) { PyErr_Clear(); msg = "(no message)"; }
    const char *dot = strrchr(tname, '.');
    if (strcmp(dot ? dot + 1 : tname, "GuidMismatch") == 0)  /* bad input of the host, not a bug */
        log_c(I, fmi2Error, "%s", msg);
    else
        log_c(I, fmi2Error, "%s failed with a Python exception (a bug in the FMU): %s: %s", where, tname,
              msg);
    Py_XDECREF(text);
    Py_XDECREF(type);
    Py_XDECREF(value);
    Py_XDECREF(tb);
}

/* Forwards the slave's queued (status, category, message) log records. GIL held. */
static void flush_logs(Instance *I)
{
    PyObject *records = PyObject_CallMethod(I->slave, "fmi2_take_logs", NULL);
    if (!records) { log_exception(I, "fmi2_take_logs"); return; }
    Py_ssize_t n = PyList_Size(records);
    for (Py_ssize_t k = 0; k < n; k++) {
        int status;
        const char *category, *message;
        if (!PyArg_ParseTuple(PyList_GET_ITEM(records, k), "iss", &status, &category, &message)) {
            log_exception(I, "fmi2_take_logs");
            break;
        }
        emit(I, (fmi2Status)status, category, message);
    }
    Py_DECREF(records);
}

/* Turns a slave method's result (new reference or NULL) into an fmi2Status. GIL held. */
static fmi2Status finish(Instance *I, PyObject *result, const char *where)
{
    if (!result) {
        log_exception(I, where);
        return fmi2Error;
    }
    long code = PyLong_AsLong(result);
    Py_DECREF(result);
    if (code == -1 && PyErr_Occurred()) {
        log_exception(I, where);
        return fmi2Error;
    }
    if (code & FLAG_LOGS) flush_logs(I);
    code &= 7;
    return code <= fmi2Pending ? (fmi2Status)code : fmi2Error;
}

#define WITH_GIL(I, where, call)                                                               \
    do {                                                                                       \
        PyGILState_STATE gil_ = PyGILState_Ensure();                                           \
        fmi2Status status_ = finish((I), (call), (where));                                     \
        PyGILState_Release(gil_);                                                              \
        return status_;                                                                        \
    } while (0)

/* ---- interpreter (only when the host has none) -------------------------------------- */

static pthread_mutex_t init_lock = PTHREAD_MUTEX_INITIALIZER;

typedef struct { PyConfig *config; PyObject *paths; int phase; } EnvCtx;

static void apply_env(const char *key, const char *value, void *ctx)
{
    EnvCtx *e = ctx;
    if (e->phase == 0 && strcmp(key, "home") == 0 && !getenv("PYTHONHOME"))
        PyConfig_SetBytesString(e->config, &e->config->home, value);
    if (e->phase == 1 && strcmp(key, "path") == 0) {
        PyObject *p = PyUnicode_DecodeFSDefault(value);
        if (p) { PyList_Append(e->paths, p); Py_DECREF(p); }
    }
}

/* Starts Python in a host that has none, with the home and site-packages recorded in
 * python-env.txt; the main thread then releases the GIL for good. */
static int ensure_python(char *why, size_t size)
{
    int ok = 1;
    pthread_mutex_lock(&init_lock);
    if (!Py_IsInitialized()) {
        char dir[TAPMP_PATH_MAX];
        PyConfig config;
        PyConfig_InitPythonConfig(&config);
        config.install_signal_handlers = 0;  /* the host owns SIGINT */
        config.parse_argv = 0;
        EnvCtx ctx = {&config, NULL, 0};
        int have_env = tapmp_binary_dir((const void *)&ensure_python, dir, sizeof dir) &&
                       tapmp_read_python_env(dir, apply_env, &ctx);
        PyStatus st = Py_InitializeFromConfig(&config);
        PyConfig_Clear(&config);
        if (PyStatus_Exception(st)) {
            snprintf(why, size, "cannot start Python: %s", st.err_msg ? st.err_msg : "?");
            ok = 0;
        } else {
            if (have_env) {  /* site.addsitedir also honours .pth files (editable installs) */
                ctx.phase = 1;
                ctx.paths = PyList_New(0);
                tapmp_read_python_env(dir, apply_env, &ctx);
                PyObject *site = PyImport_ImportModule("site");
                for (Py_ssize_t k = 0; site && k < PyList_GET_SIZE(ctx.paths); k++) {
                    PyObject *r = PyObject_CallMethod(site, "addsitedir", "O",
                                                      PyList_GET_ITEM(ctx.paths, k));
                    Py_XDECREF(r);
                }
                if (PyErr_Occurred()) PyErr_Clear();
                Py_XDECREF(site);
                Py_DECREF(ctx.paths);
            }
            PyEval_SaveThread();
        }
    }
    pthread_mutex_unlock(&init_lock);
    return ok;
}

/* file:///a%20b/ -> /a b/ (RFC 8089 local file URIs, as FMI 2.0 prescribes). */
static int uri_to_path(const char *uri, char *path, size_t size)
{
    if (strncmp(uri, "file://", 7) == 0) {
        uri += 7;
        if (strncmp(uri, "localhost/", 10) == 0) uri += 9;
    } else if (strncmp(uri, "file:", 5) == 0) {
        uri += 5;
    }
    size_t k = 0;
    for (; *uri && k + 1 < size; uri++) {
        unsigned int byte;
        if (uri[0] == '%' && sscanf(uri + 1, "%2x", &byte) == 1) {
            path[k++] = (char)byte;
            uri += 2;
        } else {
            path[k++] = *uri;
        }
    }
    path[k] = '\0';
    return k > 0;
}

/* ---- life cycle ---------------------------------------------------------------------- */

static void release(Instance *I)
{
    if (I->reals.obj) PyBuffer_Release(&I->reals);
    if (I->ints.obj) PyBuffer_Release(&I->ints);
    Py_XDECREF(I->kinds);
    Py_XDECREF(I->do_step);
    Py_XDECREF(I->slave);
}

/* Creates the slave object and takes its value arrays. GIL held; 0 on failure (logged). */
static int create_slave(Instance *I, const char *resources, fmi2Boolean visible, const char *guid)
{
    PyObject *sys_path = PySys_GetObject("path");  /* borrowed */
    PyObject *dir = PyUnicode_DecodeFSDefault(resources);
    if (!dir || !sys_path) goto fail;
    int present = PySequence_Contains(sys_path, dir);
    if (present == 0 && PyList_Insert(sys_path, 0, dir) < 0) present = -1;
    if (present < 0) { Py_DECREF(dir); goto fail; }
    PyObject *binding = PyImport_ImportModule("fmu_common.binding");
    if (!binding) { Py_DECREF(dir); goto fail; }
    I->slave = PyObject_CallMethod(binding, "instantiate", "Osiis", dir, I->name, (int)visible,
                                   I->logging_on, guid ? guid : "");
    Py_DECREF(binding);
    Py_DECREF(dir);
    if (!I->slave) goto fail;
    I->do_step = PyObject_GetAttrString(I->slave, "fmi2_do_step");
    I->kinds = PyObject_GetAttrString(I->slave, "kinds");
    PyObject *reals = PyObject_GetAttrString(I->slave, "reals");
    PyObject *ints = PyObject_GetAttrString(I->slave, "ints");
    int got = I->do_step && I->kinds && PyBytes_Check(I->kinds) && reals && ints &&
              PyObject_GetBuffer(reals, &I->reals, PyBUF_WRITABLE | PyBUF_FORMAT) == 0 &&
              PyObject_GetBuffer(ints, &I->ints, PyBUF_WRITABLE | PyBUF_FORMAT) == 0;
    Py_XDECREF(reals);
    Py_XDECREF(ints);
    if (!got) goto fail;
    I->n = PyBytes_GET_SIZE(I->kinds);
    if (I->reals.itemsize != sizeof(double) || I->ints.itemsize != sizeof(int) ||
        I->reals.len != I->n * (Py_ssize_t)sizeof(double) ||
        I->ints.len != I->n * (Py_ssize_t)sizeof(int)) {
        log_c(I, fmi2Error, "slave value arrays do not match its %zd variables", I->n);
        return 0;
    }
    return 1;
fail:
    if (PyErr_Occurred()) log_exception(I, "fmi2Instantiate");
    return 0;
}

EXPORT fmi2Component tapmp_Instantiate(fmi2String instanceName, fmi2Type fmuType,
                                       fmi2String fmuGUID, fmi2String fmuResourceLocation,
                                       const fmi2CallbackFunctions *functions,
                                       fmi2Boolean visible, fmi2Boolean loggingOn)
{
    Instance *I = calloc(1, sizeof *I);
    if (!I) return NULL;
    I->name = strdup(instanceName ? instanceName : "");
    I->logging_on = loggingOn ? 1 : 0;
    if (functions) { I->logger = functions->logger; I->env = functions->componentEnvironment; }
    char why[1024], resources[TAPMP_PATH_MAX];
    if (fmuType != fmi2CoSimulation) {
        log_c(I, fmi2Error, "fmi2Instantiate: fmuType = %d is invalid: allowed is fmi2CoSimulation",
              (int)fmuType);
        goto fail;
    }
    if (!fmuResourceLocation || !uri_to_path(fmuResourceLocation, resources, sizeof resources)) {
        log_c(I, fmi2Error, "fmi2Instantiate: fmuResourceLocation = '%s' is invalid: allowed is a "
              "file:// URI of the FMU's resources folder",
              fmuResourceLocation ? fmuResourceLocation : "(null)");
        goto fail;
    }
    if (!ensure_python(why, sizeof why)) {
        log_c(I, fmi2Error, "fmi2Instantiate: %s", why);
        goto fail;
    }
    PyGILState_STATE gil = PyGILState_Ensure();
    int ok = create_slave(I, resources, visible, fmuGUID);
    if (!ok) release(I);
    PyGILState_Release(gil);
    if (ok) return I;
fail:
    free(I->name);
    free(I);
    return NULL;
}

EXPORT void tapmp_FreeInstance(fmi2Component c)
{
    Instance *I = c;
    PyGILState_STATE gil = PyGILState_Ensure();
    release(I);
    PyGILState_Release(gil);
    free(I->name);
    free(I);
}

EXPORT fmi2Status tapmp_SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n,
                                        const fmi2String categories[])
{
    (void)n; (void)categories;  /* categories are not filtered: errors always, the rest if on */
    ((Instance *)c)->logging_on = on ? 1 : 0;
    return fmi2OK;
}

EXPORT fmi2Status tapmp_SetupExperiment(fmi2Component c, fmi2Boolean tolDefined, fmi2Real tol,
                                        fmi2Real start, fmi2Boolean stopDefined, fmi2Real stop)
{
    Instance *I = c;
    PyGILState_STATE gil = PyGILState_Ensure();
    PyObject *py_stop = stopDefined ? PyFloat_FromDouble(stop) : (Py_INCREF(Py_None), Py_None);
    PyObject *py_tol = tolDefined ? PyFloat_FromDouble(tol) : (Py_INCREF(Py_None), Py_None);
    fmi2Status s = finish(I, PyObject_CallMethod(I->slave, "fmi2_setup_experiment", "dOO", start,
                                                 py_stop, py_tol), "fmi2SetupExperiment");
    Py_XDECREF(py_stop);
    Py_XDECREF(py_tol);
    PyGILState_Release(gil);
    return s;
}

/* Reads the slave's mode after a call that may change it. GIL held. */
static void sync_mode(Instance *I)
{
    PyObject *mode = PyObject_GetAttrString(I->slave, "mode");
    I->init_mode = mode && PyUnicode_Check(mode) &&
                   PyUnicode_CompareWithASCIIString(mode, "initialization") == 0;
    I->terminated = mode && PyUnicode_Check(mode) &&
                    PyUnicode_CompareWithASCIIString(mode, "terminated") == 0;
    I->stale = I->init_mode;
    Py_XDECREF(mode);
    PyErr_Clear();
}

#define SIMPLE(fn, method)                                                                     \
    EXPORT fmi2Status tapmp_##fn(fmi2Component c)                                              \
    {                                                                                          \
        Instance *I = c;                                                                       \
        PyGILState_STATE gil = PyGILState_Ensure();                                            \
        fmi2Status s = finish(I, PyObject_CallMethod(I->slave, method, NULL), "fmi2" #fn);     \
        sync_mode(I);                                                                          \
        PyGILState_Release(gil);                                                               \
        return s;                                                                              \
    }
SIMPLE(EnterInitializationMode, "fmi2_enter_initialization_mode")
SIMPLE(ExitInitializationMode, "fmi2_exit_initialization_mode")
SIMPLE(Terminate, "fmi2_terminate")
SIMPLE(Reset, "fmi2_reset")

EXPORT fmi2Status tapmp_DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior)
{
    (void)noSetPrior;
    Instance *I = c;
    PyObject *args[2];
    PyGILState_STATE gil = PyGILState_Ensure();
    args[0] = PyFloat_FromDouble(t);
    args[1] = PyFloat_FromDouble(h);
    PyObject *r = (args[0] && args[1]) ? PyObject_Vectorcall(I->do_step, args, 2, NULL) : NULL;
    Py_XDECREF(args[0]);
    Py_XDECREF(args[1]);
    fmi2Status s = finish(I, r, "fmi2DoStep");
    PyGILState_Release(gil);
    return s;
}

/* ---- values -------------------------------------------------------------------------- */

static int is_real(Instance *I, fmi2ValueReference vr)
{
    if ((Py_ssize_t)vr >= I->n) return 0;
    char k = PyBytes_AS_STRING(I->kinds)[vr];
    return k == 'i' || k == 'p' || k == 'o';
}

static fmi2Status bad_reference(Instance *I, const char *fn, fmi2ValueReference vr, const char *type)
{
    log_c(I, fmi2Error, "%s: value reference %u is invalid: allowed is the value reference of a "
          "%s variable of this FMU (see modelDescription.xml)", fn, (unsigned)vr, type);
    return fmi2Error;
}

/* Recomputes the outputs after values were set in Initialization Mode. */
static fmi2Status update_initial_unknowns(Instance *I, const char *fn)
{
    PyGILState_STATE gil = PyGILState_Ensure();
    fmi2Status s = finish(I, PyObject_CallMethod(I->slave, "fmi2_update_initial_unknowns", NULL), fn);
    PyGILState_Release(gil);
    I->stale = 0;
    return s;
}

EXPORT fmi2Status tapmp_GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                fmi2Real value[])
{
    Instance *I = c;
    const double *reals = I->reals.buf;
    fmi2Status s = I->stale ? update_initial_unknowns(I, "fmi2GetReal") : fmi2OK;
    if (s >= fmi2Error) return s;
    for (size_t k = 0; k < n; k++) {
        if (!is_real(I, vr[k])) return bad_reference(I, "fmi2GetReal", vr[k], "Real");
        value[k] = reals[vr[k]];
    }
    return s;
}

EXPORT fmi2Status tapmp_GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                   fmi2Integer value[])
{
    Instance *I = c;
    const int *ints = I->ints.buf;
    fmi2Status s = I->stale ? update_initial_unknowns(I, "fmi2GetInteger") : fmi2OK;
    if (s >= fmi2Error) return s;
    for (size_t k = 0; k < n; k++) {
        if ((Py_ssize_t)vr[k] >= I->n || PyBytes_AS_STRING(I->kinds)[vr[k]] != 'I')
            return bad_reference(I, "fmi2GetInteger", vr[k], "Integer");
        value[k] = ints[vr[k]];
    }
    return s;
}

/* Inputs are stored here without Python (the hot path); a non-finite input is refused by
 * the slave (fmi2_reject_input logs it); parameters go through fmi2_set_real, which checks
 * them and the mode. */
EXPORT fmi2Status tapmp_SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                const fmi2Real value[])
{
    Instance *I = c;
    double *reals = I->reals.buf;
    fmi2Status worst = fmi2OK;
    for (size_t k = 0; k < n; k++) {
        if (!is_real(I, vr[k])) return bad_reference(I, "fmi2SetReal", vr[k], "Real");
        I->stale |= I->init_mode;
        int input = PyBytes_AS_STRING(I->kinds)[vr[k]] == 'i';
        if (input && isfinite(value[k]) && !I->terminated) {
            reals[vr[k]] = value[k];
            continue;
        }
        const char *method = input && !I->terminated ? "fmi2_reject_input" : "fmi2_set_real";
        PyGILState_STATE gil = PyGILState_Ensure();
        fmi2Status s = finish(I, PyObject_CallMethod(I->slave, method, "Id", (unsigned)vr[k],
                                                     value[k]), "fmi2SetReal");
        PyGILState_Release(gil);
        if (s > worst) worst = s;
    }
    return worst;
}

EXPORT fmi2Status tapmp_SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                   const fmi2Integer value[])
{
    Instance *I = c;
    fmi2Status worst = fmi2OK;
    for (size_t k = 0; k < n; k++) {
        if ((Py_ssize_t)vr[k] >= I->n || PyBytes_AS_STRING(I->kinds)[vr[k]] != 'I')
            return bad_reference(I, "fmi2SetInteger", vr[k], "Integer");
        I->stale |= I->init_mode;
        PyGILState_STATE gil = PyGILState_Ensure();
        fmi2Status s = finish(I, PyObject_CallMethod(I->slave, "fmi2_set_integer", "Ii",
                                                     (unsigned)vr[k], (int)value[k]),
                              "fmi2SetInteger");
        PyGILState_Release(gil);
        if (s > worst) worst = s;
    }
    return worst;
}

#define NO_VARIABLES(fn, T, CONST)                                                             \
    EXPORT fmi2Status tapmp_##fn(fmi2Component c, const fmi2ValueReference vr[], size_t n,    \
                                 CONST T value[])                                              \
    {                                                                                          \
        (void)value;                                                                           \
        return n ? bad_reference(c, "fmi2" #fn, vr[0], #T + 4) : fmi2OK;                       \
    }
NO_VARIABLES(GetBoolean, fmi2Boolean, )
NO_VARIABLES(GetString, fmi2String, )
NO_VARIABLES(SetBoolean, fmi2Boolean, const)
NO_VARIABLES(SetString, fmi2String, const)

/* ---- FMU state: an opaque Python object made by the slave ------------------------------ */

/* slave.<method>(arg); not PyObject_CallMethod(.., "O", arg), which unpacks a tuple arg. */
static PyObject *call_with(Instance *I, const char *method, PyObject *arg)
{
    PyObject *name = PyUnicode_FromString(method);
    PyObject *r = name ? PyObject_CallMethodObjArgs(I->slave, name, arg, NULL) : NULL;
    Py_XDECREF(name);
    return r;
}

EXPORT fmi2Status tapmp_GetFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    Instance *I = c;
    PyGILState_STATE gil = PyGILState_Ensure();
    PyObject *s = PyObject_CallMethod(I->slave, "fmi2_get_state", NULL);
    fmi2Status status = fmi2OK;
    if (!s) {
        log_exception(I, "fmi2GetFMUstate");
        status = fmi2Error;
    } else {
        Py_XDECREF((PyObject *)*state);  /* FMI: a non-NULL state is overwritten */
        *state = s;
    }
    PyGILState_Release(gil);
    return status;
}

EXPORT fmi2Status tapmp_SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    Instance *I = c;
    if (!state) { log_c(I, fmi2Error, "fmi2SetFMUstate: FMUstate = NULL is invalid"); return fmi2Error; }
    PyGILState_STATE gil = PyGILState_Ensure();
    fmi2Status s = finish(I, call_with(I, "fmi2_set_state", (PyObject *)state), "fmi2SetFMUstate");
    sync_mode(I);
    PyGILState_Release(gil);
    return s;
}

EXPORT fmi2Status tapmp_FreeFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    (void)c;
    if (!state || !*state) return fmi2OK;
    PyGILState_STATE gil = PyGILState_Ensure();
    Py_DECREF((PyObject *)*state);
    PyGILState_Release(gil);
    *state = NULL;
    return fmi2OK;
}

/* Serialized bytes of `state` (new reference) or NULL with the error logged. GIL held. */
static PyObject *serialize(Instance *I, fmi2FMUstate state)
{
    PyObject *b = state ? call_with(I, "fmi2_serialize", (PyObject *)state) : NULL;
    if (b && !PyBytes_Check(b)) Py_CLEAR(b);
    if (!b) {
        if (PyErr_Occurred()) log_exception(I, "fmi2SerializeFMUstate");
        else log_c(I, fmi2Error, "fmi2SerializeFMUstate: no valid FMUstate given");
    }
    return b;
}

EXPORT fmi2Status tapmp_SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    Instance *I = c;
    PyGILState_STATE gil = PyGILState_Ensure();
    PyObject *b = serialize(I, state);
    if (b) *size = (size_t)PyBytes_GET_SIZE(b);
    Py_XDECREF(b);
    PyGILState_Release(gil);
    return b ? fmi2OK : fmi2Error;
}

EXPORT fmi2Status tapmp_SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[],
                                          size_t size)
{
    Instance *I = c;
    fmi2Status status = fmi2Error;
    PyGILState_STATE gil = PyGILState_Ensure();
    PyObject *b = serialize(I, state);
    if (b && (size_t)PyBytes_GET_SIZE(b) <= size) {
        memcpy(bytes, PyBytes_AS_STRING(b), (size_t)PyBytes_GET_SIZE(b));
        status = fmi2OK;
    } else if (b) {
        log_c(I, fmi2Error, "fmi2SerializeFMUstate: size = %zu is invalid: allowed is >= %zd "
              "(from fmi2SerializedFMUstateSize)", size, PyBytes_GET_SIZE(b));
    }
    Py_XDECREF(b);
    PyGILState_Release(gil);
    return status;
}

EXPORT fmi2Status tapmp_DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size,
                                            fmi2FMUstate *state)
{
    Instance *I = c;
    PyGILState_STATE gil = PyGILState_Ensure();
    PyObject *s = PyObject_CallMethod(I->slave, "fmi2_deserialize", "y#", bytes, (Py_ssize_t)size);
    if (s) {
        Py_XDECREF((PyObject *)*state);
        *state = s;
    } else {
        log_exception(I, "fmi2DeSerializeFMUstate");
    }
    PyGILState_Release(gil);
    return s ? fmi2OK : fmi2Error;
}

/* ---- capabilities this FMU does not declare ---------------------------------------------- */

static fmi2Status unsupported(fmi2Component c, const char *fn)
{
    log_c(c, fmi2Error, "%s is not supported by this FMU (see its modelDescription.xml)", fn);
    return fmi2Error;
}

EXPORT fmi2Status tapmp_GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[],
                                                 size_t nu, const fmi2ValueReference z[], size_t nz,
                                                 const fmi2Real dv[], fmi2Real dz[])
{
    (void)u; (void)nu; (void)z; (void)nz; (void)dv; (void)dz;
    return unsupported(c, "fmi2GetDirectionalDerivative");
}

EXPORT fmi2Status tapmp_SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                                size_t n, const fmi2Integer order[],
                                                const fmi2Real v[])
{
    (void)vr; (void)n; (void)order; (void)v;
    return unsupported(c, "fmi2SetRealInputDerivatives");
}

EXPORT fmi2Status tapmp_GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                                 size_t n, const fmi2Integer order[], fmi2Real v[])
{
    (void)vr; (void)n; (void)order; (void)v;
    return unsupported(c, "fmi2GetRealOutputDerivatives");
}

EXPORT fmi2Status tapmp_CancelStep(fmi2Component c)
{
    return unsupported(c, "fmi2CancelStep");
}

/* doStep is never asynchronous, so there is no status to ask for (FMI 2.0: fmi2Discard). */
#define NO_STATUS(fn, T)                                                                       \
    EXPORT fmi2Status tapmp_##fn(fmi2Component c, const fmi2StatusKind s, T *value)           \
    {                                                                                          \
        (void)c; (void)s; (void)value;                                                         \
        return fmi2Discard;                                                                    \
    }
NO_STATUS(GetStatus, fmi2Status)
NO_STATUS(GetRealStatus, fmi2Real)
NO_STATUS(GetIntegerStatus, fmi2Integer)
NO_STATUS(GetBooleanStatus, fmi2Boolean)
NO_STATUS(GetStringStatus, fmi2String)
