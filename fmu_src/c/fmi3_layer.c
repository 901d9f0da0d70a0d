/*
 * fmi3_layer.c - the FMI 3.0 layer of the latobs native FMUs (Co-Simulation and Model Exchange),
 * over the same model interface (model.h) as fmi2_layer.c: a model file compiles unchanged with
 * either layer. No maths here: the instance, the variables by value reference, the FMI 3.0 state
 * machine, logging and the statuses, in the manner of the Reference FMUs' fmi3Functions.c.
 *
 * Value references: those of the FMI 2.0 layer (parameters, inputs, Float64 outputs, Int32
 * outputs, the ModelExchange states and their derivatives), then the event indicators (local
 * Float64 variables, as FMI 3.0 declares them) and last the independent variable `time`.
 *
 * Misuse is refused as in fmi2_layer.c (a message naming the culprit is logged whatever the
 * logging setting; the host is never crashed; the state is kept):
 *   - instantiation with a wrong or NULL instantiation token, a NULL instance name or logger, an
 *     interface the FMU lacks (ModelExchange with no states, Scheduled Execution, Co-Simulation
 *     with event mode): NULL;
 *   - a NULL or foreign instance pointer: fmi3Error (nothing to log through);
 *   - an unknown value reference, one of another type, setting an output, a NULL array with a
 *     nonzero count, nValues != nValueReferences: fmi3Error, nothing set;
 *   - a parameter set after initialisation: ignored, fmi3Warning;
 *   - a parameter outside its declared [min, max] or refused by the model: fmi3Error at
 *     fmi3ExitInitializationMode, the instance refuses to step until fmi3Reset;
 *   - a call in the wrong state or of the other interface: fmi3Error;
 *   - a non-finite, non-positive or too long communication step (MAX_STEP), an input outside its
 *     declared [min, max] (non-finite included) at fmi3DoStep or a ModelExchange evaluation:
 *     fmi3Error, the state kept;
 *   - functions of what the FMU does not provide (clocks, directional and adjoint derivatives,
 *     variable dependencies, output derivatives, types other than Float64 and Int32): fmi3Error.
 * Log messages are plain text (FMI 3.0's logger takes no format string).
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"

#define FMU_CONFIG_TABLES /* the variable tables of fmu_config.h: this file only */
#include "model.h"
#include "model_util.h"

/* signed, so that a group of none compares without warnings */
#define VR_PAR0 0L
#define VR_IN0 (VR_PAR0 + N_PARAMETERS)
#define VR_OUT0 (VR_IN0 + N_INPUTS)
#define VR_INT0 (VR_OUT0 + N_OUTPUTS)
#define VR_STATE0 (VR_INT0 + N_INT_OUTPUTS)
#define VR_DER0 (VR_STATE0 + N_STATES)
#define VR_EVI0 (VR_DER0 + N_STATES)
#define VR_TIME (VR_EVI0 + N_EVENT_INDICATORS)
#define VR_ARR0 (VR_TIME + 1) /* the gain arrays (constants, fmu_config.h: ARR_*) */
#define N_VR (VR_ARR0 + N_ARRAYS)

#define MAGIC 0x4c415433u /* "LAT3": marks a live instance of this layer */
#define MSG_MAX 1024

typedef enum {
    PHASE_INSTANTIATED, /* after instantiation / fmi3Reset */
    PHASE_INIT,         /* between fmi3EnterInitializationMode and fmi3ExitInitializationMode */
    PHASE_STEP,         /* co-simulation: step mode */
    PHASE_EVENT,        /* model exchange: event mode */
    PHASE_CONTINUOUS,   /* model exchange: continuous-time mode */
    PHASE_TERMINATED,
    PHASE_FAILED        /* initialisation failed: only reset, terminate, free, get */
} Phase;

typedef enum { TYPE_ME, TYPE_CS } InterfaceType;

struct Log {
    struct Instance *inst;
    int worst;   /* highest level logged during the current call */
    double time; /* s, the time of the model call in progress (layer_time) */
};

/* Everything fmi3GetFMUState copies; the model's bytes follow it in the state blob. */
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
    InterfaceType type;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback logger;
    int logging_on;
    Values v;
    Log log;
    Model *model;
} Instance;

