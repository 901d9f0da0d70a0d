/*
 * fmi3_layer.c - the FMI 3.0 layer of the latobs native FMUs (Co-Simulation and Model Exchange),
 * over the same model interface (model.h) as fmi2_layer.c: a model file compiles unchanged with
 * either layer. No maths here: it maps the FMI 3.0 calls, types and statuses onto the instance,
 * state machine, logging and checks both layers share (layer.h), in the manner of the Reference
 * FMUs' fmi3Functions.c beside their fmi2Functions.c.
 *
 * Value references: those of the FMI 2.0 layer (parameters, inputs, Float64 outputs, Int32
 * outputs, the ModelExchange states and their derivatives), then the event indicators (local
 * Float64 variables, as FMI 3.0 declares them), the independent variable `time` and the gain
 * arrays (constants, LAYER_CONFIG: ARR_*; an array's values count in nValues).
 *
 * Misuse is refused as in fmi2_layer.c (a message naming the culprit is logged whatever the
 * logging setting; the host is never crashed; the state is kept):
 *   - instantiation with a wrong or NULL instantiation token, a NULL instance name or logger, an
 *     interface the FMU lacks (ModelExchange with no states, Scheduled Execution, Co-Simulation
 *     with event mode): NULL;
 *   - a NULL or foreign instance pointer: fmi3Error (nothing to log through);
 *   - an unknown value reference, one of another type, setting an output or a constant, a NULL
 *     array with a nonzero count, nValues not the number of values the references hold: fmi3Error,
 *     nothing set;
 *   - a parameter set after initialisation: ignored, fmi3Warning;
 *   - a parameter outside its declared [min, max] or refused by the model: fmi3Error at
 *     fmi3ExitInitializationMode, the instance refuses to step until fmi3Reset;
 *   - a call in the wrong state or of the other interface: fmi3Error;
 *   - a non-finite, non-positive or too long communication step (MAX_STEP), an input outside its
 *     declared [min, max] (non-finite included) at fmi3DoStep or a ModelExchange evaluation:
 *     fmi3Error, the state kept;
 *   - a state of another FMU (or of this model's FMI 2.0 FMU), a truncated, extended or corrupted
 *     one, in memory or serialised, given to any FMU-state function: fmi3Error, the state kept
 *     (layer.h: a state carries a hash of its FMU's token, its size and a checksum);
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

#define LATOBS_LAYER /* one object for every FMU: the FMU's configuration is read at run time */
#include "model.h"
#include "layer_config.h"
#include "model_util.h"

#define LAYER_PREFIX "fmi3"
#define LAYER_MAGIC 0x4c415433u /* "LAT3": marks a live instance of this layer */
#define LAYER_HOST                 \
    fmi3InstanceEnvironment env;   \
    fmi3LogMessageCallback logger;
#define VR_EVI0 VR_ME_END
#define VR_TIME (VR_EVI0 + N_EVENT_INDICATORS)
#define VR_ARR0 (VR_TIME + 1) /* the gain arrays (constants, LAYER_CONFIG: ARR_*) */
#define N_VR (VR_ARR0 + N_ARRAYS)
#include "layer.h"

static void host_log(const Instance *inst, int level, const char *text)
{
    if (inst->logger == NULL) return;
    inst->logger(inst->env, level == LOG_ERROR ? fmi3Error : level == LOG_WARNING ? fmi3Warning : fmi3OK,
                 level == LOG_ERROR ? "logStatusError" : level == LOG_WARNING ? "logStatusWarning" : "logAll", text);
}

static const char *var_name(long r, char buf[64])
{
    if (r >= 0 && r < VR_EVI0) return VAR_NAMES[r];
    if (r >= VR_EVI0 && r < VR_TIME) {
        snprintf(buf, 64, "event_indicator_%ld", r - VR_EVI0 + 1);
        return buf;
    }
    if (r >= VR_ARR0 && r < N_VR) return ARR_NAMES[r - VR_ARR0];
    return r == VR_TIME ? "time" : "?";
}

static fmi3Status status(int level)
{
    return level >= LOG_ERROR ? fmi3Error : level >= LOG_WARNING ? fmi3Warning : fmi3OK;
}

