/*
 * fmi2_layer.c - the one FMI 2.0 layer of every latobs native FMU (CoSimulation and ModelExchange).
 *
 * Hand-written, shared by every model file (model.h); no maths here. It holds the instance, the
 * variables by value reference, the FMI state machine, logging and the statuses. A model file
 * (<runtime>.c) gives the maths through model.h; the build generates fmu_config.h (identifiers,
 * guid, variable table) for each FMU.
 *
 * Value references (the same as the pythonfmu backend's, latobs.fmu_src.framework.variable_table,
 * extended): parameters, inputs, Real outputs, Integer outputs, then the ModelExchange states and
 * their derivatives.
 *
 * Behaviour on misuse (every refusal logs a message naming the culprit, whatever the logging
 * setting; the host is never crashed):
 *   - fmi2Instantiate with a wrong or NULL guid, a NULL instance name or callbacks, or an
 *     interface the FMU lacks (ModelExchange when it has no states): NULL;
 *   - a NULL or foreign instance pointer: fmi2Error (nothing to log through);
 *   - an unknown value reference, one of another type, setting an output, a NULL array with a
 *     nonzero count: fmi2Error, nothing set (a get fills 0 for the unknown references);
 *   - a parameter set after initialisation: ignored, fmi2Warning;
 *   - a parameter outside its declared [min, max], or refused by the model: fmi2Error at
 *     fmi2ExitInitializationMode, and the instance refuses to step until fmi2Reset;
 *   - a call in the wrong state (fmi2DoStep before fmi2ExitInitializationMode, a
 *     ModelExchange function in a co-simulation instance and vice versa): fmi2Error;
 *   - a non-finite or non-positive communication step, one longer than the model's MAX_STEP (its
 *     ModelSpec's max_step, declared in the model description), or an input outside its declared
 *     [min, max] (IN_MIN, IN_MAX; non-finite ones included) at fmi2DoStep or at a ModelExchange
 *     evaluation: fmi2Error, the state kept (a later call with valid values proceeds);
 *     fmi2SetReal stores any value, the call that uses it checks it. The pythonfmu framework
 *     (fmu_src/framework.py) refuses the same steps with the same messages (as fmi2Discard);
 *   - warnings of the model (clamps, excursions): fmi2Warning for that call.
 * fmi2GetFMUstate/fmi2SetFMUstate and their serialisation copy the whole instance state (the
 * model holds no pointers).
 * Over ~600 lines: the whole FMI 2.0 API (co-simulation and model exchange, states, serialisation,
 * every refusal of a bad call) for every C model; one layer, one file.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#define FMU_CONFIG_TABLES /* the variable tables of fmu_config.h: this file only */
#include "model.h"
#include "model_util.h"

/* signed, so that a group of none (e.g. no parameters) compares without warnings */
#define VR_PAR0 0L
#define VR_IN0 (VR_PAR0 + N_PARAMETERS)
#define VR_OUT0 (VR_IN0 + N_INPUTS)
#define VR_INT0 (VR_OUT0 + N_OUTPUTS)
#define VR_STATE0 (VR_INT0 + N_INT_OUTPUTS)
#define VR_DER0 (VR_STATE0 + N_STATES)
#define N_VR (VR_DER0 + N_STATES)

#define MAGIC 0x4c41544fu /* "LATO": marks a live instance of this library */
#define MSG_MAX 1024

typedef enum {
    PHASE_INSTANTIATED, /* after fmi2Instantiate / fmi2Reset */
    PHASE_INIT,         /* between fmi2EnterInitializationMode and fmi2ExitInitializationMode */
    PHASE_STEP,         /* co-simulation: ready for fmi2DoStep */
    PHASE_EVENT,        /* model exchange: event mode */
    PHASE_CONTINUOUS,   /* model exchange: continuous-time mode */
    PHASE_TERMINATED,
    PHASE_FAILED        /* initialisation failed: only reset, terminate, free, get */
} Phase;

struct Log {
    struct Instance *inst;
    int worst;   /* highest level logged during the current call */
    double time; /* s, the time of the model call in progress (layer_time) */
};

/* Everything fmi2GetFMUstate copies; the model's bytes follow it in the state blob. */
typedef struct {
    Phase phase;
    int ready; /* model_setup succeeded: the model's state exists */
    double time;
    double p[N_PARAMETERS + 1];
    double u[N_INPUTS + 1];
    double y[N_OUTPUTS + 1];
    int yi[N_INT_OUTPUTS + 1];
} Values;