/* ------------------------------------------------------------------ logging */
static void emit(Instance *inst, int level, const char *text)
{
    if (level > inst->log.worst) inst->log.worst = level;
    if (level == LOG_INFO && !inst->logging_on) return;
    if (inst->logger == NULL) return;
    inst->logger(inst->env, level == LOG_ERROR ? fmi3Error : level == LOG_WARNING ? fmi3Warning : fmi3OK,
                 level == LOG_ERROR ? "logStatusError" : level == LOG_WARNING ? "logStatusWarning" : "logAll", text);
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
static Instance *begin(fmi3Instance c)
{
    Instance *inst = (Instance *)c;
    if (inst == NULL || inst->magic != MAGIC) return NULL;
    inst->log.worst = LOG_INFO;
    return inst;
}

static fmi3Status status_of(const Instance *inst)
{
    return inst->log.worst >= LOG_ERROR ? fmi3Error : inst->log.worst >= LOG_WARNING ? fmi3Warning : fmi3OK;
}

/* ------------------------------------------------------------------ variables */
static const char *var_name(fmi3ValueReference vr, char buf[64])
{
    long r = (long)vr;
    if (r < VR_EVI0) return VAR_NAMES[r];
    if (r < VR_TIME) {
        snprintf(buf, 64, "event_indicator_%ld", r - VR_EVI0 + 1);
        return buf;
    }
    if (r >= VR_ARR0 && r < N_VR) return ARR_NAMES[r - VR_ARR0];
    return r == VR_TIME ? "time" : "?";
}

/* how many values variable r has: an array's elements, else 1 (a scalar or an unknown reference) */
static size_t n_values(long r)
{
    return r >= VR_ARR0 && r < N_VR ? (size_t)ARR_SIZE[r - VR_ARR0] : 1u;
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
 * (returns 1), else those outside their range with it (returns 0) */
static int bad_inputs(const double *u, char *list, size_t size)
{
    char a[32], b[32], c[32], n[64];
    size_t len = 0;
    int nonfinite = 0;
    list[0] = '\0';
    for (int i = 0; i < N_INPUTS; i++) nonfinite |= !isfinite(u[i]);
    for (int i = 0; i < N_INPUTS; i++) {
        if (u[i] >= IN_MIN[i] && u[i] <= IN_MAX[i]) continue;
        if (nonfinite && isfinite(u[i])) continue;
        if (len + 160 > size) break;
        len += (size_t)snprintf(list + len, size - len, "%s%s = %s", len ? ", " : "",
                                var_name((fmi3ValueReference)(VR_IN0 + i), n), py_repr(u[i], a));
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

static int require_type(Instance *inst, const char *what, InterfaceType type)
{
    if (inst->type == type) return 1;
    say(inst, LOG_ERROR, "%s is a %s function; this instance is %s", what,
        type == TYPE_ME ? "ModelExchange" : "CoSimulation", inst->type == TYPE_ME ? "ModelExchange" : "CoSimulation");
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
    if (inst->type == TYPE_ME && (inst->v.phase == PHASE_EVENT || inst->v.phase == PHASE_CONTINUOUS) &&
        inputs_valid(inst->v.u))
        model_me_outputs(inst->model, inst->v.u, inst->v.y, inst->v.yi);
#else
    (void)inst;
#endif
}

/* ------------------------------------------------------------------ instantiation */
const char *fmi3GetVersion(void)
{
    return fmi3Version;
}

fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi3Error;
    (void)categories;
    (void)nCategories; /* the categories filter nothing: warnings and errors are always logged */
    inst->logging_on = loggingOn ? 1 : 0;
    return fmi3OK;
}

static Instance *instantiate(const char *what, InterfaceType type, fmi3String instanceName,
                             fmi3String instantiationToken, fmi3Boolean loggingOn, fmi3InstanceEnvironment env,
                             fmi3LogMessageCallback logger)
{
    Instance probe;
    if (logger == NULL) return NULL; /* nobody to tell */
    memset(&probe, 0, sizeof probe);
    probe.magic = MAGIC;
    probe.env = env;
    probe.logger = logger;
    snprintf(probe.name, sizeof probe.name, "%s", instanceName ? instanceName : "?");
    if (instanceName == NULL || instanceName[0] == '\0') {
        say(&probe, LOG_ERROR, "%s: missing instance name", what);
        return NULL;
    }
    if (instantiationToken == NULL || strcmp(instantiationToken, INSTANTIATION_TOKEN) != 0) {
        say(&probe, LOG_ERROR, "%s: instantiation token %s is not this FMU's (%s): refusing another FMU's model "
            "description", what, instantiationToken ? instantiationToken : "(NULL)", INSTANTIATION_TOKEN);
        return NULL;
    }
    if (type == TYPE_ME && N_STATES == 0) {
        say(&probe, LOG_ERROR, "%s: %s has no ModelExchange interface (co-simulation only)", what, MODEL_IDENTIFIER);
        return NULL;
    }
    Instance *inst = (Instance *)calloc(1, sizeof(Instance));
    Model *model = (Model *)calloc(1, model_size());
    if (inst == NULL || model == NULL) {
        free(inst);
        free(model);
        say(&probe, LOG_ERROR, "%s: out of memory", what);
        return NULL;
    }
    *inst = probe;
    inst->type = type;
    inst->logging_on = loggingOn ? 1 : 0;
    inst->model = model;
    inst->log.inst = inst;
    reset_values(inst);
    return inst;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    (void)resourcePath; /* everything is compiled in */
    (void)visible;
    return instantiate("fmi3InstantiateModelExchange", TYPE_ME, instanceName, instantiationToken, loggingOn,
                       instanceEnvironment, logMessage);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    (void)resourcePath;
    (void)visible;
    (void)earlyReturnAllowed; /* a step never returns early */
    (void)requiredIntermediateVariables;
    (void)nRequiredIntermediateVariables;
    (void)intermediateUpdate; /* no intermediate updates: steps are synchronous */
    if (eventModeUsed && logMessage != NULL) {
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateCoSimulation: this FMU has no event mode in co-simulation (hasEventMode=\"false\")");
        return NULL;
    }
    return instantiate("fmi3InstantiateCoSimulation", TYPE_CS, instanceName, instantiationToken, loggingOn,
                       instanceEnvironment, logMessage);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instanceName, (void)instantiationToken, (void)resourcePath, (void)visible, (void)loggingOn;
    (void)clockUpdate, (void)lockPreemption, (void)unlockPreemption;
    if (logMessage != NULL)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateScheduledExecution: this FMU has no ScheduledExecution interface");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance c)
{
    Instance *inst = begin(c);
    if (inst == NULL) return;
    inst->magic = 0;
    free(inst->model);
    free(inst);
}

/* ------------------------------------------------------------------ initialisation, reset */
fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    Instance *inst = begin(c);
    (void)toleranceDefined, (void)tolerance, (void)stopTimeDefined, (void)stopTime;
    if (inst == NULL) return fmi3Error;
    if (!require(inst, "fmi3EnterInitializationMode", inst->v.phase == PHASE_INSTANTIATED)) return fmi3Error;
    if (!isfinite(startTime)) {
        say(inst, LOG_ERROR, "fmi3EnterInitializationMode: start time %g is not finite", startTime);
        return fmi3Error;
    }
    inst->v.time = startTime;
    inst->v.phase = PHASE_INIT;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance c)
{
    Instance *inst = begin(c);
    char n[64];
    if (inst == NULL) return fmi3Error;
    if (!require(inst, "fmi3ExitInitializationMode", inst->v.phase == PHASE_INIT)) return fmi3Error;
    for (int i = 0; i < N_PARAMETERS; i++) {
        double x = inst->v.p[i];
        if (!isfinite(x) || x < PAR_MIN[i] || x > PAR_MAX[i]) {
            say(inst, LOG_ERROR, "parameter %s = %g is outside its declared range [%g, %g]",
                var_name((fmi3ValueReference)(VR_PAR0 + i), n), x, PAR_MIN[i], PAR_MAX[i]);
            inst->v.phase = PHASE_FAILED;
            return fmi3Error;
        }
    }
    inst->log.time = inst->v.time;
    if (model_setup(inst->model, inst->v.p, &inst->log) != 0) {
        say(inst, LOG_ERROR, "initialisation failed: the model refused its parameters");
        inst->v.phase = PHASE_FAILED;
        return fmi3Error;
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
    inst->v.phase = inst->type == TYPE_CS ? PHASE_STEP : PHASE_EVENT;
    return status_of(inst);
}

fmi3Status fmi3Terminate(fmi3Instance c)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi3Error;
    inst->v.phase = PHASE_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance c)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi3Error;
    reset_values(inst);
    return fmi3OK;
}

/* ------------------------------------------------------------------ get / set */
static int check_array(Instance *inst, const char *what, const void *vr, size_t nvr, const void *value,
                       size_t nValues)
{
    if (nvr > 0 && (vr == NULL || value == NULL)) {
        say(inst, LOG_ERROR, "%s: NULL array for %zu value references", what, nvr);
        return 0;
    }
    size_t expected = 0;
    for (size_t i = 0; i < nvr; i++) expected += n_values((long)((const fmi3ValueReference *)vr)[i]);
    if (nValues != expected) {
        say(inst, LOG_ERROR, "%s: %zu values for %zu value references, which hold %zu values", what, nValues, nvr,
            expected);
        return 0;
    }
    return 1;
}

static void unknown_ref(Instance *inst, const char *what, fmi3ValueReference vr, const char *type)
{
    char n[64];
    if ((long)vr < N_VR)
        say(inst, LOG_ERROR, "%s: value reference %u (%s) is not a%s %s variable", what, vr, var_name(vr, n),
            type[0] == 'I' ? "n" : "", type);
    else
        say(inst, LOG_ERROR, "%s: value reference %u is not a variable of %s (references 0..%u)", what, vr,
            MODEL_IDENTIFIER, (unsigned)N_VR - 1u);
}

fmi3Status fmi3GetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[],
                          size_t nValues)
{
    Instance *inst = begin(c);
    char n[64];
    if (inst == NULL) return fmi3Error;
    if (!check_array(inst, "fmi3GetFloat64", vr, nvr, values, nValues)) return fmi3Error;
    refresh_outputs(inst);
#if N_STATES > 0
    double x[N_STATES], dx[N_STATES];
    int have_x = 0, have_dx = 0;
#endif
#if N_STATES > 0 && N_EVENT_INDICATORS > 0
    double z[N_EVENT_INDICATORS];
    int have_z = 0;
#endif
    for (size_t i = 0, j = 0; i < nvr; j += n_values((long)vr[i]), i++) {
        long r = (long)vr[i];
        if (r >= VR_ARR0 && r < N_VR) { /* a gain array: its elements, row-major */
            memcpy(values + j, ARR_VALUES + ARR_OFFSET[r - VR_ARR0], sizeof(double) * n_values(r));
            continue;
        }
        double *out = values + j;
        *out = 0.0;
        if (r < VR_IN0) *out = inst->v.p[r - VR_PAR0];
        else if (r < VR_OUT0) *out = inst->v.u[r - VR_IN0];
        else if (r < VR_INT0) *out = inst->v.y[r - VR_OUT0];
        else if (r == VR_TIME) *out = inst->v.time;
#if N_STATES > 0
        else if (r >= VR_STATE0 && r < VR_TIME && !inst->v.ready) {
            *out = 0.0; /* not set up yet: computed at fmi3ExitInitializationMode */
        } else if (r >= VR_STATE0 && r < VR_DER0) {
            if (!have_x) model_me_get_states(inst->model, x), have_x = 1;
            *out = x[r - VR_STATE0];
        } else if (r >= VR_DER0 && r < VR_EVI0) {
            if (!have_dx) {
                if (!inputs_valid(inst->v.u)) {
                    say(inst, LOG_ERROR, "fmi3GetFloat64: derivative %s needs inputs inside their declared range",
                        var_name(vr[i], n));
                    continue;
                }
                model_me_derivatives(inst->model, inst->v.u, dx), have_dx = 1;
            }
            *out = dx[r - VR_DER0];
        }
#if N_EVENT_INDICATORS > 0
        else if (r >= VR_EVI0 && r < VR_TIME) {
            if (!have_z) {
                if (!inputs_valid(inst->v.u)) {
                    say(inst, LOG_ERROR, "fmi3GetFloat64: %s needs inputs inside their declared range",
                        var_name(vr[i], n));
                    continue;
                }
                model_me_event_indicators(inst->model, inst->v.u, z), have_z = 1;
            }
            *out = z[r - VR_EVI0];
        }
#endif
#endif
        else unknown_ref(inst, "fmi3GetFloat64", vr[i], "Float64");
    }
    (void)n;
    return status_of(inst);
}

fmi3Status fmi3GetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Int32 values[],
                        size_t nValues)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi3Error;
    if (!check_array(inst, "fmi3GetInt32", vr, nvr, values, nValues)) return fmi3Error;
    refresh_outputs(inst);
    for (size_t i = 0; i < nvr; i++) {
        long r = (long)vr[i];
        values[i] = 0;
        if (r >= VR_INT0 && r < VR_STATE0) values[i] = inst->v.yi[r - VR_INT0];
        else unknown_ref(inst, "fmi3GetInt32", vr[i], "Int32");
    }
    return status_of(inst);
}

