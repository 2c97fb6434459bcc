/* The model operations of instance.h for a pythonfmu TAPMP FMU: each calls one method of
 * the adapter's Python object (fmu_common/slave.py), so the FMI rules, statuses and messages
 * are the runtime's (fmu_common/c) and fmi2_api.c's, the same as the native FMUs'. Compiled per model with
 * them into tapmp_fmi2_python.so, which fmi2_front.c loads once Python is in the process.
 *
 * Values live in the instance (get and set never enter Python); before a Python call they
 * are copied into the object's two arrays (slave.reals, float64, and slave.ints, int32,
 * indexed by value reference) and the outputs it computed are copied back. The Python model
 * is one live object per instance, while FMU states copy the instance: each state of the
 * live model has a stamp, and a call on an instance whose model data carries another stamp
 * (after SetFMUstate or Reset) first restores the Python model from the hidden state there.
 *
 * A Python exception (a bug, never bad input) is an error status with the exception logged;
 * log records the object queued are passed on after each call. Nothing here terminates or
 * finalizes the interpreter. */
#include <math.h>
#include <pthread.h>

#include "python_env.h"
#include "uri.h"

typedef struct {
    PyObject *slave, *records;  /* the adapter's object and its queue of log records (a list) */
    Py_buffer reals, ints;      /* slave.reals and slave.ints */
    unsigned long live;         /* the stamp of the Python model's current state */
    PyObject *evicted;          /* the JSON of the state the model last left (sync_model) */
    unsigned long evicted_stamp;
} py_backend;

static unsigned long last_stamp;  /* stamps are unique in the process */
static pthread_mutex_t init_lock = PTHREAD_MUTEX_INITIALIZER;

static unsigned long new_stamp(void)
{
    pthread_mutex_lock(&init_lock);
    unsigned long s = ++last_stamp;
    pthread_mutex_unlock(&init_lock);
    return s;
}

/* ---- interpreter (only when the host has none) -------------------------------------- */

typedef struct { PyConfig *config; PyObject *paths; int phase; } env_ctx;