typedef struct Instance {
    unsigned magic;
    char name[256];
    fmi2Type type;
    fmi2CallbackFunctions cb;
    int logging_on;
    Values v;
    Log log;
    Model *model;
} Instance;

/* ------------------------------------------------------------------ logging */
static void emit(Instance *inst, int level, const char *text)
{
    static const char *const category[] = {"logAll", "logStatusWarning", "logAll", "logStatusError"};
    char escaped[2 * MSG_MAX];
    size_t k = 0;
    if (level > inst->log.worst) inst->log.worst = level;
    if (level == LOG_INFO && !inst->logging_on) return;
    if (inst->cb.logger == NULL) return;
    /* the message is a format string for the host: double every '%' */
    for (const char *s = text; *s && k + 2 < sizeof escaped; s++) {
        escaped[k++] = *s;
        if (*s == '%') escaped[k++] = '%';
    }
    escaped[k] = '\0';
    inst->cb.logger(inst->cb.componentEnvironment, inst->name,
                    level == LOG_ERROR ? fmi2Error : level == LOG_WARNING ? fmi2Warning : fmi2OK,
                    category[level == LOG_ERROR ? 3 : level == LOG_WARNING ? 1 : 0], escaped);
}

double layer_time(const Log *log)
{
    return log->time;
}

void log_event(const Log *log, int level, const char *fmt, ...)
{
    char text[MSG_MAX];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    emit(log->inst, level, text);
}