fmi3Status fmi3SetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Float64 values[],
                          size_t nValues)
{
    Instance *inst = begin(c);
    char n[64];
    if (inst == NULL) return fmi3Error;
    if (!check_array(inst, "fmi3SetFloat64", vr, nvr, values, nValues)) return fmi3Error;
    int before_init = inst->v.phase == PHASE_INSTANTIATED || inst->v.phase == PHASE_INIT;
    for (size_t i = 0, j = 0; i < nvr; j += n_values((long)vr[i]), i++) {
        long r = (long)vr[i];
        if (r >= VR_IN0 && r < VR_OUT0) {
            inst->v.u[r - VR_IN0] = values[j]; /* checked (finite, in range) where it is used */
        } else if (r < VR_IN0) {
            if (before_init) inst->v.p[r - VR_PAR0] = values[j];
            else say(inst, LOG_WARNING, "parameter %s set after initialisation: ignored", var_name(vr[i], n));
        } else if (r >= VR_ARR0 && r < N_VR) {
            say(inst, LOG_ERROR, "fmi3SetFloat64: %s is a constant; ignored", var_name(vr[i], n));
        } else if (r < VR_INT0 || (r >= VR_STATE0 && r < N_VR)) {
            say(inst, LOG_ERROR, "fmi3SetFloat64: value reference %u (%s) is not an input or a parameter; ignored",
                vr[i], var_name(vr[i], n));
        } else {
            unknown_ref(inst, "fmi3SetFloat64", vr[i], "Float64");
        }
    }
    return status_of(inst);
}