static void apply_env(const char *key, const char *value, void *ctx)
{
    env_ctx *e = ctx;
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
        env_ctx ctx = {&config, NULL, 0};
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
                    PyObject *r = PyObject_CallMethod(site, "addsitedir", "O", PyList_GET_ITEM(ctx.paths, k));
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

static int resources_dir(const char *location, char *path, size_t size, char *why, size_t why_size)
{
    if (location && uri_to_path(location, path, size)) return 1;
    snprintf(why, why_size, "fmuResourceLocation = '%s' is invalid: allowed is a file:// URI of the FMU's "
             "resources folder on this machine (file:///path or file://localhost/path; each %% followed by two "
             "hex digits, not %%00)", location ? location : "(null)");
    return 0;
}

/* ---- calls into Python ---------------------------------------------------------------- */

/* Logs the pending Python exception as an error of `where` and clears it. GIL held. */
static void log_exception(tapmp_instance *inst, const char *where)
{
    PyObject *type, *value, *tb;
    PyErr_Fetch(&type, &value, &tb);
    PyErr_NormalizeException(&type, &value, &tb);
    PyObject *text = value ? PyObject_Str(value) : NULL;
    const char *msg = text ? PyUnicode_AsUTF8(text) : NULL;
    if (!msg) { PyErr_Clear(); msg = "(no message)"; }
    tapmp_fail(inst, "%s failed with a Python exception (a bug in the FMU): %s: %s", where,
               type ? ((PyTypeObject *)type)->tp_name : "?", msg);
    Py_XDECREF(text);
    Py_XDECREF(type);
    Py_XDECREF(value);
    Py_XDECREF(tb);
}

/* Passes on the (status, category, message) records the object queued: an error as
 * tapmp_log does (the first is kept, doStep refused from then on), a warning always and
 * the rest with debug logging on, as the native models log. GIL held. */
static void flush_logs(tapmp_instance *inst, py_backend *B)
{
    Py_ssize_t n = PyList_GET_SIZE(B->records);
    for (Py_ssize_t k = 0; k < n; k++) {
        int status;
        const char *category, *message;
        if (!PyArg_ParseTuple(PyList_GET_ITEM(B->records, k), "iss", &status, &category, &message)) {
            log_exception(inst, "log");
            break;
        }
        if (status >= ST_ERROR) tapmp_log(inst, status, category, "%s", message);
        else if (inst->log && (inst->logging_on || status >= ST_WARNING)) inst->log(inst, status, category, message);
    }
    PyList_SetSlice(B->records, 0, n, NULL);
}

static PyObject *call(py_backend *B, const char *method, PyObject *arg)
{
    PyObject *name = PyUnicode_FromString(method);
    PyObject *r = name ? PyObject_CallMethodObjArgs(B->slave, name, arg, NULL) : NULL;
    Py_XDECREF(name);
    return r;
}

/* The hidden state's JSON from its character codes (inst->m.hidden: whole numbers 1 to 255,
 * then zeros, as model_capture writes them and model_check_hidden checks them): a new str, or NULL. */
static PyObject *hidden_text(const double hidden[])
{
    char text[MODEL_N_HIDDEN + 1];
    int n = 0;
    while (n < MODEL_N_HIDDEN && hidden[n] >= 1.0 && hidden[n] <= 255.0) {
        text[n] = (char)(unsigned char)hidden[n];
        n++;
    }
    return PyUnicode_DecodeUTF8(text, n, "strict");
}

/* Restores the Python model from inst->m if it is in another state; 0 on failure (logged).
 * The state it leaves is kept as JSON (evicted): the instance it belongs to may come back
 * to it without having captured it (a state that SetFMUstate refused was checked on the
 * model, say). GIL held, values pushed. */
static int sync_model(tapmp_instance *inst, py_backend *B)
{
    if (inst->m.stamp == B->live) return 1;
    PyObject *text = NULL;
    if (inst->m.hidden[0] > 0.0) {
        if (!(text = hidden_text(inst->m.hidden))) {
            log_exception(inst, "restore_hidden_state");
            return 0;
        }
    } else if (B->evicted && inst->m.stamp == B->evicted_stamp) {
        text = B->evicted;
        Py_INCREF(text);
    }
    if (!text) {  /* never captured (the model data before a failed step): the model stays */
        B->live = inst->m.stamp;
        return 1;
    }
    PyObject *current = call(B, "fmi2_hidden", NULL);
    if (current) {
        Py_XDECREF(B->evicted);
        B->evicted = current;
        B->evicted_stamp = B->live;
    } else {
        PyErr_Clear();
    }
    PyObject *r = call(B, "fmi2_restore", text);
    Py_DECREF(text);
    if (!r) {
        log_exception(inst, "restore_hidden_state");
        return 0;
    }
    Py_DECREF(r);
    B->live = inst->m.stamp;
    return 1;
}

/* Takes the GIL and gives the object the instance's values and time, and with `sync` the
 * instance's model state (sync_model); NULL on failure (logged). A call that only checks values
 * (of an FMU state, say) does not sync: it leaves the live model as it is. */
static py_backend *begin(const tapmp_instance *c, PyGILState_STATE *gil, int sync)
{
    tapmp_instance *inst = (tapmp_instance *)c;  /* logging may record the error */
    py_backend *B = inst->backend;
    *gil = PyGILState_Ensure();
    memcpy(B->reals.buf, inst->reals, sizeof inst->reals);
    memcpy(B->ints.buf, inst->ints, sizeof inst->ints);
    PyObject *t = PyFloat_FromDouble(inst->time);
    int ok = t && PyObject_SetAttrString(B->slave, "time", t) == 0;
    Py_XDECREF(t);
    if (!ok) log_exception(inst, "time");
    if (ok && sync && inst->has_model) ok = sync_model(inst, B);
    if (!ok) {
        PyGILState_Release(*gil);
        return NULL;
    }
    return B;
}

static void end(const tapmp_instance *inst, py_backend *B, PyGILState_STATE gil)
{
    if (PyList_GET_SIZE(B->records)) flush_logs((tapmp_instance *)inst, B);
    PyGILState_Release(gil);
}

/* A call of a method that returns None or the message of a bad value: 1, or 0 with the
 * message (or the exception's) in msg. GIL held. */
static int checked(tapmp_instance *inst, PyObject *r, const char *where, char *msg, size_t size)
{
    if (!r) {
        log_exception(inst, where);
        snprintf(msg, size, "%s", inst->error);
        return 0;
    }
    int ok = r == Py_None;
    if (!ok) {
        const char *text = PyUnicode_Check(r) ? PyUnicode_AsUTF8(r) : NULL;
        snprintf(msg, size, "%s", text ? text : "(no message)");
        if (!text) PyErr_Clear();
    }
    Py_DECREF(r);
    return ok;
}

/* The Python model was changed: its new state gets a stamp, which inst->m takes. */
static void changed(tapmp_instance *inst, py_backend *B)
{
    inst->m.stamp = B->live = new_stamp();
    inst->m.hidden[0] = 0.0;  /* not captured yet */
}

static void outputs_from(py_backend *B, double out[])
{
    memcpy(out, (double *)B->reals.buf + MODEL_OUT_FIRST, MODEL_N_OUT * sizeof *out);
}

/* ---- the model operations of instance.h ---------------------------------------------- */

int model_prepare(const char *resource_location, char *why, size_t size)
{
    char dir[TAPMP_PATH_MAX], path[TAPMP_PATH_MAX + 16];
    if (!resources_dir(resource_location, dir, sizeof dir, why, size) || !ensure_python(why, size)) return 0;
    snprintf(path, sizeof path, "%s/guid.txt", dir);  /* written at build time: this FMU's fmuGUID */
    FILE *f = fopen(path, "r");
    pthread_mutex_lock(&init_lock);
    int ok = f && fgets(tapmp_python_token, sizeof tapmp_python_token, f);
    if (ok) tapmp_python_token[strcspn(tapmp_python_token, "\r\n")] = '\0';
    pthread_mutex_unlock(&init_lock);
    if (f) fclose(f);
    if (!ok) snprintf(why, size, "cannot read %s: the FMU's resources are incomplete", path);
    return ok;
}

/* Creates the adapter's object (fmu_common/binding.py) and takes its value arrays. */
int model_instantiate(tapmp_instance *inst, const char *resource_location, int visible)
{
    char dir[TAPMP_PATH_MAX], why[TAPMP_PATH_MAX + 128];
    resources_dir(resource_location, dir, sizeof dir, why, sizeof why);  /* checked by model_prepare */
    py_backend *B = calloc(1, sizeof *B);
    if (!B) return tapmp_fail(inst, "fmi2Instantiate: out of memory"), 0;
    PyGILState_STATE gil = PyGILState_Ensure();
    /* the FMU's own packages (fmu_common, tapmp) and adapter, from its resources folder first */
    PyObject *sys_path = PySys_GetObject("path"), *folder = PyUnicode_DecodeFSDefault(dir);  /* borrowed, new */
    int present = folder && sys_path ? PySequence_Contains(sys_path, folder) : -1;
    if (present == 0 && PyList_Insert(sys_path, 0, folder) < 0) present = -1;
    Py_XDECREF(folder);
    PyObject *binding = present >= 0 ? PyImport_ImportModule("fmu_common.binding") : NULL;
    PyObject *reals = NULL, *ints = NULL;
    if (binding) B->slave = PyObject_CallMethod(binding, "instantiate", "ssi", dir, inst->name, visible);
    if (B->slave) {
        B->records = PyObject_GetAttrString(B->slave, "_records");
        reals = PyObject_GetAttrString(B->slave, "reals");
        ints = PyObject_GetAttrString(B->slave, "ints");
    }
    int ok = B->records && PyList_Check(B->records) && reals && ints &&
             PyObject_GetBuffer(reals, &B->reals, PyBUF_WRITABLE | PyBUF_FORMAT) == 0 &&
             PyObject_GetBuffer(ints, &B->ints, PyBUF_WRITABLE | PyBUF_FORMAT) == 0;
    if (!ok && PyErr_Occurred()) log_exception(inst, "fmi2Instantiate");
    else if (!ok || B->reals.len != (Py_ssize_t)sizeof inst->reals || B->ints.len != (Py_ssize_t)sizeof inst->ints) {
        tapmp_fail(inst, "fmi2Instantiate: the Python model's value arrays do not match the %d variables of %s",
                   N_VARS, MODEL_IDENTIFIER_STRING);
        ok = 0;
    }
    Py_XDECREF(binding);
    Py_XDECREF(reals);
    Py_XDECREF(ints);
    inst->backend = B;
    if (!ok) model_free(inst);
    PyGILState_Release(gil);
    return ok;
}

void model_free(tapmp_instance *inst)
{
    py_backend *B = inst->backend;
    if (!B) return;
    PyGILState_STATE gil = PyGILState_Ensure();
    if (B->reals.obj) PyBuffer_Release(&B->reals);
    if (B->ints.obj) PyBuffer_Release(&B->ints);
    Py_XDECREF(B->records);
    Py_XDECREF(B->evicted);
    Py_XDECREF(B->slave);
    PyGILState_Release(gil);
    free(B);
    inst->backend = NULL;
}

int model_validate(const tapmp_instance *inst, char *msg, size_t size)
{
    PyGILState_STATE gil;
    py_backend *B = begin(inst, &gil, 0);  /* the settings alone: check_parameters builds aside */
    if (!B) return snprintf(msg, size, "%s", inst->error), 0;
    int ok = checked((tapmp_instance *)inst, call(B, "fmi2_check", NULL), "check_parameters", msg, size);
    end(inst, B, gil);
    return ok;
}

void model_setup(tapmp_instance *inst)
{
    char msg[TAPMP_MESSAGE_MAX];
    PyGILState_STATE gil;
    py_backend *B = begin(inst, &gil, 1);
    if (!B) return;
    if (checked(inst, call(B, "fmi2_setup", NULL), "setup_model", msg, sizeof msg))
        outputs_from(B, inst->reals + MODEL_OUT_FIRST);
    else if (!inst->failed)
        tapmp_fail(inst, "%s", msg);
    changed(inst, B);
    end(inst, B, gil);
}

int model_initial_outputs(tapmp_instance *inst, char *msg, size_t size)
{
    PyGILState_STATE gil;
    py_backend *B = begin(inst, &gil, 1);
    if (!B) return snprintf(msg, size, "%s", inst->error), 0;
    int ok = checked(inst, call(B, "fmi2_initial_outputs", NULL), "initial_outputs", msg, size);
    if (ok) outputs_from(B, inst->reals + MODEL_OUT_FIRST);
    changed(inst, B);
    end(inst, B, gil);
    return ok;
}

int model_step(tapmp_instance *inst, double t, double h, double out[], char *msg, size_t size)
{
    PyGILState_STATE gil;
    py_backend *B = begin(inst, &gil, 1);
    if (!B) return snprintf(msg, size, "%s", inst->error), 0;
    PyObject *args[3] = {B->slave, PyFloat_FromDouble(t), PyFloat_FromDouble(h)};
    PyObject *name = PyUnicode_FromString(inst->retune ? "fmi2_retune_step" : "fmi2_do_step");
    PyObject *r = args[1] && args[2] && name ?
                  PyObject_VectorcallMethod(name, args, 3 | PY_VECTORCALL_ARGUMENTS_OFFSET, NULL) : NULL;
    Py_XDECREF(name);
    Py_XDECREF(args[1]);
    Py_XDECREF(args[2]);
    long answer = r && PyLong_Check(r) ? PyLong_AsLong(r) : 0;  /* a status the model answers with */
    if (answer > 0) Py_CLEAR(r);
    int ok = answer > 0 ? -(int)answer : checked(inst, r, "step", msg, size);
    if (ok == 1) outputs_from(B, out);
    changed(inst, B);
    end(inst, B, gil);
    return ok;
}

/* Brings the live model's hidden state into inst->m (the JSON text, one character per
 * double); a state too large for it gets NaN, which every check of a state refuses. */
void model_capture(tapmp_instance *inst)
{
    py_backend *B = inst->backend;
    if (!inst->has_model || inst->m.stamp != B->live || inst->m.hidden[0] > 0.0) return;
    PyGILState_STATE gil = PyGILState_Ensure();
    PyObject *r = call(B, "fmi2_hidden", NULL);
    Py_ssize_t n = 0;
    const char *text = r && PyUnicode_Check(r) ? PyUnicode_AsUTF8AndSize(r, &n) : NULL;
    if (!text) {
        log_exception(inst, "hidden_state");
        inst->m.hidden[0] = NAN;
    } else if (n == 0 || n > MODEL_N_HIDDEN) {
        tapmp_fail(inst, "hidden_state: %zd characters of JSON are invalid: allowed are 1 to %d", n, MODEL_N_HIDDEN);
        inst->m.hidden[0] = NAN;
    } else {
        for (Py_ssize_t k = 0; k < MODEL_N_HIDDEN; k++)
            inst->m.hidden[k] = k < n ? (double)(unsigned char)text[k] : 0.0;
    }
    Py_XDECREF(r);
    end(inst, B, gil);
}

void model_get_hidden(const tapmp_instance *inst, double hidden[])
{
    model_capture((tapmp_instance *)inst);
    memcpy(hidden, inst->m.hidden, sizeof inst->m.hidden);
}

/* The model data of a deserialized state (model_check_hidden has checked hidden): the hidden
 * state is kept as data under a stamp of its own, so nothing here enters Python or touches the
 * live model; a SetFMUstate with the state makes it the instance's, and its next call restores
 * the Python model from it (sync_model). */
void model_set_hidden(tapmp_instance *inst, const double hidden[])
{
    memcpy(inst->m.hidden, hidden, sizeof inst->m.hidden);
    inst->m.stamp = new_stamp();
}

/* The hidden state's JSON (character codes 1 to 255, then zeros) checked by the adapter's
 * check_hidden_state against the state's settings, outputs and time, without touching the
 * live model (the values are pushed, the model is not synced). */
int model_check_hidden(const tapmp_instance *state, const double hidden[], char *msg, size_t size)
{
    char v[40];
    int n = 0;
    while (n < MODEL_N_HIDDEN && hidden[n] != 0.0) {
        if (!(hidden[n] >= 1.0 && hidden[n] <= 255.0 && hidden[n] == floor(hidden[n])))
            return snprintf(msg, size, "hidden state character %d = %s is invalid: allowed is a character code "
                            "1 to 255 (the JSON text of the model's hidden state)", n, tapmp_repr(hidden[n], v)), 0;
        n++;
    }
    if (n == 0) return snprintf(msg, size, "hidden state = '' is invalid: allowed is the JSON text of the "
                                "model's hidden state"), 0;
    for (int i = n; i < MODEL_N_HIDDEN; i++)
        if (hidden[i] != 0.0)
            return snprintf(msg, size, "hidden state character %d = %s is invalid: allowed is 0 after the end of "
                            "the text", i, tapmp_repr(hidden[i], v)), 0;
    PyGILState_STATE gil;
    py_backend *B = begin(state, &gil, 0);
    if (!B) return snprintf(msg, size, "%s", state->error), 0;
    PyObject *text = hidden_text(hidden);
    int ok;
    if (!text) {
        PyErr_Clear();
        snprintf(msg, size, "hidden state: the text is invalid: allowed is UTF-8 JSON");
        ok = 0;
    } else {
        ok = checked((tapmp_instance *)state, call(B, "fmi2_check_state", text), "check_hidden_state", msg, size);
        Py_DECREF(text);
    }
    end(state, B, gil);
    return ok;
}

int model_input_status(tapmp_instance *inst, unsigned vr, double value)
{
    PyGILState_STATE gil;
    py_backend *B = begin(inst, &gil, 1);
    if (!B) return -1;
    PyObject *r = PyObject_CallMethod(B->slave, "fmi2_reject_input", "Id", vr, value);
    long answer = r && PyLong_Check(r) ? PyLong_AsLong(r) : -1;
    if (!r) log_exception(inst, "fmi2_reject_input");
    Py_XDECREF(r);
    end(inst, B, gil);
    return answer >= 0 && answer <= ST_FATAL ? (int)answer : -1;
}