static void say(Instance *inst, int level, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;

static void say(Instance *inst, int level, const char *fmt, ...)
{
    char text[MSG_MAX];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    emit(inst, level, text);
}

/* the status of a call: the worst level logged since begin() */
static Instance *begin(fmi2Component c)
{
    Instance *inst = (Instance *)c;
    if (inst == NULL || inst->magic != MAGIC) return NULL;
    inst->log.worst = LOG_INFO;
    return inst;
}

static fmi2Status status_of(const Instance *inst)
{
    return inst->log.worst >= LOG_ERROR ? fmi2Error : inst->log.worst >= LOG_WARNING ? fmi2Warning : fmi2OK;
}

/* ------------------------------------------------------------------ variables */
static const char *var_name(fmi2ValueReference vr)
{
    return vr < N_VR ? VAR_NAMES[vr] : "?";
}

static int is_real(fmi2ValueReference vr)
{
    return vr < VR_INT0 || (vr >= VR_STATE0 && vr < N_VR);
}

static int all_finite(const double *x, int n)
{
    for (int i = 0; i < n; i++)
        if (!isfinite(x[i])) return 0;
    return 1;
}

/* 1 if every input is inside its declared [IN_MIN, IN_MAX] (so finite) */
static int inputs_valid(const double *u)
{
    for (int i = 0; i < N_INPUTS; i++)
        if (!(u[i] >= IN_MIN[i] && u[i] <= IN_MAX[i])) return 0;
    return 1;
}

/* the inputs outside their range, "name = value, ..." in `list`: the non-finite ones if any
 * (returns 1), else those outside their range with it (returns 0); the framework's _bad_inputs */
static int bad_inputs(const double *u, char *list, size_t size)
{
    char a[32], b[32], c[32];
    size_t len = 0;
    int nonfinite = 0;
    list[0] = '\0';
    for (int i = 0; i < N_INPUTS; i++) nonfinite |= !isfinite(u[i]);
    for (int i = 0; i < N_INPUTS; i++) {
        if (u[i] >= IN_MIN[i] && u[i] <= IN_MAX[i]) continue;
        if (nonfinite && isfinite(u[i])) continue;
        if (len + 160 > size) break;
        len += (size_t)snprintf(list + len, size - len, "%s%s = %s", len ? ", " : "",
                                var_name((fmi2ValueReference)(VR_IN0 + i)), py_repr(u[i], a));
        if (!nonfinite)
            len += (size_t)snprintf(list + len, size - len, " (declared range [%s, %s])", py_repr(IN_MIN[i], b),
                                    py_repr(IN_MAX[i], c));
    }
    return nonfinite;
}

/* 1 if the inputs are inside their declared ranges; else an error naming them, for the call `what` */
static int inputs_ok(Instance *inst, const char *what)
{
    if (inputs_valid(inst->v.u)) return 1;
    char list[MSG_MAX / 2], t[32];
    if (bad_inputs(inst->v.u, list, sizeof list))
        say(inst, LOG_ERROR, "%s refused at t = %s: non-finite input(s) %s; state held", what,
            py_repr(inst->v.time, t), list);
    else
        say(inst, LOG_ERROR, "%s refused at t = %s: input(s) outside the declared range: %s; state held", what,
            py_repr(inst->v.time, t), list);
    return 0;
}

static const char *phase_name(Phase p)
{
    static const char *const names[] = {"instantiated", "initialization mode", "step mode", "event mode",
                                        "continuous-time mode", "terminated", "failed initialisation"};
    return names[p];
}

static int require(Instance *inst, const char *what, int ok)
{
    if (!ok) say(inst, LOG_ERROR, "%s called in %s: not allowed there", what, phase_name(inst->v.phase));
    return ok;
}

static int require_type(Instance *inst, const char *what, fmi2Type type)
{
    if (inst->type == type) return 1;
    say(inst, LOG_ERROR, "%s is a %s function; this instance is %s", what,
        type == fmi2ModelExchange ? "ModelExchange" : "CoSimulation",
        inst->type == fmi2ModelExchange ? "ModelExchange" : "CoSimulation");
    return 0;
}

static void reset_values(Instance *inst)
{
    memset(&inst->v, 0, sizeof inst->v);
    for (int i = 0; i < N_PARAMETERS; i++) inst->v.p[i] = PAR_START[i];
    for (int i = 0; i < N_INPUTS; i++) inst->v.u[i] = IN_START[i];
    for (int i = 0; i < N_OUTPUTS; i++) inst->v.y[i] = OUT_START[i];
    for (int i = 0; i < N_INT_OUTPUTS; i++) inst->v.yi[i] = INT_START[i];
    memset(inst->model, 0, model_size());
    inst->v.phase = PHASE_INSTANTIATED;
}

/* the model exchange outputs are functions of the states and inputs: refresh before a get */
static void refresh_outputs(Instance *inst)
{
#if N_STATES > 0
    if (inst->type == fmi2ModelExchange && (inst->v.phase == PHASE_EVENT || inst->v.phase == PHASE_CONTINUOUS) &&
        inputs_valid(inst->v.u))
        model_me_outputs(inst->model, inst->v.u, inst->v.y, inst->v.yi);
#else
    (void)inst;
#endif
}

/* ------------------------------------------------------------------ common functions */
const char *fmi2GetTypesPlatform(void)
{
    return fmi2TypesPlatform;
}

const char *fmi2GetVersion(void)
{
    return fmi2Version;
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi2Error;
    (void)categories;
    (void)nCategories; /* the categories filter nothing: warnings and errors are always logged */
    inst->logging_on = loggingOn ? 1 : 0;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    Instance probe;
    (void)fmuResourceLocation; /* everything is compiled in */
    (void)visible;
    if (functions == NULL || functions->logger == NULL) return NULL; /* nobody to tell */
    memset(&probe, 0, sizeof probe);
    probe.magic = MAGIC;
    probe.cb = *functions;
    snprintf(probe.name, sizeof probe.name, "%s", instanceName ? instanceName : "?");
    if (instanceName == NULL || instanceName[0] == '\0') {
        say(&probe, LOG_ERROR, "fmi2Instantiate: missing instance name");
        return NULL;
    }
    if (fmuGUID == NULL || strcmp(fmuGUID, INSTANTIATION_TOKEN) != 0) {
        say(&probe, LOG_ERROR, "fmi2Instantiate: guid %s is not this FMU's (%s): refusing another FMU's "
            "model description", fmuGUID ? fmuGUID : "(NULL)", INSTANTIATION_TOKEN);
        return NULL;
    }
    if (fmuType != fmi2CoSimulation && fmuType != fmi2ModelExchange) {
        say(&probe, LOG_ERROR, "fmi2Instantiate: unknown interface type %d", (int)fmuType);
        return NULL;
    }
    if (fmuType == fmi2ModelExchange && N_STATES == 0) {
        say(&probe, LOG_ERROR, "fmi2Instantiate: %s has no ModelExchange interface (co-simulation only)",
            MODEL_IDENTIFIER);
        return NULL;
    }
    Instance *inst = (Instance *)calloc(1, sizeof(Instance));
    Model *model = (Model *)calloc(1, model_size());
    if (inst == NULL || model == NULL) {
        free(inst);
        free(model);
        say(&probe, LOG_ERROR, "fmi2Instantiate: out of memory");
        return NULL;
    }
    *inst = probe;
    inst->type = fmuType;
    inst->logging_on = loggingOn ? 1 : 0;
    inst->model = model;
    inst->log.inst = inst;
    reset_values(inst);
    return inst;
}

void fmi2FreeInstance(fmi2Component c)
{
    Instance *inst = begin(c);
    if (inst == NULL) return;
    inst->magic = 0;
    free(inst->model);
    free(inst);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    Instance *inst = begin(c);
    (void)toleranceDefined;
    (void)tolerance;
    (void)stopTimeDefined;
    (void)stopTime;
    if (inst == NULL) return fmi2Error;
    if (!require(inst, "fmi2SetupExperiment", inst->v.phase == PHASE_INSTANTIATED)) return fmi2Error;
    if (!isfinite(startTime)) {
        say(inst, LOG_ERROR, "fmi2SetupExperiment: start time %g is not finite", startTime);
        return fmi2Error;
    }
    inst->v.time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi2Error;
    if (!require(inst, "fmi2EnterInitializationMode", inst->v.phase == PHASE_INSTANTIATED)) return fmi2Error;
    inst->v.phase = PHASE_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi2Error;
    if (!require(inst, "fmi2ExitInitializationMode", inst->v.phase == PHASE_INIT)) return fmi2Error;
    for (int i = 0; i < N_PARAMETERS; i++) {
        double x = inst->v.p[i];
        if (!isfinite(x) || x < PAR_MIN[i] || x > PAR_MAX[i]) {
            say(inst, LOG_ERROR, "parameter %s = %g is outside its declared range [%g, %g]",
                var_name((fmi2ValueReference)(VR_PAR0 + i)), x, PAR_MIN[i], PAR_MAX[i]);
            inst->v.phase = PHASE_FAILED;
            return fmi2Error;
        }
    }
    inst->log.time = inst->v.time;
    if (model_setup(inst->model, inst->v.p, &inst->log) != 0) {
        say(inst, LOG_ERROR, "initialisation failed: the model refused its parameters");
        inst->v.phase = PHASE_FAILED;
        return fmi2Error;
    }
    inst->v.ready = 1;
    char list[MSG_MAX / 2];
    if (inputs_valid(inst->v.u))
        model_initialize(inst->model, inst->v.u, &inst->log);
    else if (bad_inputs(inst->v.u, list, sizeof list))
        say(inst, LOG_WARNING, "non-finite inputs at initialisation: the model starts from the first step");
    else
        say(inst, LOG_WARNING, "input(s) outside the declared range at initialisation: %s; the model starts from "
            "the first step", list);
    model_outputs(inst->model, inst->v.y, inst->v.yi);
    inst->v.phase = inst->type == fmi2CoSimulation ? PHASE_STEP : PHASE_EVENT;
    return status_of(inst);
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi2Error;
    inst->v.phase = PHASE_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi2Error;
    reset_values(inst);
    return fmi2OK;
}

/* ------------------------------------------------------------------ get / set */
static int check_array(Instance *inst, const char *what, const void *vr, size_t nvr, const void *value)
{
    if (nvr > 0 && (vr == NULL || value == NULL)) {
        say(inst, LOG_ERROR, "%s: NULL array for %zu value references", what, nvr);
        return 0;
    }
    return 1;
}

static void unknown_ref(Instance *inst, const char *what, fmi2ValueReference vr, const char *type)
{
    if (vr < N_VR)
        say(inst, LOG_ERROR, "%s: value reference %u (%s) is not a%s %s variable", what, vr, var_name(vr),
            type[0] == 'I' ? "n" : "", type);
    else
        say(inst, LOG_ERROR, "%s: value reference %u is not a variable of %s (references 0..%u)", what, vr,
            MODEL_IDENTIFIER, (unsigned)N_VR - 1u);
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi2Error;
    if (!check_array(inst, "fmi2GetReal", vr, nvr, value)) return fmi2Error;
    refresh_outputs(inst);
#if N_STATES > 0
    double x[N_STATES], dx[N_STATES];
    int have_x = 0, have_dx = 0;
#endif
    for (size_t i = 0; i < nvr; i++) {
        long r = (long)vr[i];
        value[i] = 0.0;
        if (r < VR_IN0) value[i] = inst->v.p[r - VR_PAR0];
        else if (r < VR_OUT0) value[i] = inst->v.u[r - VR_IN0];
        else if (r < VR_INT0) value[i] = inst->v.y[r - VR_OUT0];
#if N_STATES > 0
        else if (r >= VR_STATE0 && r < N_VR && !inst->v.ready) {
            value[i] = 0.0; /* not set up yet: the states are computed at fmi2ExitInitializationMode */
        } else if (r >= VR_STATE0 && r < VR_DER0) {
            if (!have_x) model_me_get_states(inst->model, x), have_x = 1;
            value[i] = x[r - VR_STATE0];
        } else if (r >= VR_DER0 && r < N_VR) {
            if (!have_dx) {
                if (!inputs_valid(inst->v.u)) {
                    say(inst, LOG_ERROR, "fmi2GetReal: derivative %s needs inputs inside their declared range",
                        var_name(vr[i]));
                    continue;
                }
                model_me_derivatives(inst->model, inst->v.u, dx), have_dx = 1;
            }
            value[i] = dx[r - VR_DER0];
        }
#endif
        else unknown_ref(inst, "fmi2GetReal", vr[i], "Real");
    }
    return status_of(inst);
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi2Error;
    if (!check_array(inst, "fmi2GetInteger", vr, nvr, value)) return fmi2Error;
    refresh_outputs(inst);
    for (size_t i = 0; i < nvr; i++) {
        value[i] = 0;
        if (vr[i] >= VR_INT0 && vr[i] < VR_STATE0) value[i] = inst->v.yi[vr[i] - VR_INT0];
        else unknown_ref(inst, "fmi2GetInteger", vr[i], "Integer");
    }
    return status_of(inst);
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi2Error;
    if (!check_array(inst, "fmi2GetBoolean", vr, nvr, value)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        value[i] = fmi2False;
        unknown_ref(inst, "fmi2GetBoolean", vr[i], "Boolean");
    }
    return status_of(inst);
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi2Error;
    if (!check_array(inst, "fmi2GetString", vr, nvr, value)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        value[i] = "";
        unknown_ref(inst, "fmi2GetString", vr[i], "String");
    }
    return status_of(inst);
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi2Error;
    if (!check_array(inst, "fmi2SetReal", vr, nvr, value)) return fmi2Error;
    int before_init = inst->v.phase == PHASE_INSTANTIATED || inst->v.phase == PHASE_INIT;
    for (size_t i = 0; i < nvr; i++) {
        long r = (long)vr[i];
        if (r >= VR_IN0 && r < VR_OUT0) {
            inst->v.u[r - VR_IN0] = value[i]; /* checked (finite) where it is used */
        } else if (r < VR_IN0) {
            if (before_init) inst->v.p[r - VR_PAR0] = value[i];
            else say(inst, LOG_WARNING, "parameter %s set after initialisation: ignored", var_name(vr[i]));
        } else if (is_real(vr[i])) {
            say(inst, LOG_ERROR, "fmi2SetReal: value reference %u (%s) is not an input or a parameter; ignored",
                vr[i], var_name(vr[i]));
        } else {
            unknown_ref(inst, "fmi2SetReal", vr[i], "Real");
        }
    }
    return status_of(inst);
}

static fmi2Status refuse_set(fmi2Component c, const char *what, const char *type, const fmi2ValueReference vr[],
                             size_t nvr, const void *value)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi2Error;
    if (!check_array(inst, what, vr, nvr, value)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        if (type[0] == 'I' && vr[i] >= VR_INT0 && vr[i] < VR_STATE0)
            say(inst, LOG_ERROR, "%s: value reference %u (%s) is an output; ignored", what, vr[i], var_name(vr[i]));
        else
            unknown_ref(inst, what, vr[i], type);
    }
    return status_of(inst);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[])
{
    return refuse_set(c, "fmi2SetInteger", "Integer", vr, nvr, value);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[])
{
    return refuse_set(c, "fmi2SetBoolean", "Boolean", vr, nvr, value);
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{
    return refuse_set(c, "fmi2SetString", "String", vr, nvr, value);
}

/* ------------------------------------------------------------------ FMU state */
typedef struct {
    unsigned magic;
    Values v;
} StateHeader;

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi2Error;
    if (state == NULL) {
        say(inst, LOG_ERROR, "fmi2GetFMUstate: NULL state pointer");
        return fmi2Error;
    }
    StateHeader *blob = (StateHeader *)*state;
    if (blob == NULL) blob = (StateHeader *)malloc(sizeof(StateHeader) + model_size());
    if (blob == NULL) {
        say(inst, LOG_ERROR, "fmi2GetFMUstate: out of memory");
        return fmi2Error;
    }
    blob->magic = MAGIC;
    blob->v = inst->v;
    memcpy(blob + 1, inst->model, model_size());
    *state = blob;
    return fmi2OK;
}