fmi3Status fmi3SetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Int32 values[],
                        size_t nValues)
{
    Instance *inst = begin(c);
    char n[64];
    if (inst == NULL) return fmi3Error;
    if (!check_array(inst, "fmi3SetInt32", vr, nvr, values, nValues)) return fmi3Error;
    for (size_t i = 0; i < nvr; i++) {
        long r = (long)vr[i];
        if (r >= VR_INT0 && r < VR_STATE0)
            say(inst, LOG_ERROR, "fmi3SetInt32: value reference %u (%s) is an output; ignored", vr[i],
                var_name(vr[i], n));
        else
            unknown_ref(inst, "fmi3SetInt32", vr[i], "Int32");
    }
    return status_of(inst);
}

/* the types this FMU has no variable of: every reference is refused */
static fmi3Status no_such_type(fmi3Instance c, const char *what, const char *type, const fmi3ValueReference vr[],
                               size_t nvr, const void *values, size_t nValues)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi3Error;
    if (!check_array(inst, what, vr, nvr, values, nValues)) return fmi3Error;
    for (size_t i = 0; i < nvr; i++) unknown_ref(inst, what, vr[i], type);
    return status_of(inst);
}

#define NO_GET(T, NAME)                                                                                       \
    fmi3Status fmi3Get##NAME(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, T values[], size_t nValues) \
    {                                                                                                         \
        return no_such_type(c, "fmi3Get" #NAME, #NAME, vr, nvr, values, nValues);                             \
    }
#define NO_SET(T, NAME)                                                                                       \
    fmi3Status fmi3Set##NAME(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const T values[],     \
                             size_t nValues)                                                                  \
    {                                                                                                         \
        return no_such_type(c, "fmi3Set" #NAME, #NAME, vr, nvr, values, nValues);                             \
    }
#define NO_TYPE(T, NAME) NO_GET(T, NAME) NO_SET(T, NAME)

NO_TYPE(fmi3Float32, Float32)
NO_TYPE(fmi3Int8, Int8)
NO_TYPE(fmi3UInt8, UInt8)
NO_TYPE(fmi3Int16, Int16)
NO_TYPE(fmi3UInt16, UInt16)
NO_TYPE(fmi3UInt32, UInt32)
NO_TYPE(fmi3Int64, Int64)
NO_TYPE(fmi3UInt64, UInt64)
NO_TYPE(fmi3Boolean, Boolean)
NO_TYPE(fmi3String, String)

fmi3Status fmi3GetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, size_t valueSizes[],
                         fmi3Binary values[], size_t nValues)
{
    (void)valueSizes;
    return no_such_type(c, "fmi3GetBinary", "Binary", vr, nvr, values, nValues);
}

