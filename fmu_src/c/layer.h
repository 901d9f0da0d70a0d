/*
 * layer.h - what the FMI 2.0 and FMI 3.0 layers (fmi2_layer.c, fmi3_layer.c) share: the instance
 * and its values, the state machine, logging, the checks of inputs, parameters and steps, and the
 * bodies of the calls both standards have (instantiation, initialisation, a co-simulation step,
 * the variables of model.h, the model exchange evaluations, the FMU state and its serialisation).
 * As the Reference FMUs share cosimulation.c between their fmi2Functions.c and fmi3Functions.c:
 * no FMI type here. A layer maps its calls, types and statuses onto these functions; they return a
 * log level (LOG_INFO: done, LOG_WARNING, LOG_ERROR: refused, the culprit logged) or 1/0.
 *
 * The layer includes it once, after model.h and layer_config.h (the FMU's sizes and tables, read
 * at run time: no size here is a compile-time constant), having defined:
 *   LAYER_PREFIX  "fmi2" or "fmi3", the prefix of the function names in messages;
 *   LAYER_MAGIC   marks a live instance of this layer;
 *   LAYER_HOST    the instance's fields holding the host's callbacks;
 *   N_VR          the number of value references (at least VR_ME_END);
 * and defines after it host_log (hand a message to the host) and var_name (a reference's name).
 *
 * Value references: parameters, inputs, Real outputs, Integer outputs, the ModelExchange states
 * and their derivatives (VR_PAR0 ... VR_ME_END); a layer may declare more after them.
 */
#ifndef LATOBS_LAYER_H
#define LATOBS_LAYER_H

#include <stdint.h>

/* signed, so that a group of none (e.g. no parameters) compares without warnings */
#define VR_PAR0 0L
#define VR_IN0 (VR_PAR0 + N_PARAMETERS)
#define VR_OUT0 (VR_IN0 + N_INPUTS)
#define VR_INT0 (VR_OUT0 + N_OUTPUTS)
#define VR_STATE0 (VR_INT0 + N_INT_OUTPUTS)
#define VR_DER0 (VR_STATE0 + N_STATES)
#define VR_ME_END (VR_DER0 + N_STATES)

#define MSG_MAX 1024

typedef enum {
    PHASE_INSTANTIATED, /* after instantiation or reset */
    PHASE_INIT,         /* between entering and exiting initialisation mode */
    PHASE_STEP,         /* co-simulation: ready for a step */
    PHASE_EVENT,        /* model exchange: event mode */
    PHASE_CONTINUOUS,   /* model exchange: continuous-time mode */
    PHASE_TERMINATED,
    PHASE_FAILED        /* initialisation failed: only reset, terminate, free, get */
} Phase;

typedef enum { IF_ME, IF_CS } Interface;

struct Log {
    struct Instance *inst;
    int worst;   /* highest level logged during the current call */
    double time; /* s, the time of the model call in progress (layer_time) */
};

/* Everything a get-FMU-state copies; the model's bytes follow it in the state blob. */
typedef struct {
    Phase phase;
    int ready; /* model_setup succeeded: the model's state exists */
    double time;
    double p[LAYER_MAX_VARS]; /* the first N_PARAMETERS used; likewise below */
    double u[LAYER_MAX_VARS];
    double y[LAYER_MAX_VARS];
    int yi[LAYER_MAX_VARS];
} Values;

typedef struct Instance {
    unsigned magic;
    char name[256];
    Interface type;
    LAYER_HOST
    int logging_on;
    Values v;
    Log log;
    Model *model;
} Instance;

/* the layer's: hand one message (plain text) of `level` to the host; the name of reference r */
static void host_log(const Instance *inst, int level, const char *text);
static const char *var_name(long r, char buf[64]);