static int valid_state(Instance *inst, const char *what, const StateHeader *blob)
{
    if (blob == NULL || blob->magic != MAGIC) {
        say(inst, LOG_ERROR, "%s: not a state of this FMU", what);
        return 0;
    }
    return 1;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi2Error;
    const StateHeader *blob = (const StateHeader *)state;
    if (!valid_state(inst, "fmi2SetFMUstate", blob)) return fmi2Error;
    inst->v = blob->v;
    memcpy(inst->model, blob + 1, model_size());
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi2Error;
    if (state != NULL) {
        free(*state);
        *state = NULL;
    }
    return fmi2OK;
}

/* serialised: the guid, then the state blob */
static size_t serialized_size(void)
{
    return sizeof INSTANTIATION_TOKEN + sizeof(StateHeader) + model_size();
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi2Error;
    if (!valid_state(inst, "fmi2SerializedFMUstateSize", (const StateHeader *)state) || size == NULL)
        return fmi2Error;
    *size = serialized_size();
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi2Error;
    if (!valid_state(inst, "fmi2SerializeFMUstate", (const StateHeader *)state)) return fmi2Error;
    if (bytes == NULL || size < serialized_size()) {
        say(inst, LOG_ERROR, "fmi2SerializeFMUstate: buffer of %zu bytes, %zu needed", size, serialized_size());
        return fmi2Error;
    }
    memcpy(bytes, INSTANTIATION_TOKEN, sizeof INSTANTIATION_TOKEN);
    memcpy(bytes + sizeof INSTANTIATION_TOKEN, state, sizeof(StateHeader) + model_size());
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *state)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi2Error;
    if (serializedState == NULL || state == NULL || size != serialized_size() ||
        memcmp(serializedState, INSTANTIATION_TOKEN, sizeof INSTANTIATION_TOKEN) != 0) {
        say(inst, LOG_ERROR, "fmi2DeSerializeFMUstate: not a serialised state of this FMU (guid %s, %zu bytes)",
            INSTANTIATION_TOKEN, serialized_size());
        return fmi2Error;
    }
    void *blob = realloc(*state, sizeof(StateHeader) + model_size());
    if (blob == NULL) {
        say(inst, LOG_ERROR, "fmi2DeSerializeFMUstate: out of memory");
        return fmi2Error;
    }
    memcpy(blob, serializedState + sizeof INSTANTIATION_TOKEN, sizeof(StateHeader) + model_size());
    *state = blob;
    return fmi2OK;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    Instance *inst = begin(c);
    (void)vUnknown_ref, (void)nUnknown, (void)vKnown_ref, (void)nKnown, (void)dvKnown, (void)dvUnknown;
    if (inst == NULL) return fmi2Error;
    say(inst, LOG_ERROR, "fmi2GetDirectionalDerivative is not provided (providesDirectionalDerivative=\"false\")");
    return fmi2Error;
}