fmi3Status fmi3SetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues)
{
    (void)valueSizes;
    return no_such_type(c, "fmi3SetBinary", "Binary", vr, nvr, values, nValues);
}

fmi3Status fmi3GetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[])
{
    return no_such_type(c, "fmi3GetClock", "Clock", vr, nvr, values, nvr);
}

fmi3Status fmi3SetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock values[])
{
    return no_such_type(c, "fmi3SetClock", "Clock", vr, nvr, values, nvr);
}

/* ------------------------------------------------------------------ what is not provided */
static fmi3Status not_provided(fmi3Instance c, const char *what)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi3Error;
    say(inst, LOG_ERROR, "%s is not provided by this FMU", what);
    return fmi3Error;
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance c, fmi3ValueReference valueReference,
                                               size_t *nDependencies)
{
    (void)valueReference, (void)nDependencies;
    return not_provided(c, "fmi3GetNumberOfVariableDependencies (the model description lists the dependencies)");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance c, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies)
{
    (void)dependent, (void)elementIndicesOfDependent, (void)independents, (void)elementIndicesOfIndependents;
    (void)dependencyKinds, (void)nDependencies;
    return not_provided(c, "fmi3GetVariableDependencies (the model description lists the dependencies)");
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance c, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed, (void)sensitivity;
    (void)nSensitivity;
    return not_provided(c, "fmi3GetDirectionalDerivative (providesDirectionalDerivatives=\"false\")");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance c, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed, (void)sensitivity;
    (void)nSensitivity;
    return not_provided(c, "fmi3GetAdjointDerivative (providesAdjointDerivatives=\"false\")");
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance c)
{
    return not_provided(c, "fmi3EnterConfigurationMode (no structural parameters)");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance c)
{
    return not_provided(c, "fmi3ExitConfigurationMode (no structural parameters)");
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr,
                                  fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[])
{
    (void)vr, (void)nvr, (void)intervals, (void)qualifiers;
    return not_provided(c, "fmi3GetIntervalDecimal (no clocks)");
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr,
                                   fmi3UInt64 counters[], fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[])
{
    (void)vr, (void)nvr, (void)counters, (void)resolutions, (void)qualifiers;
    return not_provided(c, "fmi3GetIntervalFraction (no clocks)");
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 shifts[])
{
    (void)vr, (void)nvr, (void)shifts;
    return not_provided(c, "fmi3GetShiftDecimal (no clocks)");
}

