/*
 * fmi2_layer.c - the FMI 2.0 layer of every latobs native FMU (CoSimulation and ModelExchange).
 *
 * Hand-written, shared by every model file (model.h); no maths here. It maps the FMI 2.0 calls,
 * types and statuses onto the instance, state machine, logging and checks that both FMI layers
 * share (layer.h); fmi3_layer.c is its FMI 3.0 counterpart. A model file (<runtime>.c) gives the
 * maths through model.h; the FMU's identifiers, guid and variable table are read at run time from
 * LAYER_CONFIG (layer_config.h, defined by layer_config.c from the FMU's generated headers),
 * so one compiled layer serves every FMU.
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
 * model holds no pointers), behind a header naming the FMU (a hash of its guid), the layer, the
 * platform, the size and a checksum (layer.h). A state of another FMU (or of this model's FMI 3.0
 * FMU), a truncated, extended or corrupted one, in memory or serialised, is refused with fmi2Error
 * and a message saying which, the instance's state kept; fmi2FreeFMUstate refuses to free another
 * FMU's state.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#define LATOBS_LAYER /* one object for every FMU: the FMU's configuration is read at run time */
#include "model.h"
#include "layer_config.h"
#include "model_util.h"

#define LAYER_PREFIX "fmi2"
#define LAYER_MAGIC 0x4c41544fu /* "LATO": marks a live instance of this library */
#define LAYER_HOST fmi2CallbackFunctions cb;
#define N_VR VR_ME_END
#include "layer.h"

static void host_log(const Instance *inst, int level, const char *text)
{
    static const char *const category[] = {"logAll", "logStatusWarning", "logAll", "logStatusError"};
    char escaped[2 * MSG_MAX];
    size_t k = 0;
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

static const char *var_name(long r, char buf[64])
{
    (void)buf;
    return r >= 0 && r < N_VR ? VAR_NAMES[r] : "?";
}

static fmi2Status status(int level)
{
    return level >= LOG_ERROR ? fmi2Error : level >= LOG_WARNING ? fmi2Warning : fmi2OK;
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
    probe.magic = LAYER_MAGIC;
    probe.cb = *functions;
    snprintf(probe.name, sizeof probe.name, "%s", instanceName ? instanceName : "");
    if (fmuType != fmi2CoSimulation && fmuType != fmi2ModelExchange) {
        say(&probe, LOG_ERROR, "fmi2Instantiate: unknown interface type %d", (int)fmuType);
        return NULL;
    }
    return instantiate(&probe, "fmi2Instantiate", "guid", fmuGUID, fmuType == fmi2ModelExchange ? IF_ME : IF_CS,
                       loggingOn ? 1 : 0);
}

void fmi2FreeInstance(fmi2Component c)
{
    free_instance(c);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    Instance *inst = begin(c);
    (void)toleranceDefined, (void)tolerance, (void)stopTimeDefined, (void)stopTime;
    return inst == NULL ? fmi2Error : status(set_start_time(inst, "fmi2SetupExperiment", startTime));
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    Instance *inst = begin(c);
    return inst == NULL ? fmi2Error : status(enter_initialization(inst));
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    Instance *inst = begin(c);
    return inst == NULL ? fmi2Error : status(exit_initialization(inst));
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
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    Instance *inst = begin(c);
    GetCache cache = {{0}, {0}, 0, 0};
    if (inst == NULL) return fmi2Error;
    if (!check_array(inst, "fmi2GetReal", vr, nvr, value)) return fmi2Error;
    refresh_outputs(inst);
    for (size_t i = 0; i < nvr; i++)
        if (!get_real(inst, "fmi2GetReal", (long)vr[i], &value[i], &cache)) unknown_ref(inst, "fmi2GetReal", vr[i], "Real");
    return status(inst->log.worst);
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi2Error;
    if (!check_array(inst, "fmi2GetInteger", vr, nvr, value)) return fmi2Error;
    refresh_outputs(inst);
    for (size_t i = 0; i < nvr; i++) {
        value[i] = 0;
        if ((long)vr[i] >= VR_INT0 && (long)vr[i] < VR_STATE0) value[i] = inst->v.yi[vr[i] - VR_INT0];
        else unknown_ref(inst, "fmi2GetInteger", vr[i], "Integer");
    }
    return status(inst->log.worst);
}

/* the types this FMU has no variable of (a get) */
static fmi2Status no_such_type(fmi2Component c, const char *what, const char *type, const fmi2ValueReference vr[],
                               size_t nvr, const void *value)
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi2Error;
    if (!check_array(inst, what, vr, nvr, value)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) unknown_ref(inst, what, vr[i], type);
    return status(inst->log.worst);
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    for (size_t i = 0; value != NULL && i < nvr; i++) value[i] = fmi2False;
    return no_such_type(c, "fmi2GetBoolean", "Boolean", vr, nvr, value);
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    for (size_t i = 0; value != NULL && i < nvr; i++) value[i] = "";
    return no_such_type(c, "fmi2GetString", "String", vr, nvr, value);
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    Instance *inst = begin(c);
    if (inst == NULL) return fmi2Error;
    if (!check_array(inst, "fmi2SetReal", vr, nvr, value)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++)
        if (!set_real(inst, "fmi2SetReal", (long)vr[i], value[i])) unknown_ref(inst, "fmi2SetReal", vr[i], "Real");
    return status(inst->log.worst);
}