/* ------------------------------------------------------------------ co-simulation */
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    Instance *inst = begin(c);
    (void)vr, (void)nvr, (void)order, (void)value;
    if (inst == NULL) return fmi2Error;
    say(inst, LOG_ERROR, "fmi2SetRealInputDerivatives: inputs are held over a step (canInterpolateInputs=\"false\")");
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    Instance *inst = begin(c);
    (void)vr, (void)nvr, (void)order, (void)value;
    if (inst == NULL) return fmi2Error;
    say(inst, LOG_ERROR, "fmi2GetRealOutputDerivatives: not provided (maxOutputDerivativeOrder=\"0\")");
    return fmi2Error;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    Instance *inst = begin(c);
    (void)noSetFMUStatePriorToCurrentPoint;
    if (inst == NULL) return fmi2Error;
    if (!require_type(inst, "fmi2DoStep", fmi2CoSimulation)) return fmi2Error;
    if (inst->v.phase != PHASE_STEP) {
        say(inst, LOG_ERROR, "step refused at t = %g: fmi2DoStep called in %s (call fmi2ExitInitializationMode "
            "first%s)", currentCommunicationPoint, phase_name(inst->v.phase),
            inst->v.phase == PHASE_FAILED ? "; initialisation failed, see the earlier error" : "");
        return fmi2Error;
    }
    if (!(communicationStepSize > 0.0) || !isfinite(communicationStepSize)) {
        say(inst, LOG_ERROR, "step refused: communication step %g must be finite and > 0 s", communicationStepSize);
        return fmi2Error;
    }
    if (communicationStepSize > MAX_STEP_REFUSED_ABOVE) {
        char t[32], h[32], m[32];
        say(inst, LOG_ERROR, "step refused at t = %s: communication step %s s exceeds this FMU's longest step %s s "
            "(declared in its model description); state held", py_repr(currentCommunicationPoint, t),
            py_repr(communicationStepSize, h), py_repr(MAX_STEP, m));
        return fmi2Error;
    }
    if (!inputs_ok(inst, "step")) return fmi2Error;
    inst->log.time = currentCommunicationPoint;
    if (model_do_step(inst->model, communicationStepSize, inst->v.u, &inst->log) == 0) {
        inst->v.time = currentCommunicationPoint + communicationStepSize;
        model_outputs(inst->model, inst->v.y, inst->v.yi);
    } else if (inst->log.worst < LOG_ERROR) {
        say(inst, LOG_ERROR, "step refused at t = %g by the model", currentCommunicationPoint);
    }
    return status_of(inst);
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi2Error;
    say(inst, LOG_ERROR, "fmi2CancelStep: steps are synchronous, nothing to cancel");
    return fmi2Error;
}