fmi3Status fmi3GetShiftFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3UInt64 counters[],
                                fmi3UInt64 resolutions[])
{
    (void)vr, (void)nvr, (void)counters, (void)resolutions;
    return not_provided(c, "fmi3GetShiftFraction (no clocks)");
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr,
                                  const fmi3Float64 intervals[])
{
    (void)vr, (void)nvr, (void)intervals;
    return not_provided(c, "fmi3SetIntervalDecimal (no clocks)");
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr,
                                   const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{
    (void)vr, (void)nvr, (void)counters, (void)resolutions;
    return not_provided(c, "fmi3SetIntervalFraction (no clocks)");
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Float64 shifts[])
{
    (void)vr, (void)nvr, (void)shifts;
    return not_provided(c, "fmi3SetShiftDecimal (no clocks)");
}

fmi3Status fmi3SetShiftFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{
    (void)vr, (void)nvr, (void)counters, (void)resolutions;
    return not_provided(c, "fmi3SetShiftFraction (no clocks)");
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance c)
{
    return not_provided(c, "fmi3EvaluateDiscreteStates (no clocks)");
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr,
                                    const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues)
{
    (void)vr, (void)nvr, (void)orders, (void)values, (void)nValues;
    return not_provided(c, "fmi3GetOutputDerivatives (maxOutputDerivativeOrder=\"0\")");
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance c, fmi3ValueReference clockReference, fmi3Float64 activationTime)
{
    (void)clockReference, (void)activationTime;
    return not_provided(c, "fmi3ActivateModelPartition (no ScheduledExecution interface)");
}

/* ------------------------------------------------------------------ FMU state */
typedef struct {
    unsigned magic;
    Values v;
} StateHeader;

fmi3Status fmi3GetFMUState(fmi3Instance c, fmi3FMUState *state)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi3Error;
    if (state == NULL) {
        say(inst, LOG_ERROR, "fmi3GetFMUState: NULL state pointer");
        return fmi3Error;
    }
    StateHeader *blob = (StateHeader *)*state;
    if (blob == NULL) blob = (StateHeader *)malloc(sizeof(StateHeader) + model_size());
    if (blob == NULL) {
        say(inst, LOG_ERROR, "fmi3GetFMUState: out of memory");
        return fmi3Error;
    }
    blob->magic = MAGIC;
    blob->v = inst->v;
    memcpy(blob + 1, inst->model, model_size());
    *state = blob;
    return fmi3OK;
}

static int valid_state(Instance *inst, const char *what, const StateHeader *blob)
{
    if (blob == NULL || blob->magic != MAGIC) {
        say(inst, LOG_ERROR, "%s: not a state of this FMU", what);
        return 0;
    }
    return 1;
}

fmi3Status fmi3SetFMUState(fmi3Instance c, fmi3FMUState state)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi3Error;
    const StateHeader *blob = (const StateHeader *)state;
    if (!valid_state(inst, "fmi3SetFMUState", blob)) return fmi3Error;
    inst->v = blob->v;
    memcpy(inst->model, blob + 1, model_size());
    return fmi3OK;
}

fmi3Status fmi3FreeFMUState(fmi3Instance c, fmi3FMUState *state)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi3Error;
    if (state != NULL) {
        free(*state);
        *state = NULL;
    }
    return fmi3OK;
}

/* serialised: the instantiation token, then the state blob */
static size_t serialized_size(void)
{
    return sizeof INSTANTIATION_TOKEN + sizeof(StateHeader) + model_size();
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance c, fmi3FMUState state, size_t *size)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi3Error;
    if (!valid_state(inst, "fmi3SerializedFMUStateSize", (const StateHeader *)state)) return fmi3Error;
    if (size == NULL) {
        say(inst, LOG_ERROR, "fmi3SerializedFMUStateSize: NULL size pointer");
        return fmi3Error;
    }
    *size = serialized_size();
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance c, fmi3FMUState state, fmi3Byte serializedState[], size_t size)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi3Error;
    if (!valid_state(inst, "fmi3SerializeFMUState", (const StateHeader *)state)) return fmi3Error;
    if (serializedState == NULL || size < serialized_size()) {
        say(inst, LOG_ERROR, "fmi3SerializeFMUState: buffer of %zu bytes, %zu needed", size, serialized_size());
        return fmi3Error;
    }
    memcpy(serializedState, INSTANTIATION_TOKEN, sizeof INSTANTIATION_TOKEN);
    memcpy(serializedState + sizeof INSTANTIATION_TOKEN, state, sizeof(StateHeader) + model_size());
    return fmi3OK;
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance c, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *state)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi3Error;
    StateHeader head;
    if (serializedState != NULL && size == serialized_size())
        memcpy(&head, serializedState + sizeof INSTANTIATION_TOKEN, sizeof head);
    if (serializedState == NULL || state == NULL || size != serialized_size() ||
        memcmp(serializedState, INSTANTIATION_TOKEN, sizeof INSTANTIATION_TOKEN) != 0 || head.magic != MAGIC) {
        say(inst, LOG_ERROR, "fmi3DeserializeFMUState: not a serialised state of this FMU (token %s, %zu bytes)",
            INSTANTIATION_TOKEN, serialized_size());
        return fmi3Error;
    }
    void *blob = realloc(*state, sizeof(StateHeader) + model_size());
    if (blob == NULL) {
        say(inst, LOG_ERROR, "fmi3DeserializeFMUState: out of memory");
        return fmi3Error;
    }
    memcpy(blob, serializedState + sizeof INSTANTIATION_TOKEN, sizeof(StateHeader) + model_size());
    *state = blob;
    return fmi3OK;
}