static fmi2Status refuse_set(fmi2Component c, const char *what, const char *type, const fmi2ValueReference vr[],
                             size_t nvr, const void *value)
{
    Instance *inst = begin(c);
    char n[64];
    if (inst == NULL) return fmi2Error;
    if (!check_array(inst, what, vr, nvr, value)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        if (type[0] == 'I' && (long)vr[i] >= VR_INT0 && (long)vr[i] < VR_STATE0)
            say(inst, LOG_ERROR, "%s: value reference %u (%s) is an output; ignored", what, vr[i], var_name(vr[i], n));
        else
            unknown_ref(inst, what, vr[i], type);
    }
    return status(inst->log.worst);
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
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    Instance *inst = begin(c);
    return inst == NULL ? fmi2Error : status(get_state(inst, "fmi2GetFMUstate", state));
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    Instance *inst = begin(c);
    return inst == NULL ? fmi2Error : status(set_state(inst, "fmi2SetFMUstate", state));
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    Instance *inst = begin(c);
    return inst == NULL ? fmi2Error : status(free_state(inst, "fmi2FreeFMUstate", state));
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    Instance *inst = begin(c);
    return inst == NULL ? fmi2Error : status(state_size(inst, "fmi2SerializedFMUstateSize", state, size));
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size)
{
    Instance *inst = begin(c);
    return inst == NULL ? fmi2Error
                        : status(serialize(inst, "fmi2SerializeFMUstate", state, (unsigned char *)bytes, size));
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *state)
{
    Instance *inst = begin(c);
    return inst == NULL ? fmi2Error
                        : status(deserialize(inst, "fmi2DeSerializeFMUstate", (const unsigned char *)serializedState,
                                             size, state));
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
    return inst == NULL ? fmi2Error : status(do_step(inst, currentCommunicationPoint, communicationStepSize));
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
    int changed;
    if (inst == NULL || eventInfo == NULL) return fmi2Error;
    memset(eventInfo, 0, sizeof *eventInfo);
    fmi2Status s = status(event_update(inst, "fmi2NewDiscreteStates", &changed));
    eventInfo->valuesOfContinuousStatesChanged = changed ? fmi2True : fmi2False;
    return s;
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
    return inst == NULL ? fmi2Error : status(set_time(inst, "fmi2SetTime", time));
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx)
{
    Instance *inst = me_begin(c, "fmi2SetContinuousStates", IN_EVENT | IN_CONT);
    return inst == NULL ? fmi2Error : status(set_states(inst, "fmi2SetContinuousStates", x, nx));
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx)
{
    Instance *inst = me_begin(c, "fmi2GetDerivatives", IN_RUN);
    return inst == NULL ? fmi2Error : status(get_derivatives(inst, "fmi2GetDerivatives", derivatives, nx));
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni)
{
    Instance *inst = me_begin(c, "fmi2GetEventIndicators", IN_RUN);
    if (inst == NULL) return fmi2Error;
    if (ni == 0) return fmi2OK; /* (FMI 2.0 hosts ask for none when they use none) */
    return status(get_event_indicators(inst, "fmi2GetEventIndicators", eventIndicators, ni));
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx)
{
    Instance *inst = me_begin(c, "fmi2GetContinuousStates", IN_RUN);
    return inst == NULL ? fmi2Error : status(get_states(inst, "fmi2GetContinuousStates", x, nx, 0));
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx)
{
    Instance *inst = me_begin(c, "fmi2GetNominalsOfContinuousStates", IN_RUN);
    return inst == NULL ? fmi2Error : status(get_states(inst, "fmi2GetNominalsOfContinuousStates", x_nominal, nx, 1));
}