static fmi2Status no_status(fmi2Component c, const char *what)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi2Error;
    say(inst, LOG_ERROR, "%s: steps are synchronous (no pending step, no status to report)", what);
    return fmi2Discard;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    (void)s, (void)value;
    return no_status(c, "fmi2GetStatus");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    Instance *inst = begin(c);
    if (inst != NULL && s == fmi2LastSuccessfulTime && value != NULL) {
        *value = inst->v.time;
        return fmi2OK;
    }
    return no_status(c, "fmi2GetRealStatus");
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    (void)s, (void)value;
    return no_status(c, "fmi2GetIntegerStatus");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    (void)s, (void)value;
    return no_status(c, "fmi2GetBooleanStatus");
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    (void)s, (void)value;
    return no_status(c, "fmi2GetStringStatus");
}

/* ------------------------------------------------------------------ model exchange */
#define IN_EVENT (1 << PHASE_EVENT)
#define IN_CONT (1 << PHASE_CONTINUOUS)
#define IN_INIT ((1 << PHASE_INSTANTIATED) | (1 << PHASE_INIT))
#define IN_RUN (IN_EVENT | IN_CONT | (1 << PHASE_TERMINATED)) /* the model is set up */

static Instance *me_begin(fmi2Component c, const char *what, int phases)
{
    Instance *inst = begin(c);
    if (inst == NULL) return NULL;
    if (!require_type(inst, what, fmi2ModelExchange)) return NULL;
    if (!require(inst, what, (phases >> inst->v.phase) & 1)) return NULL;
    if (phases == IN_RUN && !inst->v.ready) {
        say(inst, LOG_ERROR, "%s: the model was never initialised (fmi2ExitInitializationMode failed or was "
            "not called)", what);
        return NULL;
    }
    return inst;
}