/* how many values variable r has: an array's elements, else 1 (a scalar or an unknown reference) */
static size_t n_values(long r)
{
    return r >= VR_ARR0 && r < N_VR ? (size_t)ARR_SIZE[r - VR_ARR0] : 1u;
}

/* layer.h's check_array, and nValues: the number of values the references hold */
static int check_values(Instance *inst, const char *what, const fmi3ValueReference *vr, size_t nvr,
                        const void *values, size_t nValues)
{
    if (!check_array(inst, what, vr, nvr, values)) return 0;
    size_t expected = 0;
    for (size_t i = 0; i < nvr; i++) expected += n_values((long)vr[i]);
    if (nValues != expected) {
        say(inst, LOG_ERROR, "%s: %zu values for %zu value references, which hold %zu values", what, nValues, nvr,
            expected);
        return 0;
    }
    return 1;
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

static Instance *instantiate3(const char *what, Interface type, fmi3String instanceName, fmi3String token,
                              fmi3Boolean loggingOn, fmi3InstanceEnvironment env, fmi3LogMessageCallback logger)
{
    Instance probe;
    if (logger == NULL) return NULL; /* nobody to tell */
    memset(&probe, 0, sizeof probe);
    probe.env = env;
    probe.logger = logger;
    snprintf(probe.name, sizeof probe.name, "%s", instanceName ? instanceName : "");
    return instantiate(&probe, what, "instantiation token", token, type, loggingOn ? 1 : 0);
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    (void)resourcePath; /* everything is compiled in */
    (void)visible;
    return instantiate3("fmi3InstantiateModelExchange", IF_ME, instanceName, instantiationToken, loggingOn,
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
    return instantiate3("fmi3InstantiateCoSimulation", IF_CS, instanceName, instantiationToken, loggingOn,
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
    free_instance(c);
}

/* ------------------------------------------------------------------ initialisation, reset */
fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    Instance *inst = begin(c);
    (void)toleranceDefined, (void)tolerance, (void)stopTimeDefined, (void)stopTime;
    if (inst == NULL) return fmi3Error;
    int level = set_start_time(inst, "fmi3EnterInitializationMode", startTime);
    return status(level >= LOG_ERROR ? level : enter_initialization(inst));
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance c)
{
    Instance *inst = begin(c);
    return inst == NULL ? fmi3Error : status(exit_initialization(inst));
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
fmi3Status fmi3GetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[],
                          size_t nValues)
{
    Instance *inst = begin(c);
    GetCache cache = {{0}, {0}, 0, 0};
    char n[64];
    double z[LAYER_MAX_EVENT_INDICATORS];
    int have_z = 0;
    if (inst == NULL) return fmi3Error;
    if (!check_values(inst, "fmi3GetFloat64", vr, nvr, values, nValues)) return fmi3Error;
    refresh_outputs(inst);
    for (size_t i = 0, j = 0; i < nvr; j += n_values((long)vr[i]), i++) {
        long r = (long)vr[i];
        double *out = values + j;
        if (r >= VR_ARR0 && r < N_VR) /* a gain array: its elements, row-major */
            memcpy(out, ARR_VALUES + ARR_OFFSET[r - VR_ARR0], sizeof(double) * n_values(r));
        else if (r == VR_TIME)
            *out = inst->v.time;
        else if (r >= VR_EVI0 && r < VR_TIME) {
            *out = 0.0; /* (before initialisation: not computed yet) */
            if (!inst->v.ready || N_STATES == 0) continue;
            if (!have_z) {
                if (!inputs_valid(inst->v.u)) {
                    say(inst, LOG_ERROR, "fmi3GetFloat64: %s needs inputs inside their declared range", var_name(r, n));
                    continue;
                }
                model_me_event_indicators(inst->model, inst->v.u, z), have_z = 1;
            }
            *out = z[r - VR_EVI0];
        } else if (!get_real(inst, "fmi3GetFloat64", r, out, &cache))
            unknown_ref(inst, "fmi3GetFloat64", r, "Float64");
    }
    (void)n;
    return status(inst->log.worst);
}

fmi3Status fmi3GetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Int32 values[],
                        size_t nValues)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi3Error;
    if (!check_values(inst, "fmi3GetInt32", vr, nvr, values, nValues)) return fmi3Error;
    refresh_outputs(inst);
    for (size_t i = 0; i < nvr; i++) {
        long r = (long)vr[i];
        values[i] = 0;
        if (r >= VR_INT0 && r < VR_STATE0) values[i] = inst->v.yi[r - VR_INT0];
        else unknown_ref(inst, "fmi3GetInt32", r, "Int32");
    }
    return status(inst->log.worst);
}