/* ------------------------------------------------------------------ co-simulation */
fmi3Status fmi3EnterStepMode(fmi3Instance c)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi3Error;
    if (!require_type(inst, "fmi3EnterStepMode", TYPE_CS)) return fmi3Error;
    say(inst, LOG_ERROR, "fmi3EnterStepMode: this FMU has no event mode in co-simulation (it is in step mode after "
        "fmi3ExitInitializationMode)");
    return fmi3Error;
}

fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *eventHandlingNeeded,
                      fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime)
{
    Instance *inst = begin(c);
    (void)noSetFMUStatePriorToCurrentPoint;
    if (inst == NULL) return fmi3Error;
    if (eventHandlingNeeded) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = fmi3False;
    if (lastSuccessfulTime) *lastSuccessfulTime = inst->v.time;
    if (!require_type(inst, "fmi3DoStep", TYPE_CS)) return fmi3Error;
    if (inst->v.phase != PHASE_STEP) {
        say(inst, LOG_ERROR, "step refused at t = %g: fmi3DoStep called in %s (call fmi3ExitInitializationMode "
            "first%s)", currentCommunicationPoint, phase_name(inst->v.phase),
            inst->v.phase == PHASE_FAILED ? "; initialisation failed, see the earlier error" : "");
        return fmi3Error;
    }
    if (!(communicationStepSize > 0.0) || !isfinite(communicationStepSize)) {
        say(inst, LOG_ERROR, "step refused: communication step %g must be finite and > 0 s", communicationStepSize);
        return fmi3Error;
    }
    if (communicationStepSize > MAX_STEP_REFUSED_ABOVE) {
        char t[32], h[32], m[32];
        say(inst, LOG_ERROR, "step refused at t = %s: communication step %s s exceeds this FMU's longest step %s s "
            "(declared in its model description); state held", py_repr(currentCommunicationPoint, t),
            py_repr(communicationStepSize, h), py_repr(MAX_STEP, m));
        return fmi3Error;
    }
    if (!inputs_ok(inst, "step")) return fmi3Error;
    inst->log.time = currentCommunicationPoint;
    if (model_do_step(inst->model, communicationStepSize, inst->v.u, &inst->log) == 0) {
        inst->v.time = currentCommunicationPoint + communicationStepSize;
        model_outputs(inst->model, inst->v.y, inst->v.yi);
    } else if (inst->log.worst < LOG_ERROR) {
        say(inst, LOG_ERROR, "step refused at t = %g by the model", currentCommunicationPoint);
    }
    if (lastSuccessfulTime) *lastSuccessfulTime = inst->v.time;
    return status_of(inst);
}

/* ------------------------------------------------------------------ model exchange */
#define IN_EVENT (1 << PHASE_EVENT)
#define IN_CONT (1 << PHASE_CONTINUOUS)
#define IN_INIT ((1 << PHASE_INSTANTIATED) | (1 << PHASE_INIT))
#define IN_RUN (IN_EVENT | IN_CONT | (1 << PHASE_TERMINATED)) /* the model is set up */