/* ------------------------------------------------------------------ logging */
static void emit(Instance *inst, int level, const char *text)
{
    if (level > inst->log.worst) inst->log.worst = level;
    if (level == LOG_INFO && !inst->logging_on) return;
    host_log(inst, level, text);
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

/* the instance of a call (NULL: not one of this layer's); its status is the worst level logged from here */
static Instance *begin(void *c)
{
    Instance *inst = (Instance *)c;
    if (inst == NULL || inst->magic != LAYER_MAGIC) return NULL;
    inst->log.worst = LOG_INFO;
    return inst;
}

/* ------------------------------------------------------------------ checks */
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
    char a[32], b[32], c[32], n[64];
    size_t len = 0;
    int nonfinite = 0;
    list[0] = '\0';
    for (int i = 0; i < N_INPUTS; i++) nonfinite |= !isfinite(u[i]);
    for (int i = 0; i < N_INPUTS; i++) {
        if (u[i] >= IN_MIN[i] && u[i] <= IN_MAX[i]) continue;
        if (nonfinite && isfinite(u[i])) continue;
        if (len + 160 > size) break;
        len += (size_t)snprintf(list + len, size - len, "%s%s = %s", len ? ", " : "", var_name(VR_IN0 + i, n),
                                py_repr(u[i], a));
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

static int require_type(Instance *inst, const char *what, Interface type)
{
    if (inst->type == type) return 1;
    say(inst, LOG_ERROR, "%s is a %s function; this instance is %s", what,
        type == IF_ME ? "ModelExchange" : "CoSimulation", inst->type == IF_ME ? "ModelExchange" : "CoSimulation");
    return 0;
}

static void unknown_ref(Instance *inst, const char *what, long r, const char *type)
{
    char n[64];
    if (r < N_VR)
        say(inst, LOG_ERROR, "%s: value reference %ld (%s) is not a%s %s variable", what, r, var_name(r, n),
            type[0] == 'I' ? "n" : "", type);
    else
        say(inst, LOG_ERROR, "%s: value reference %ld is not a variable of %s (references 0..%u)", what, r,
            MODEL_IDENTIFIER, (unsigned)N_VR - 1u);
}

static int check_array(Instance *inst, const char *what, const void *vr, size_t nvr, const void *value)
{
    if (nvr > 0 && (vr == NULL || value == NULL)) {
        say(inst, LOG_ERROR, "%s: NULL array for %zu value references", what, nvr);
        return 0;
    }
    return 1;
}

/* ------------------------------------------------------------------ instance */
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

/* a new instance like `probe` (its name and host fields set; the messages go through it), of
 * interface `type`, if `token` is this FMU's (`token_kind`: what the standard calls it); else NULL */
static Instance *instantiate(Instance *probe, const char *what, const char *token_kind, const char *token,
                             Interface type, int logging_on)
{
    probe->magic = LAYER_MAGIC;
    if (probe->name[0] == '\0') {
        snprintf(probe->name, sizeof probe->name, "?");
        say(probe, LOG_ERROR, "%s: missing instance name", what);
        return NULL;
    }
    if (token == NULL || strcmp(token, INSTANTIATION_TOKEN) != 0) {
        say(probe, LOG_ERROR, "%s: %s %s is not this FMU's (%s): refusing another FMU's model description", what,
            token_kind, token ? token : "(NULL)", INSTANTIATION_TOKEN);
        return NULL;
    }
    if (type == IF_ME && N_STATES == 0) {
        say(probe, LOG_ERROR, "%s: %s has no ModelExchange interface (co-simulation only)", what, MODEL_IDENTIFIER);
        return NULL;
    }
    Instance *inst = (Instance *)calloc(1, sizeof(Instance));
    Model *model = (Model *)calloc(1, model_size());
    if (inst == NULL || model == NULL) {
        free(inst);
        free(model);
        say(probe, LOG_ERROR, "%s: out of memory", what);
        return NULL;
    }
    *inst = *probe;
    inst->type = type;
    inst->logging_on = logging_on;
    inst->model = model;
    inst->log.inst = inst;
    reset_values(inst);
    return inst;
}

static void free_instance(void *c)
{
    Instance *inst = begin(c);
    if (inst == NULL) return;
    inst->magic = 0;
    free(inst->model);
    free(inst);
}

/* the start time, before initialisation mode */
static int set_start_time(Instance *inst, const char *what, double t)
{
    if (!require(inst, what, inst->v.phase == PHASE_INSTANTIATED)) return LOG_ERROR;
    if (!isfinite(t)) {
        say(inst, LOG_ERROR, "%s: start time %g is not finite", what, t);
        return LOG_ERROR;
    }
    inst->v.time = t;
    return LOG_INFO;
}

static int enter_initialization(Instance *inst)
{
    if (!require(inst, LAYER_PREFIX "EnterInitializationMode", inst->v.phase == PHASE_INSTANTIATED)) return LOG_ERROR;
    inst->v.phase = PHASE_INIT;
    return LOG_INFO;
}

/* the parameters checked, the model set up and initialised from the inputs, the outputs computed */
static int exit_initialization(Instance *inst)
{
    char n[64], list[MSG_MAX / 2];
    if (!require(inst, LAYER_PREFIX "ExitInitializationMode", inst->v.phase == PHASE_INIT)) return LOG_ERROR;
    for (int i = 0; i < N_PARAMETERS; i++) {
        double x = inst->v.p[i];
        if (!isfinite(x) || x < PAR_MIN[i] || x > PAR_MAX[i]) {
            say(inst, LOG_ERROR, "parameter %s = %g is outside its declared range [%g, %g]", var_name(VR_PAR0 + i, n),
                x, PAR_MIN[i], PAR_MAX[i]);
            inst->v.phase = PHASE_FAILED;
            return LOG_ERROR;
        }
    }
    inst->log.time = inst->v.time;
    if (model_setup(inst->model, inst->v.p, &inst->log) != 0) {
        say(inst, LOG_ERROR, "initialisation failed: the model refused its parameters");
        inst->v.phase = PHASE_FAILED;
        return LOG_ERROR;
    }
    inst->v.ready = 1;
    if (inputs_valid(inst->v.u))
        model_initialize(inst->model, inst->v.u, &inst->log);
    else if (bad_inputs(inst->v.u, list, sizeof list))
        say(inst, LOG_WARNING, "non-finite inputs at initialisation: the model starts from the first step");
    else
        say(inst, LOG_WARNING, "input(s) outside the declared range at initialisation: %s; the model starts from "
            "the first step", list);
    model_outputs(inst->model, inst->v.y, inst->v.yi);
    inst->v.phase = inst->type == IF_CS ? PHASE_STEP : PHASE_EVENT;
    return inst->log.worst;
}

/* ------------------------------------------------------------------ variables */
/* the model exchange outputs are functions of the states and inputs: refresh before a get */
static void refresh_outputs(Instance *inst)
{
    if (inst->type == IF_ME && (inst->v.phase == PHASE_EVENT || inst->v.phase == PHASE_CONTINUOUS) &&
        inputs_valid(inst->v.u)) /* (a ModelExchange instance has states) */
        model_me_outputs(inst->model, inst->v.u, inst->v.y, inst->v.yi);
}

typedef struct { /* the model exchange values of one get call, computed once */
    double x[LAYER_MAX_STATES], dx[LAYER_MAX_STATES];
    int have_x, have_dx;
} GetCache;

/* the Real variable r of model.h (a parameter, input, output, state or derivative) into *out:
 * 1, or 0 when r is none of them (an error logged when a derivative cannot be evaluated) */
static int get_real(Instance *inst, const char *what, long r, double *out, GetCache *cache)
{
    char n[64];
    *out = 0.0;
    if (r < VR_IN0) *out = inst->v.p[r - VR_PAR0];
    else if (r < VR_OUT0) *out = inst->v.u[r - VR_IN0];
    else if (r < VR_INT0) *out = inst->v.y[r - VR_OUT0];
    else if (r >= VR_STATE0 && r < VR_ME_END && !inst->v.ready) {
        *out = 0.0; /* not set up yet: the states are computed when initialisation mode is left */
    } else if (r >= VR_STATE0 && r < VR_DER0) {
        if (!cache->have_x) model_me_get_states(inst->model, cache->x), cache->have_x = 1;
        *out = cache->x[r - VR_STATE0];
    } else if (r >= VR_DER0 && r < VR_ME_END) {
        if (!cache->have_dx) {
            if (!inputs_valid(inst->v.u)) {
                say(inst, LOG_ERROR, "%s: derivative %s needs inputs inside their declared range", what,
                    var_name(r, n));
                return 1;
            }
            model_me_derivatives(inst->model, inst->v.u, cache->dx), cache->have_dx = 1;
        }
        *out = cache->dx[r - VR_DER0];
    } else return 0;
    return 1;
}

/* the Real variable r of model.h set: an input (checked where it is used), a parameter before
 * initialisation (after: ignored with a warning); any other of them refused. 0: r is none of them */
static int set_real(Instance *inst, const char *what, long r, double value)
{
    char n[64];
    if (r >= VR_IN0 && r < VR_OUT0) {
        inst->v.u[r - VR_IN0] = value; /* checked (finite, in range) where it is used */
    } else if (r < VR_IN0) {
        if (inst->v.phase == PHASE_INSTANTIATED || inst->v.phase == PHASE_INIT) inst->v.p[r - VR_PAR0] = value;
        else say(inst, LOG_WARNING, "parameter %s set after initialisation: ignored", var_name(r, n));
    } else if (r < VR_INT0 || (r >= VR_STATE0 && r < VR_ME_END)) {
        say(inst, LOG_ERROR, "%s: value reference %ld (%s) is not an input or a parameter; ignored", what, r,
            var_name(r, n));
    } else {
        return 0;
    }
    return 1;
}

/* ------------------------------------------------------------------ co-simulation */
static int do_step(Instance *inst, double t, double h)
{
    if (!require_type(inst, LAYER_PREFIX "DoStep", IF_CS)) return LOG_ERROR;
    if (inst->v.phase != PHASE_STEP) {
        say(inst, LOG_ERROR, "step refused at t = %g: " LAYER_PREFIX "DoStep called in %s (call " LAYER_PREFIX
            "ExitInitializationMode first%s)", t, phase_name(inst->v.phase),
            inst->v.phase == PHASE_FAILED ? "; initialisation failed, see the earlier error" : "");
        return LOG_ERROR;
    }
    if (!isfinite(t)) { /* (the instance's time, so its state, stays finite) */
        say(inst, LOG_ERROR, "step refused: communication point %g is not finite; state held", t);
        return LOG_ERROR;
    }
    if (!(h > 0.0) || !isfinite(h)) {
        say(inst, LOG_ERROR, "step refused: communication step %g must be finite and > 0 s", h);
        return LOG_ERROR;
    }
    if (h > MAX_STEP_REFUSED_ABOVE) {
        char ts[32], hs[32], ms[32];
        say(inst, LOG_ERROR, "step refused at t = %s: communication step %s s exceeds this FMU's longest step %s s "
            "(declared in its model description); state held", py_repr(t, ts), py_repr(h, hs), py_repr(MAX_STEP, ms));
        return LOG_ERROR;
    }
    if (!inputs_ok(inst, "step")) return LOG_ERROR;
    inst->log.time = t;
    if (model_do_step(inst->model, h, inst->v.u, &inst->log) == 0) {
        inst->v.time = t + h;
        model_outputs(inst->model, inst->v.y, inst->v.yi);
    } else if (inst->log.worst < LOG_ERROR) {
        say(inst, LOG_ERROR, "step refused at t = %g by the model", t);
    }
    return inst->log.worst;
}

/* ------------------------------------------------------------------ model exchange */
#define IN_EVENT (1 << PHASE_EVENT)
#define IN_CONT (1 << PHASE_CONTINUOUS)
#define IN_INIT ((1 << PHASE_INSTANTIATED) | (1 << PHASE_INIT))
#define IN_RUN (IN_EVENT | IN_CONT | (1 << PHASE_TERMINATED)) /* the model is set up */

/* the instance of a model exchange call allowed in `phases`, else NULL (the refusal logged) */
static Instance *me_begin(void *c, const char *what, int phases)
{
    Instance *inst = begin(c);
    if (inst == NULL) return NULL;
    if (!require_type(inst, what, IF_ME)) return NULL;
    if (!require(inst, what, (phases >> inst->v.phase) & 1)) return NULL;
    if (phases == IN_RUN && !inst->v.ready) {
        say(inst, LOG_ERROR, "%s: the model was never initialised (" LAYER_PREFIX "ExitInitializationMode failed or "
            "was not called)", what);
        return NULL;
    }
    return inst;
}

static int count_ok(Instance *inst, const char *what, const void *array, size_t n, size_t expected)
{
    if (array == NULL || n != expected) {
        say(inst, LOG_ERROR, "%s: %zu values (array %s) given, this FMU has %zu", what, n, array ? "set" : "NULL",
            expected);
        return 0;
    }
    return 1;
}

/* an event: the model's discrete update; *changed: the continuous states changed */
static int event_update(Instance *inst, const char *what, int *changed)
{
    *changed = 0;
    if (N_STATES == 0) return inst->log.worst;
    if (!inputs_ok(inst, what)) return LOG_ERROR;
    *changed = model_me_event_update(inst->model, inst->v.time, inst->v.u, &inst->log) != 0;
    return inst->log.worst;
}

static int set_time(Instance *inst, const char *what, double t)
{
    if (!isfinite(t)) {
        say(inst, LOG_ERROR, "%s: time %g is not finite", what, t);
        return LOG_ERROR;
    }
    inst->v.time = t;
    return LOG_INFO;
}

static int set_states(Instance *inst, const char *what, const double *x, size_t nx)
{
    if (!count_ok(inst, what, x, nx, N_STATES)) return LOG_ERROR;
    if (N_STATES == 0) return LOG_INFO;
    if (!all_finite(x, N_STATES)) {
        say(inst, LOG_ERROR, "%s: non-finite state refused", what);
        return LOG_ERROR;
    }
    model_me_set_states(inst->model, x);
    return LOG_INFO;
}

static int get_derivatives(Instance *inst, const char *what, double *dx, size_t nx)
{
    if (!count_ok(inst, what, dx, nx, N_STATES)) return LOG_ERROR;
    if (N_STATES == 0) return inst->log.worst;
    if (!inputs_ok(inst, what)) return LOG_ERROR;
    model_me_derivatives(inst->model, inst->v.u, dx);
    return inst->log.worst;
}

static int get_event_indicators(Instance *inst, const char *what, double *z, size_t ni)
{
    if (!count_ok(inst, what, z, ni, N_EVENT_INDICATORS)) return LOG_ERROR;
    if (N_STATES == 0 || N_EVENT_INDICATORS == 0) return inst->log.worst;
    if (!inputs_ok(inst, what)) return LOG_ERROR;
    model_me_event_indicators(inst->model, inst->v.u, z);
    return inst->log.worst;
}

static int get_states(Instance *inst, const char *what, double *x, size_t nx, int nominals)
{
    if (!count_ok(inst, what, x, nx, N_STATES)) return LOG_ERROR;
    if (N_STATES == 0) return LOG_INFO;
    if (nominals) model_me_nominals(inst->model, x);
    else model_me_get_states(inst->model, x);
    return LOG_INFO;
}

/* ------------------------------------------------------------------ FMU state */
/* A state, in memory (get_state) and serialised (the same bytes): StateHeader, Values, then the
 * model's model_size() bytes. The header's first 24 bytes are fixed for every format: STATE_MAGIC,
 * the hash of the FMU's instantiation token, the state's size. A state handed to a call is read
 * in that order, and no further than what was checked: its first 8 bytes (the magic), then the
 * header (every latobs state has one), then, once its token, layer, layout and size are this
 * FMU's, the whole state (its checksum, then its values). So another latobs FMU's state, one of
 * another FMI version or platform, a truncated, extended or corrupted one is refused before a byte
 * past its end is read. (A pointer to memory that is not a state at all can only be read: a C
 * function cannot tell a block's size. Such a pointer is read for 8 bytes, which must be readable:
 * docs/using-fmus.md.) The checksum: FNV-1a 64 over 8-byte words, each step folding its high half into
 * its low one (mix; hash_lanes beyond the header): any change of one word, so any one-bit flip,
 * changes it. */
#define STATE_FORMAT 1u
static const unsigned char STATE_MAGIC[8] = {'l', 'a', 't', 'o', 'b', 's', 'S', 't'};
#define FNV_OFFSET 0xcbf29ce484222325ull
#define FNV_PRIME 0x100000001b3ull

typedef struct {
    unsigned char magic[8]; /* STATE_MAGIC */
    uint64_t token_hash;    /* FNV-1a 64 of the FMU's instantiation token (guid) */
    uint64_t size;          /* bytes of the whole state: header, Values, model */
    uint32_t format;        /* STATE_FORMAT */
    uint32_t layer;         /* LAYER_MAGIC: the FMI version of the layer that made it */
    uint32_t layout;        /* the platform's data layout (state_layout) */
    uint32_t type;          /* the instance's interface (Interface) */
    uint64_t checksum;      /* state_checksum of the whole state, this field taken as 0 */
    char model[64];         /* the model identifier (for messages only) */
} StateHeader;

/* C99 compile-time checks: no padding in the header; the values and the model stay 16-byte aligned */
typedef char state_header_size[(sizeof(StateHeader) == 112 && sizeof(Values) % 16 == 0) ? 1 : -1];

static uint64_t word_at(const unsigned char *p)
{
    uint64_t w;
    memcpy(&w, p, 8);
    return w;
}

/* one step of the checksum: FNV-1a's on a whole word, then the high half folded into the low one.
 * (FNV's multiplication carries only upwards: without the fold, a change of a word's top byte
 * stayed in the hash's top byte, and two such changes cancelled once in 256; the fuzz found one.)
 * A bijection of h and of w: a change of one word always changes the result. */
static uint64_t mix(uint64_t h, uint64_t w)
{
    h = (h ^ w) * FNV_PRIME;
    return h ^ h >> 32;
}

static uint64_t hash_words(uint64_t h, const unsigned char *p, size_t n)
{
    size_t i = 0;
    for (; i + 8 <= n; i += 8) h = mix(h, word_at(p + i));
    for (; i < n; i++) h = mix(h, p[i]);
    return h;
}

/* hash_words in four interleaved lanes (word k into lane k % 4), the lanes then hashed into h: the
 * lanes' multiplications overlap (137 KB in ~12 us, ~4x faster than one chain) */
static uint64_t hash_lanes(uint64_t h, const unsigned char *p, size_t n)
{
    uint64_t a = h, b = h ^ 1u, c = h ^ 2u, d = h ^ 3u; /* (scalars: gcc vectorises an array of lanes badly) */
    size_t i = 0;
    for (; i + 32 <= n; i += 32) {
        a = mix(a, word_at(p + i));
        b = mix(b, word_at(p + i + 8));
        c = mix(c, word_at(p + i + 16));
        d = mix(d, word_at(p + i + 24));
    }
    return hash_words(mix(mix(mix(mix(h, a), b), c), d), p + i, n - i);
}

static uint64_t token_hash(void)
{
    uint64_t h = FNV_OFFSET;
    for (const unsigned char *s = (const unsigned char *)INSTANTIATION_TOKEN; *s; s++) h = (h ^ *s) * FNV_PRIME;
    return h;
}

/* pointer and long sizes, a double's alignment and the byte order: what the state's bytes depend on */
static uint32_t state_layout(void)
{
    struct probe { char c; double d; };
    const uint16_t one = 1;
    unsigned char little;
    memcpy(&little, &one, 1);
    return (uint32_t)(sizeof(void *) | sizeof(long) << 8 | offsetof(struct probe, d) << 16 | (uint32_t)little << 24);
}

static size_t state_bytes(void)
{
    return sizeof(StateHeader) + sizeof(Values) + model_size();
}

/* the checksum of a state of `size` bytes whose header is `head` */
static uint64_t state_checksum(const StateHeader *head, const unsigned char *state, size_t size)
{
    StateHeader h = *head;
    h.checksum = 0;
    return hash_lanes(hash_words(FNV_OFFSET, (const unsigned char *)&h, sizeof h), state + sizeof h, size - sizeof h);
}

/* the values of a state this FMU could have made: a known phase of the state's interface, set up
 * exactly in the phases that need it, a finite time, the parameters in range once set up. Else 0,
 * the first value that is not in `why` */
static int values_possible(const Values *v, Interface type, char *why, size_t n)
{
    char a[32], nm[64];
    const int run = v->phase == PHASE_STEP || v->phase == PHASE_EVENT || v->phase == PHASE_CONTINUOUS;
    const int before = v->phase == PHASE_INSTANTIATED || v->phase == PHASE_INIT || v->phase == PHASE_FAILED;
    if ((unsigned)v->phase > (unsigned)PHASE_FAILED)
        snprintf(why, n, "phase %d (none)", (int)v->phase);
    else if (type == IF_CS ? v->phase == PHASE_EVENT || v->phase == PHASE_CONTINUOUS : v->phase == PHASE_STEP)
        snprintf(why, n, "%s in a %s state", phase_name(v->phase), type == IF_ME ? "ModelExchange" : "CoSimulation");
    else if ((v->ready != 0 && v->ready != 1) || (run && !v->ready) || (before && v->ready))
        snprintf(why, n, "%s with ready = %d", phase_name(v->phase), v->ready);
    else if (!isfinite(v->time))
        snprintf(why, n, "time = %s", py_repr(v->time, a));
    else {
        for (int i = 0; v->ready && i < N_PARAMETERS; i++)
            if (!(v->p[i] >= PAR_MIN[i] && v->p[i] <= PAR_MAX[i])) {
                snprintf(why, n, "parameter %s = %s outside its declared range", var_name(VR_PAR0 + i, nm),
                         py_repr(v->p[i], a));
                return 0;
            }
        return 1;
    }
    return 0;
}

#define IN_MEMORY ((size_t)-1) /* the byte count of a state given by pointer: unknown */

/* whether `state` (`avail` bytes, or IN_MEMORY: its size unknown) is a state
 * of this FMU, made by this layer on this platform, of `avail` bytes if known; with `whole`, also
 * its checksum and values, and of this instance's interface. Else an error logged, 0 */
static int check_state(Instance *inst, const char *what, const unsigned char *state, size_t avail, int whole)
{
    const size_t need = state_bytes();
    const int in_memory = avail == IN_MEMORY;
    StateHeader h;
    char why[320], other[sizeof h.model];
    if (state == NULL) {
        say(inst, LOG_ERROR, "%s: NULL state", what);
        return 0;
    }
    if (!in_memory && avail < sizeof STATE_MAGIC) {
        say(inst, LOG_ERROR, "%s: serialised state refused: %zu bytes, a state of %s has %zu; the instance's state "
            "is kept", what, avail, MODEL_IDENTIFIER, need);
        return 0;
    }
    if (memcmp(state, STATE_MAGIC, sizeof STATE_MAGIC) != 0) {
        say(inst, LOG_ERROR, "%s: %s refused: it is not a state of a latobs FMU (%s); the instance's state is kept",
            what, in_memory ? "state" : "serialised state",
            in_memory ? "a pointer this FMU never handed out, or one freed since" : "no latobs state header");
        return 0;
    }
    if (!in_memory && avail < sizeof h) {
        say(inst, LOG_ERROR, "%s: serialised state refused: it is truncated (%zu bytes, %zu expected); the "
            "instance's state is kept", what, avail, need);
        return 0;
    }
    memcpy(&h, state, sizeof h);
    for (size_t i = 0; i < sizeof other; i++) { /* the other model's name, printable */
        unsigned char c = (unsigned char)h.model[i];
        other[i] = c == 0 || i + 1 == sizeof other ? '\0' : c < 0x20 || c > 0x7e ? '?' : (char)c;
        if (other[i] == '\0') break;
    }
    const int same_model = strcmp(other, MODEL_IDENTIFIER) == 0;
    if (h.format != STATE_FORMAT)
        snprintf(why, sizeof why, "it is of format %u (another latobs version), this FMU reads format %u",
                 (unsigned)h.format, STATE_FORMAT);
    else if (same_model && h.layer != LAYER_MAGIC)
        snprintf(why, sizeof why, "it is a state of %s's FMI %s FMU, this is its FMI %s FMU", other,
                 LAYER_PREFIX[3] == '2' ? "3.0" : "2.0", LAYER_PREFIX[3] == '2' ? "2.0" : "3.0");
    else if (same_model && h.token_hash != token_hash())
        snprintf(why, sizeof why, "it is a state of another build of %s (another design, vehicle or latobs "
                 "version: another instantiation token)", other);
    else if (h.token_hash != token_hash() || h.layer != LAYER_MAGIC)
        snprintf(why, sizeof why, "it is a state of another FMU, %s (%llu bytes), not of this %s (%zu bytes)", other,
                 (unsigned long long)h.size, MODEL_IDENTIFIER, need);
    else if (h.layout != state_layout())
        snprintf(why, sizeof why, "it was saved on another platform (data layout %08x, here %08x)",
                 (unsigned)h.layout, (unsigned)state_layout());
    else if (h.size != need)
        snprintf(why, sizeof why, "its header gives %llu bytes, this FMU's states have %zu",
                 (unsigned long long)h.size, need);
    else if (!in_memory && avail != need)
        snprintf(why, sizeof why, "it is %s (%zu bytes, %zu expected)", avail < need ? "truncated" : "extended", avail,
                 need);
    else if (!whole)
        return 1;
    else if ((Interface)h.type != inst->type)
        snprintf(why, sizeof why, "it is a state of a %s instance, this one is %s",
                 h.type == IF_ME ? "ModelExchange" : "CoSimulation", inst->type == IF_ME ? "ModelExchange" : "CoSimulation");
    else if (state_checksum(&h, state, need) != h.checksum)
        snprintf(why, sizeof why, "it is corrupted (its checksum does not match its %zu bytes)", need);
    else {
        Values v;
        char value[96];
        memcpy(&v, state + sizeof h, sizeof v);
        if (values_possible(&v, inst->type, value, sizeof value)) return 1;
        snprintf(why, sizeof why, "it holds what this FMU never holds: %s", value);
    }
    say(inst, LOG_ERROR, "%s: %s refused: %s; the instance's state is kept", what,
        in_memory ? "state" : "serialised state", why);
    return 0;
}

static int get_state(Instance *inst, const char *what, void **state)
{
    if (state == NULL) {
        say(inst, LOG_ERROR, "%s: NULL state pointer", what);
        return LOG_ERROR;
    }
    /* a state given to be overwritten must be one of this FMU's (FMI: one it returned before) */
    if (*state != NULL && !check_state(inst, what, (const unsigned char *)*state, IN_MEMORY, 0)) return LOG_ERROR;
    unsigned char *blob = (unsigned char *)(*state != NULL ? *state : malloc(state_bytes()));
    if (blob == NULL) {
        say(inst, LOG_ERROR, "%s: out of memory", what);
        return LOG_ERROR;
    }
    StateHeader h;
    memset(&h, 0, sizeof h);
    memcpy(h.magic, STATE_MAGIC, sizeof h.magic);
    h.token_hash = token_hash();
    h.size = state_bytes();
    h.format = STATE_FORMAT;
    h.layer = LAYER_MAGIC;
    h.layout = state_layout();
    h.type = (uint32_t)inst->type;
    snprintf(h.model, sizeof h.model, "%s", MODEL_IDENTIFIER);
    memcpy(blob + sizeof h, &inst->v, sizeof inst->v);
    memcpy(blob + sizeof h + sizeof inst->v, inst->model, model_size());
    h.checksum = state_checksum(&h, blob, state_bytes());
    memcpy(blob, &h, sizeof h);
    *state = blob;
    return LOG_INFO;
}

static int set_state(Instance *inst, const char *what, const void *state)
{
    const unsigned char *blob = (const unsigned char *)state;
    if (!check_state(inst, what, blob, IN_MEMORY, 1)) return LOG_ERROR;
    memcpy(&inst->v, blob + sizeof(StateHeader), sizeof inst->v);
    memcpy(inst->model, blob + sizeof(StateHeader) + sizeof inst->v, model_size());
    return LOG_INFO;
}

/* a state of this FMU freed (its header wiped first: a later use of it is refused, not trusted);
 * another FMU's is refused, not freed */
static int free_state(Instance *inst, const char *what, void **state)
{
    if (state == NULL || *state == NULL) return LOG_INFO; /* FMI: ignored */
    if (!check_state(inst, what, (const unsigned char *)*state, IN_MEMORY, 0)) return LOG_ERROR;
    memset(*state, 0, sizeof(StateHeader));
    free(*state);
    *state = NULL;
    return LOG_INFO;
}

static int state_size(Instance *inst, const char *what, const void *state, size_t *size)
{
    if (!check_state(inst, what, (const unsigned char *)state, IN_MEMORY, 1)) return LOG_ERROR;
    if (size == NULL) {
        say(inst, LOG_ERROR, "%s: NULL size pointer", what);
        return LOG_ERROR;
    }
    *size = state_bytes();
    return LOG_INFO;
}

/* serialised: the state's bytes as they are in memory (header, values, model) */
static int serialize(Instance *inst, const char *what, const void *state, unsigned char *bytes, size_t size)
{
    if (!check_state(inst, what, (const unsigned char *)state, IN_MEMORY, 1)) return LOG_ERROR;
    if (bytes == NULL || size < state_bytes()) {
        say(inst, LOG_ERROR, "%s: buffer of %zu bytes, %zu needed", what, bytes ? size : 0, state_bytes());
        return LOG_ERROR;
    }
    memcpy(bytes, state, state_bytes());
    return LOG_INFO;
}

/* a new state (or *state, one of this FMU's, overwritten) from serialised bytes checked whole */
static int deserialize(Instance *inst, const char *what, const unsigned char *bytes, size_t size, void **state)
{
    if (state == NULL) {
        say(inst, LOG_ERROR, "%s: NULL state pointer", what);
        return LOG_ERROR;
    }
    if (!check_state(inst, what, bytes, bytes ? size : 0, 1)) return LOG_ERROR;
    if (*state != NULL && !check_state(inst, what, (const unsigned char *)*state, IN_MEMORY, 0)) return LOG_ERROR;
    void *blob = *state != NULL ? *state : malloc(state_bytes());
    if (blob == NULL) {
        say(inst, LOG_ERROR, "%s: out of memory", what);
        return LOG_ERROR;
    }
    memcpy(blob, bytes, state_bytes());
    *state = blob;
    return LOG_INFO;
}

#endif