fmi3Status fmi3SetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Float64 values[],
                          size_t nValues)
{
    Instance *inst = begin(c);
    char n[64];
    if (inst == NULL) return fmi3Error;
    if (!check_values(inst, "fmi3SetFloat64", vr, nvr, values, nValues)) return fmi3Error;
    for (size_t i = 0, j = 0; i < nvr; j += n_values((long)vr[i]), i++) {
        long r = (long)vr[i];
        if (r >= VR_ARR0 && r < N_VR)
            say(inst, LOG_ERROR, "fmi3SetFloat64: %s is a constant; ignored", var_name(r, n));
        else if (r >= VR_EVI0 && r <= VR_TIME)
            say(inst, LOG_ERROR, "fmi3SetFloat64: value reference %ld (%s) is not an input or a parameter; ignored",
                r, var_name(r, n));
        else if (!set_real(inst, "fmi3SetFloat64", r, values[j]))
            unknown_ref(inst, "fmi3SetFloat64", r, "Float64");
    }
    return status(inst->log.worst);
}

fmi3Status fmi3SetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Int32 values[],
                        size_t nValues)
{
    Instance *inst = begin(c);
    char n[64];
    if (inst == NULL) return fmi3Error;
    if (!check_values(inst, "fmi3SetInt32", vr, nvr, values, nValues)) return fmi3Error;
    for (size_t i = 0; i < nvr; i++) {
        long r = (long)vr[i];
        if (r >= VR_INT0 && r < VR_STATE0)
            say(inst, LOG_ERROR, "fmi3SetInt32: value reference %ld (%s) is an output; ignored", r, var_name(r, n));
        else
            unknown_ref(inst, "fmi3SetInt32", r, "Int32");
    }
    return status(inst->log.worst);
}

/* the types this FMU has no variable of: every reference is refused */
static fmi3Status no_such_type(fmi3Instance c, const char *what, const char *type, const fmi3ValueReference vr[],
                               size_t nvr, const void *values, size_t nValues)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi3Error;
    if (!check_values(inst, what, vr, nvr, values, nValues)) return fmi3Error;
    for (size_t i = 0; i < nvr; i++) unknown_ref(inst, what, (long)vr[i], type);
    return status(inst->log.worst);
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
fmi3Status fmi3GetFMUState(fmi3Instance c, fmi3FMUState *state)
{
    Instance *inst = begin(c);
    return inst == NULL ? fmi3Error : status(get_state(inst, "fmi3GetFMUState", state));
}

fmi3Status fmi3SetFMUState(fmi3Instance c, fmi3FMUState state)
{
    Instance *inst = begin(c);
    return inst == NULL ? fmi3Error : status(set_state(inst, "fmi3SetFMUState", state));
}

fmi3Status fmi3FreeFMUState(fmi3Instance c, fmi3FMUState *state)
{
    Instance *inst = begin(c);
    return inst == NULL ? fmi3Error : status(free_state(inst, "fmi3FreeFMUState", state));
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance c, fmi3FMUState state, size_t *size)
{
    Instance *inst = begin(c);
    return inst == NULL ? fmi3Error : status(state_size(inst, "fmi3SerializedFMUStateSize", state, size));
}

fmi3Status fmi3SerializeFMUState(fmi3Instance c, fmi3FMUState state, fmi3Byte serializedState[], size_t size)
{
    Instance *inst = begin(c);
    return inst == NULL ? fmi3Error : status(serialize(inst, "fmi3SerializeFMUState", state, serializedState, size));
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance c, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *state)
{
    Instance *inst = begin(c);
    return inst == NULL ? fmi3Error
                        : status(deserialize(inst, "fmi3DeserializeFMUState", serializedState, size, state));
}