static Instance *me_begin(fmi3Instance c, const char *what, int phases)
{
    Instance *inst = begin(c);
    if (inst == NULL) return NULL;
    if (!require_type(inst, what, TYPE_ME)) return NULL;
    if (!require(inst, what, (phases >> inst->v.phase) & 1)) return NULL;
    if (phases == IN_RUN && !inst->v.ready) {
        say(inst, LOG_ERROR, "%s: the model was never initialised (fmi3ExitInitializationMode failed or was "
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

fmi3Status fmi3EnterEventMode(fmi3Instance c)
{
    Instance *inst = me_begin(c, "fmi3EnterEventMode", IN_EVENT | IN_CONT);
    if (inst == NULL) return fmi3Error;
    inst->v.phase = PHASE_EVENT;
    return fmi3OK;
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime)
{
    Instance *inst = me_begin(c, "fmi3UpdateDiscreteStates", IN_EVENT);
    if (inst == NULL) return fmi3Error;
    if (discreteStatesNeedUpdate == NULL || terminateSimulation == NULL || nominalsOfContinuousStatesChanged == NULL ||
        valuesOfContinuousStatesChanged == NULL || nextEventTimeDefined == NULL || nextEventTime == NULL) {
        say(inst, LOG_ERROR, "fmi3UpdateDiscreteStates: NULL result pointer");
        return fmi3Error;
    }
    *discreteStatesNeedUpdate = fmi3False;
    *terminateSimulation = fmi3False;
    *nominalsOfContinuousStatesChanged = fmi3False;
    *valuesOfContinuousStatesChanged = fmi3False;
    *nextEventTimeDefined = fmi3False; /* every event of these models is a state event */
    *nextEventTime = 0.0;
#if N_STATES > 0
    if (!inputs_ok(inst, "fmi3UpdateDiscreteStates")) return fmi3Error;
    *valuesOfContinuousStatesChanged =
        model_me_event_update(inst->model, inst->v.time, inst->v.u, &inst->log) ? fmi3True : fmi3False;
#endif
    return status_of(inst);
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance c)
{
    Instance *inst = me_begin(c, "fmi3EnterContinuousTimeMode", IN_EVENT);
    if (inst == NULL) return fmi3Error;
    inst->v.phase = PHASE_CONTINUOUS;
    return fmi3OK;
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance c, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation)
{
    Instance *inst = me_begin(c, "fmi3CompletedIntegratorStep", IN_CONT);
    (void)noSetFMUStatePriorToCurrentPoint;
    if (inst == NULL) return fmi3Error;
    if (enterEventMode == NULL || terminateSimulation == NULL) {
        say(inst, LOG_ERROR, "fmi3CompletedIntegratorStep: NULL result pointer");
        return fmi3Error;
    }
    *enterEventMode = fmi3False; /* every event of these models is a state event */
    *terminateSimulation = fmi3False;
    return fmi3OK;
}

fmi3Status fmi3SetTime(fmi3Instance c, fmi3Float64 time)
{
    Instance *inst = me_begin(c, "fmi3SetTime", IN_EVENT | IN_CONT | IN_INIT);
    if (inst == NULL) return fmi3Error;
    if (!isfinite(time)) {
        say(inst, LOG_ERROR, "fmi3SetTime: time %g is not finite", time);
        return fmi3Error;
    }
    inst->v.time = time;
    return fmi3OK;
}

fmi3Status fmi3SetContinuousStates(fmi3Instance c, const fmi3Float64 x[], size_t nx)
{
    Instance *inst = me_begin(c, "fmi3SetContinuousStates", IN_EVENT | IN_CONT);
    if (inst == NULL || !count_ok(inst, "fmi3SetContinuousStates", x, nx, N_STATES)) return fmi3Error;
#if N_STATES > 0
    if (!all_finite(x, N_STATES)) {
        say(inst, LOG_ERROR, "fmi3SetContinuousStates: non-finite state refused");
        return fmi3Error;
    }
    model_me_set_states(inst->model, x);
#else
    (void)all_finite;
#endif
    return fmi3OK;
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance c, fmi3Float64 derivatives[], size_t nx)
{
    Instance *inst = me_begin(c, "fmi3GetContinuousStateDerivatives", IN_RUN);
    if (inst == NULL || !count_ok(inst, "fmi3GetContinuousStateDerivatives", derivatives, nx, N_STATES))
        return fmi3Error;
#if N_STATES > 0
    if (!inputs_ok(inst, "fmi3GetContinuousStateDerivatives")) return fmi3Error;
    model_me_derivatives(inst->model, inst->v.u, derivatives);
#endif
    return status_of(inst);
}

fmi3Status fmi3GetEventIndicators(fmi3Instance c, fmi3Float64 eventIndicators[], size_t ni)
{
    Instance *inst = me_begin(c, "fmi3GetEventIndicators", IN_RUN);
    if (inst == NULL) return fmi3Error;
    if (ni == 0 && N_EVENT_INDICATORS == 0) return fmi3OK;
    if (!count_ok(inst, "fmi3GetEventIndicators", eventIndicators, ni, N_EVENT_INDICATORS)) return fmi3Error;
#if N_STATES > 0 && N_EVENT_INDICATORS > 0
    if (!inputs_ok(inst, "fmi3GetEventIndicators")) return fmi3Error;
    model_me_event_indicators(inst->model, inst->v.u, eventIndicators);
#endif
    return status_of(inst);
}

fmi3Status fmi3GetContinuousStates(fmi3Instance c, fmi3Float64 x[], size_t nx)
{
    Instance *inst = me_begin(c, "fmi3GetContinuousStates", IN_RUN);
    if (inst == NULL || !count_ok(inst, "fmi3GetContinuousStates", x, nx, N_STATES)) return fmi3Error;
#if N_STATES > 0
    model_me_get_states(inst->model, x);
#endif
    return fmi3OK;
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance c, fmi3Float64 nominals[], size_t nx)
{
    Instance *inst = me_begin(c, "fmi3GetNominalsOfContinuousStates", IN_RUN);
    if (inst == NULL || !count_ok(inst, "fmi3GetNominalsOfContinuousStates", nominals, nx, N_STATES))
        return fmi3Error;
#if N_STATES > 0
    model_me_nominals(inst->model, nominals);
#endif
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance c, size_t *nEventIndicators)
{
    Instance *inst = me_begin(c, "fmi3GetNumberOfEventIndicators", IN_INIT | IN_RUN);
    if (inst == NULL) return fmi3Error;
    if (nEventIndicators == NULL) {
        say(inst, LOG_ERROR, "fmi3GetNumberOfEventIndicators: NULL pointer");
        return fmi3Error;
    }
    *nEventIndicators = N_EVENT_INDICATORS;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance c, size_t *nContinuousStates)
{
    Instance *inst = me_begin(c, "fmi3GetNumberOfContinuousStates", IN_INIT | IN_RUN);
    if (inst == NULL) return fmi3Error;
    if (nContinuousStates == NULL) {
        say(inst, LOG_ERROR, "fmi3GetNumberOfContinuousStates: NULL pointer");
        return fmi3Error;
    }
    *nContinuousStates = N_STATES;
    return fmi3OK;
}