static int count_ok(Instance *inst, const char *what, const void *array, size_t n, size_t expected)
{
    if (array == NULL || n != expected) {
        say(inst, LOG_ERROR, "%s: %zu values (array %s) given, this FMU has %zu", what, n,
            array ? "set" : "NULL", expected);
        return 0;
    }
    return 1;
}

fmi2Status fmi2EnterEventMode(fmi2Component c)
{
    Instance *inst = me_begin(c, "fmi2EnterEventMode", IN_EVENT | IN_CONT);
    if (inst == NULL) return fmi2Error;
    inst->v.phase = PHASE_EVENT;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo)
{
    Instance *inst = me_begin(c, "fmi2NewDiscreteStates", IN_EVENT);
    if (inst == NULL || eventInfo == NULL) return fmi2Error;
    memset(eventInfo, 0, sizeof *eventInfo);
#if N_STATES > 0
    if (!inputs_ok(inst, "fmi2NewDiscreteStates")) return fmi2Error;
    eventInfo->valuesOfContinuousStatesChanged =
        model_me_event_update(inst->model, inst->v.time, inst->v.u, &inst->log) ? fmi2True : fmi2False;
#endif
    return status_of(inst);
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c)
{
    Instance *inst = me_begin(c, "fmi2EnterContinuousTimeMode", IN_EVENT);
    if (inst == NULL) return fmi2Error;
    inst->v.phase = PHASE_CONTINUOUS;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation)
{
    Instance *inst = me_begin(c, "fmi2CompletedIntegratorStep", IN_CONT);
    (void)noSetFMUStatePriorToCurrentPoint;
    if (inst == NULL || enterEventMode == NULL || terminateSimulation == NULL) return fmi2Error;
    *enterEventMode = fmi2False; /* every event of these models is a state event */
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time)
{
    Instance *inst = me_begin(c, "fmi2SetTime", IN_EVENT | IN_CONT | IN_INIT);
    if (inst == NULL) return fmi2Error;
    if (!isfinite(time)) {
        say(inst, LOG_ERROR, "fmi2SetTime: time %g is not finite", time);
        return fmi2Error;
    }
    inst->v.time = time;
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx)
{
    Instance *inst = me_begin(c, "fmi2SetContinuousStates", IN_EVENT | IN_CONT);
    if (inst == NULL || !count_ok(inst, "fmi2SetContinuousStates", x, nx, N_STATES)) return fmi2Error;
#if N_STATES > 0
    if (!all_finite(x, N_STATES)) {
        say(inst, LOG_ERROR, "fmi2SetContinuousStates: non-finite state refused");
        return fmi2Error;
    }
    model_me_set_states(inst->model, x);
#endif
    return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx)
{
    Instance *inst = me_begin(c, "fmi2GetDerivatives", IN_RUN);
    if (inst == NULL || !count_ok(inst, "fmi2GetDerivatives", derivatives, nx, N_STATES)) return fmi2Error;
#if N_STATES > 0
    if (!inputs_ok(inst, "fmi2GetDerivatives")) return fmi2Error;
    model_me_derivatives(inst->model, inst->v.u, derivatives);
#endif
    return status_of(inst);
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni)
{
    Instance *inst = me_begin(c, "fmi2GetEventIndicators", IN_RUN);
    if (inst == NULL) return fmi2Error;
    if (ni == 0) return fmi2OK;
    if (!count_ok(inst, "fmi2GetEventIndicators", eventIndicators, ni, N_EVENT_INDICATORS)) return fmi2Error;
#if N_STATES > 0 && N_EVENT_INDICATORS > 0
    if (!inputs_ok(inst, "fmi2GetEventIndicators")) return fmi2Error;
    model_me_event_indicators(inst->model, inst->v.u, eventIndicators);
#endif
    return status_of(inst);
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx)
{
    Instance *inst = me_begin(c, "fmi2GetContinuousStates", IN_RUN);
    if (inst == NULL || !count_ok(inst, "fmi2GetContinuousStates", x, nx, N_STATES)) return fmi2Error;
#if N_STATES > 0
    model_me_get_states(inst->model, x);
#endif
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx)
{
    Instance *inst = me_begin(c, "fmi2GetNominalsOfContinuousStates", IN_RUN);
    if (inst == NULL || !count_ok(inst, "fmi2GetNominalsOfContinuousStates", x_nominal, nx, N_STATES))
        return fmi2Error;
#if N_STATES > 0
    model_me_nominals(inst->model, x_nominal);
#endif
    return fmi2OK;
}