/* ------------------------------------------------------------------ co-simulation */
fmi3Status fmi3EnterStepMode(fmi3Instance c)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi3Error;
    if (!require_type(inst, "fmi3EnterStepMode", IF_CS)) return fmi3Error;
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
    fmi3Status s = status(do_step(inst, currentCommunicationPoint, communicationStepSize));
    if (lastSuccessfulTime) *lastSuccessfulTime = inst->v.time;
    return s;
}

/* ------------------------------------------------------------------ model exchange */
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
    int changed;
    if (inst == NULL) return fmi3Error;
    if (discreteStatesNeedUpdate == NULL || terminateSimulation == NULL || nominalsOfContinuousStatesChanged == NULL ||
        valuesOfContinuousStatesChanged == NULL || nextEventTimeDefined == NULL || nextEventTime == NULL) {
        say(inst, LOG_ERROR, "fmi3UpdateDiscreteStates: NULL result pointer");
        return fmi3Error;
    }
    *discreteStatesNeedUpdate = fmi3False;
    *terminateSimulation = fmi3False;
    *nominalsOfContinuousStatesChanged = fmi3False;
    *nextEventTimeDefined = fmi3False; /* every event of these models is a state event */
    *nextEventTime = 0.0;
    fmi3Status s = status(event_update(inst, "fmi3UpdateDiscreteStates", &changed));
    *valuesOfContinuousStatesChanged = changed ? fmi3True : fmi3False;
    return s;
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
    return inst == NULL ? fmi3Error : status(set_time(inst, "fmi3SetTime", time));
}

fmi3Status fmi3SetContinuousStates(fmi3Instance c, const fmi3Float64 x[], size_t nx)
{
    Instance *inst = me_begin(c, "fmi3SetContinuousStates", IN_EVENT | IN_CONT);
    return inst == NULL ? fmi3Error : status(set_states(inst, "fmi3SetContinuousStates", x, nx));
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance c, fmi3Float64 derivatives[], size_t nx)
{
    Instance *inst = me_begin(c, "fmi3GetContinuousStateDerivatives", IN_RUN);
    return inst == NULL ? fmi3Error : status(get_derivatives(inst, "fmi3GetContinuousStateDerivatives", derivatives, nx));
}

fmi3Status fmi3GetEventIndicators(fmi3Instance c, fmi3Float64 eventIndicators[], size_t ni)
{
    Instance *inst = me_begin(c, "fmi3GetEventIndicators", IN_RUN);
    if (inst == NULL) return fmi3Error;
    if (ni == 0 && N_EVENT_INDICATORS == 0) return fmi3OK;
    return status(get_event_indicators(inst, "fmi3GetEventIndicators", eventIndicators, ni));
}

fmi3Status fmi3GetContinuousStates(fmi3Instance c, fmi3Float64 x[], size_t nx)
{
    Instance *inst = me_begin(c, "fmi3GetContinuousStates", IN_RUN);
    return inst == NULL ? fmi3Error : status(get_states(inst, "fmi3GetContinuousStates", x, nx, 0));
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance c, fmi3Float64 nominals[], size_t nx)
{
    Instance *inst = me_begin(c, "fmi3GetNominalsOfContinuousStates", IN_RUN);
    return inst == NULL ? fmi3Error : status(get_states(inst, "fmi3GetNominalsOfContinuousStates", nominals, nx, 1));
}

/* the number of states or indicators, in any phase of a model exchange instance */
static fmi3Status count_of(fmi3Instance c, const char *what, size_t *n, size_t value)
{
    Instance *inst = me_begin(c, what, IN_INIT | IN_RUN);
    if (inst == NULL) return fmi3Error;
    if (n == NULL) {
        say(inst, LOG_ERROR, "%s: NULL pointer", what);
        return fmi3Error;
    }
    *n = value;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance c, size_t *nEventIndicators)
{
    return count_of(c, "fmi3GetNumberOfEventIndicators", nEventIndicators, N_EVENT_INDICATORS);
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance c, size_t *nContinuousStates)
{
    return count_of(c, "fmi3GetNumberOfContinuousStates", nContinuousStates, N_STATES);
}
