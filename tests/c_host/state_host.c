/*
 * state_host.c - a plain C host for tests/cbackend/test_fmu_state.py: the FMU state functions of
 * native latobs FMUs (FMI 2.0 and 3.0) fed states of other FMUs and damaged serialisations.
 *
 * usage: state_host ITERATIONS SECONDS SEED FMU...
 *   each FMU is 8 arguments: VERSION (2 or 3) LIBRARY ID TOKEN IN_VRS IN_STARTS OUT_VRS INT_VRS
 *   (comma-separated lists; "-" for none). Every FMU is instantiated twice (a main instance and
 *   its untouched twin), initialised and stepped (5 ms, inputs near their starts) alike; the twin
 *   never sees a state call. Checks, each an "ok"/"FAIL" line:
 *   - for every ordered pair (X, Y) of different FMUs: X's state into Y's SetFMUState,
 *     GetFMUState (as the state to reuse), FreeFMUState, SerializedFMUStateSize and
 *     SerializeFMUState, and X's serialised bytes into Y's DeserializeFMUState: each refused
 *     (status >= error), X's state intact (X restores it), Y's outputs bit-identical to its twin's;
 *   - for every FMU, its own serialised state truncated (several lengths), extended, its second
 *     half 0xFF, a one-bit flip at every header bit and at random payload bits, random mutations
 *     (a few bytes, a block, the top bytes of two words, another length, all bytes; up to
 *     ITERATIONS of them, or SECONDS): each refused;
 *     its in-memory state with a bit flipped: SetFMUState refused; 64 random bytes given as a
 *     state: refused, untouched; the intact ones accepted (also into a block of their own);
 *   - after all that, each main instance and its twin stepped on: bit-identical outputs.
 * "msg CHECK: TEXT" lines give the message logged by a refusal (for the test to read).
 * Exits 0 only if every check passed. Built by the test with the system C compiler, plain (the
 * shipped binaries, under valgrind) or with -fsanitize=address (the FMUs' shipped sources too).
 */
#include <dlfcn.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2Functions.h"
#include "fmi3Functions.h"

#define MAX_FMUS 6
#define MAX_VRS 64
#define STEP 0.005
#define KEEP 1024 /* bytes of a state compared before and after another FMU's calls */

static int failures;
static char last_error[2048];

/* one check's line, "ok" or "FAIL" (counted) */
static void check(int ok, const char *fmt, ...)
{
    va_list ap;
    if (!ok) failures++;
    printf(ok ? "ok   " : "FAIL ");
    va_start(ap, fmt);
    vprintf(fmt, ap);
    va_end(ap);
    printf("\n");
    fflush(stdout);
}

/* ------------------------------------------------------------------ the FMUs */
typedef struct {
    int version;
    const char *id, *token;
    void *lib;
    void *main, *twin;
    double t;
    unsigned in[MAX_VRS], out[MAX_VRS], ints[MAX_VRS];
    double start[MAX_VRS];
    size_t n_in, n_out, n_int;
    /* FMI 2.0 */
    fmi2InstantiateTYPE *i2;
    fmi2SetupExperimentTYPE *setup2;
    fmi2EnterInitializationModeTYPE *enter2;
    fmi2ExitInitializationModeTYPE *exit2;
    fmi2DoStepTYPE *step2;
    fmi2SetRealTYPE *setr2;
    fmi2GetRealTYPE *getr2;
    fmi2GetIntegerTYPE *geti2;
    fmi2FreeInstanceTYPE *freei2;
    /* FMI 3.0 */
    fmi3InstantiateCoSimulationTYPE *i3;
    fmi3EnterInitializationModeTYPE *enter3;
    fmi3ExitInitializationModeTYPE *exit3;
    fmi3DoStepTYPE *step3;
    fmi3SetFloat64TYPE *setr3;
    fmi3GetFloat64TYPE *getr3;
    fmi3GetInt32TYPE *geti3;
    fmi3FreeInstanceTYPE *freei3;
    /* the state functions: the two versions' signatures are the same (states are void *) */
    int (*get)(void *, void **);
    int (*set)(void *, void *);
    int (*freest)(void *, void **);
    int (*size)(void *, void *, size_t *);
    int (*ser)(void *, void *, unsigned char *, size_t);
    int (*deser)(void *, const unsigned char *, size_t, void **);
} Fmu;

static Fmu fmus[MAX_FMUS];
static int n_fmus;

static void logger2(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                    fmi2String message, ...)
{
    va_list ap;
    (void)env, (void)instance, (void)category;
    if (status < fmi2Error) return;
    va_start(ap, message);
    vsnprintf(last_error, sizeof last_error, message, ap);
    va_end(ap);
}

static void logger3(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env, (void)category;
    if (status >= fmi3Error) snprintf(last_error, sizeof last_error, "%s", message);
}

static fmi2CallbackFunctions callbacks = {logger2, calloc, free, NULL, NULL};

static void *sym(Fmu *f, const char *name)
{
    char full[128];
    snprintf(full, sizeof full, "fmi%d%s", f->version, name);
    void *p = dlsym(f->lib, full);
    if (p == NULL) {
        fprintf(stderr, "state_host: %s: no %s\n", f->id, full);
        exit(2);
    }
    return p;
}

static size_t parse_list(const char *text, unsigned *vr, double *x)
{
    size_t n = 0;
    if (strcmp(text, "-") == 0) return 0;
    for (const char *s = text; *s && n < MAX_VRS; n++) {
        char *end;
        if (vr) vr[n] = (unsigned)strtoul(s, &end, 10);
        else x[n] = strtod(s, &end);
        s = *end == ',' ? end + 1 : end;
    }
    return n;
}

static void *instantiate(Fmu *f, const char *name)
{
    void *c;
    if (f->version == 2) {
        c = f->i2(name, fmi2CoSimulation, f->token, "", &callbacks, fmi2False, fmi2False);
        if (c && (f->setup2(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) > fmi2Warning ||
                  f->enter2(c) > fmi2Warning || f->exit2(c) > fmi2Warning))
            c = NULL;
    } else {
        c = f->i3(name, f->token, NULL, fmi3False, fmi3False, fmi3False, fmi3False, NULL, 0, NULL, logger3, NULL);
        if (c && (f->enter3(c, fmi3False, 0.0, 0.0, fmi3False, 0.0) > fmi3Warning || f->exit3(c) > fmi3Warning))
            c = NULL;
    }
    if (c == NULL) {
        fprintf(stderr, "state_host: %s (FMI %d) does not start: %s\n", f->id, f->version, last_error);
        exit(2);
    }
    return c;
}

static void load(Fmu *f, char **arg)
{
    f->version = atoi(arg[0]);
    f->lib = dlopen(arg[1], RTLD_NOW | RTLD_LOCAL);
    if (f->lib == NULL) {
        fprintf(stderr, "state_host: %s\n", dlerror());
        exit(2);
    }
    f->id = arg[2];
    f->token = arg[3];
    f->n_in = parse_list(arg[4], f->in, NULL);
    parse_list(arg[5], NULL, f->start);
    f->n_out = parse_list(arg[6], f->out, NULL);
    f->n_int = parse_list(arg[7], f->ints, NULL);
    if (f->version == 2) {
        *(void **)&f->i2 = sym(f, "Instantiate");
        *(void **)&f->setup2 = sym(f, "SetupExperiment");
        *(void **)&f->enter2 = sym(f, "EnterInitializationMode");
        *(void **)&f->exit2 = sym(f, "ExitInitializationMode");
        *(void **)&f->step2 = sym(f, "DoStep");
        *(void **)&f->setr2 = sym(f, "SetReal");
        *(void **)&f->getr2 = sym(f, "GetReal");
        *(void **)&f->geti2 = sym(f, "GetInteger");
        *(void **)&f->freei2 = sym(f, "FreeInstance");
        *(void **)&f->get = sym(f, "GetFMUstate");
        *(void **)&f->set = sym(f, "SetFMUstate");
        *(void **)&f->freest = sym(f, "FreeFMUstate");
        *(void **)&f->size = sym(f, "SerializedFMUstateSize");
        *(void **)&f->ser = sym(f, "SerializeFMUstate");
        *(void **)&f->deser = sym(f, "DeSerializeFMUstate");
    } else {
        *(void **)&f->i3 = sym(f, "InstantiateCoSimulation");
        *(void **)&f->enter3 = sym(f, "EnterInitializationMode");
        *(void **)&f->exit3 = sym(f, "ExitInitializationMode");
        *(void **)&f->step3 = sym(f, "DoStep");
        *(void **)&f->setr3 = sym(f, "SetFloat64");
        *(void **)&f->getr3 = sym(f, "GetFloat64");
        *(void **)&f->geti3 = sym(f, "GetInt32");
        *(void **)&f->freei3 = sym(f, "FreeInstance");
        *(void **)&f->get = sym(f, "GetFMUState");
        *(void **)&f->set = sym(f, "SetFMUState");
        *(void **)&f->freest = sym(f, "FreeFMUState");
        *(void **)&f->size = sym(f, "SerializedFMUStateSize");
        *(void **)&f->ser = sym(f, "SerializeFMUState");
        *(void **)&f->deser = sym(f, "DeserializeFMUState");
    }
    f->main = instantiate(f, "main");
    f->twin = instantiate(f, "twin");
}

/* one step of 5 ms of instance c, inputs near their starts (a slow sine, the same for both) */
static int step(Fmu *f, void *c, double t)
{
    double u[MAX_VRS];
    for (size_t i = 0; i < f->n_in; i++)
        u[i] = f->start[i] + 0.01 * fmax(1.0, fabs(f->start[i])) * sin(3.0 * t + (double)i);
    if (f->version == 2) {
        f->setr2(c, f->in, f->n_in, u);
        return f->step2(c, t, STEP, fmi2True);
    }
    fmi3Boolean a, b, e;
    fmi3Float64 last;
    f->setr3(c, f->in, f->n_in, u, f->n_in);
    return f->step3(c, t, STEP, fmi3True, &a, &b, &e, &last);
}

/* the outputs (Real, then Integer as doubles) of instance c into y */
static void outputs(Fmu *f, void *c, double *y)
{
    int yi2[MAX_VRS];
    int32_t yi3[MAX_VRS];
    memset(y, 0, sizeof(double) * 2 * MAX_VRS);
    if (f->version == 2) {
        f->getr2(c, f->out, f->n_out, y);
        f->geti2(c, f->ints, f->n_int, yi2);
        for (size_t i = 0; i < f->n_int; i++) y[f->n_out + i] = yi2[i];
    } else {
        f->getr3(c, f->out, f->n_out, y, f->n_out);
        f->geti3(c, f->ints, f->n_int, yi3, f->n_int);
        for (size_t i = 0; i < f->n_int; i++) y[f->n_out + i] = yi3[i];
    }
}

/* 1 if the main instance's outputs are bit-identical to its twin's */
static int same_as_twin(Fmu *f)
{
    double a[2 * MAX_VRS], b[2 * MAX_VRS];
    outputs(f, f->main, a);
    outputs(f, f->twin, b);
    return memcmp(a, b, sizeof a) == 0;
}

static void step_both(Fmu *f, int n)
{
    for (int k = 0; k < n; k++) {
        int s1 = step(f, f->main, f->t), s2 = step(f, f->twin, f->t);
        if (s1 > 1 || s2 > 1) check(0, "%s (FMI %d): step at t = %g refused (%d, %d)", f->id, f->version, f->t, s1, s2);
        f->t += STEP;
    }
}

static unsigned char *serialized(Fmu *f, void *state, size_t *n)
{
    *n = 0;
    if (f->size(f->main, state, n) != 0 || *n == 0) return NULL;
    unsigned char *bytes = malloc(*n);
    if (bytes && f->ser(f->main, state, bytes, *n) != 0) {
        free(bytes);
        return NULL;
    }
    return bytes;
}

/* ------------------------------------------------------------------ another FMU's state */
static void foreign(Fmu *x, Fmu *y)
{
    char what[160];
    snprintf(what, sizeof what, "%s (FMI %d) -> %s (FMI %d)", x->id, x->version, y->id, y->version);
    void *sx = NULL, *reuse;
    size_t nx = 0, n = 0;
    int s = x->get(x->main, &sx);
    unsigned char *bx = s == 0 ? serialized(x, sx, &nx) : NULL;
    if (bx == NULL) {
        check(0, "%s: %s's own state cannot be got and serialised", what, x->id);
        return;
    }
    unsigned char copy[KEEP]; /* (a latobs state is longer: its Values alone are longer) */
    memcpy(copy, sx, KEEP);
    last_error[0] = '\0';
    s = y->set(y->main, sx);
    check(s >= 3 && same_as_twin(y), "%s: SetFMUState refused (status %d), outputs kept", what, s);
    printf("msg set %s: %s\n", what, last_error);
    reuse = sx;
    s = y->get(y->main, &reuse);
    check(s >= 3 && reuse == sx && memcmp(copy, sx, KEEP) == 0, "%s: GetFMUState into it refused (status %d), "
          "the state not written", what, s);
    printf("msg get %s: %s\n", what, last_error);
    reuse = sx;
    s = y->freest(y->main, &reuse);
    check(s >= 3 && reuse == sx, "%s: FreeFMUState refused (status %d), not freed", what, s);
    s = y->size(y->main, sx, &n);
    check(s >= 3, "%s: SerializedFMUStateSize refused (status %d)", what, s);
    unsigned char *buf = calloc(1, nx + 4096);
    s = y->ser(y->main, sx, buf, nx + 4096);
    check(s >= 3, "%s: SerializeFMUState refused (status %d)", what, s);
    free(buf);
    void *got = NULL;
    last_error[0] = '\0';
    s = y->deser(y->main, bx, nx, &got);
    check(s >= 3 && got == NULL, "%s: DeserializeFMUState of its bytes refused (status %d), no state made", what, s);
    printf("msg deserialize %s: %s\n", what, last_error);
    check(same_as_twin(y), "%s: outputs identical to the twin's after the refusals", what);
    s = x->set(x->main, sx);
    check(s == 0 && memcmp(copy, sx, KEEP) == 0, "%s: %s's state intact, restored by it (status %d)", what, x->id, s);
    s = x->freest(x->main, &sx);
    check(s == 0 && sx == NULL, "%s: freed by its FMU (status %d)", what, s);
    free(bx);
}

/* ------------------------------------------------------------------ damaged serialisations */
static uint64_t rng = 88172645463325252ull;
static uint64_t rnd(void)
{
    rng ^= rng << 13, rng ^= rng >> 7, rng ^= rng << 17;
    return rng;
}

static int refused_bytes(Fmu *f, const unsigned char *bytes, size_t n)
{
    void *got = NULL;
    int s = f->deser(f->main, bytes, n, &got);
    if (s < 3 || got != NULL) {
        if (got) f->freest(f->main, &got);
        return 0;
    }
    return 1;
}

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void damaged(Fmu *f, long iterations, double seconds)
{
    void *st = NULL;
    size_t n;
    char what[96];
    snprintf(what, sizeof what, "%s (FMI %d)", f->id, f->version);
    f->get(f->main, &st);
    unsigned char *good = serialized(f, st, &n);
    if (good == NULL) {
        check(0, "%s: its state cannot be serialised", what);
        return;
    }
    unsigned char *b = malloc(n + 64);
    int bad = 0;
    /* truncated, extended */
    size_t cuts[] = {0, 1, 4, 7, 8, 16, 23, 24, 63, 64, 127, 128, n / 2, n - 8, n - 1};
    for (size_t k = 0; k < sizeof cuts / sizeof cuts[0]; k++) {
        if (cuts[k] >= n) continue;
        memcpy(b, good, cuts[k]);
        last_error[0] = '\0';
        if (!refused_bytes(f, b, cuts[k])) bad++, printf("     accepted: truncated to %zu bytes\n", cuts[k]);
        if (cuts[k] == n / 2) printf("msg truncated %s: %s\n", what, last_error);
    }
    memcpy(b, good, n);
    memset(b + n, 0, 64);
    if (!refused_bytes(f, b, n + 1) || !refused_bytes(f, b, n + 64)) bad++, printf("     accepted: extended\n");
    check(bad == 0, "%s: truncated and extended serialisations (%zu bytes) refused", what, n);
    /* the issue's: the second half 0xFF */
    memcpy(b, good, n);
    memset(b + n / 2, 0xFF, n - n / 2);
    last_error[0] = '\0';
    check(refused_bytes(f, b, n), "%s: second half 0xFF refused", what);
    printf("msg ffhalf %s: %s\n", what, last_error);
    /* a one-bit flip at every bit of the first 256 bytes, then at random bits */
    bad = 0;
    long tried = 0;
    double t0 = now();
    for (size_t bit = 0; bit < 8 * 256 && bit < 8 * n; bit++, tried++) {
        memcpy(b, good, n);
        b[bit / 8] ^= (unsigned char)(1u << (bit % 8));
        if (!refused_bytes(f, b, n)) bad++, printf("     accepted: bit %zu flipped\n", bit);
    }
    for (long k = 0; k < iterations && now() - t0 < seconds / 2; k++, tried++) {
        size_t bit = (size_t)(rnd() % (8 * n));
        memcpy(b, good, n);
        b[bit / 8] ^= (unsigned char)(1u << (bit % 8));
        if (!refused_bytes(f, b, n)) bad++, printf("     accepted: bit %zu flipped\n", bit);
    }
    check(bad == 0, "%s: %ld one-bit flips refused", what, tried);
    /* random mutations: a few bytes, a block, another length, all random */
    bad = 0, tried = 0;
    t0 = now();
    for (long k = 0; k < iterations && now() - t0 < seconds / 2; k++, tried++) {
        size_t m = n;
        memcpy(b, good, n);
        switch (rnd() % 5) {
        case 0:
            for (int j = 1 + (int)(rnd() % 8); j > 0; j--) b[rnd() % n] ^= (unsigned char)(1 + rnd() % 255);
            break;
        case 1: {
            size_t at = rnd() % n, len = 1 + rnd() % (n - at);
            memset(b + at, (int)(rnd() & 0xFF), len);
            b[at] ^= 0x5A; /* (never the same byte everywhere by chance) */
            break;
        }
        case 2:
            m = rnd() % (n + 64);
            if (m == n) m--;
            break;
        case 3: /* the top bytes of two words (a word hash without downward mixing misses 1 in 256) */
            for (int j = 0; j < 2; j++) b[(rnd() % (n / 8)) * 8 + 7] ^= (unsigned char)(1 + rnd() % 255);
            break;
        default:
            for (size_t j = 0; j < n; j++) b[j] = (unsigned char)rnd();
        }
        if (m == n && memcmp(b, good, n) == 0) { /* (a mutation that undid itself: the intact state) */
            tried--;
            continue;
        }
        if (!refused_bytes(f, b, m)) bad++, printf("     accepted: mutation %ld\n", k);
    }
    check(bad == 0, "%s: %ld random mutations refused", what, tried);
    check(refused_bytes(f, NULL, n) && refused_bytes(f, good, 0), "%s: NULL bytes and 0 bytes refused", what);
    /* in memory: a bit flipped in the state itself */
    bad = 0, tried = 0;
    unsigned char *mem = st;
    for (long k = 0; k < 64 && k < iterations; k++, tried++) {
        size_t bit = k < 8 ? (size_t)k * 8 : (size_t)(rnd() % (8 * n));
        mem[bit / 8] ^= (unsigned char)(1u << (bit % 8));
        if (f->set(f->main, st) < 3) bad++, printf("     accepted: in-memory bit %zu flipped\n", bit);
        mem[bit / 8] ^= (unsigned char)(1u << (bit % 8));
    }
    printf("msg memflip %s: %s\n", what, last_error);
    check(bad == 0 && same_as_twin(f), "%s: %ld in-memory one-bit flips refused by SetFMUState, outputs kept", what,
          tried);
    /* in memory: 64 random bytes, not a state at all */
    unsigned char junk[64], kept[64];
    for (size_t j = 0; j < sizeof junk; j++) junk[j] = kept[j] = (unsigned char)rnd();
    void *jp = junk;
    size_t js;
    int r1 = f->set(f->main, junk), r2 = f->get(f->main, &jp), r3 = f->freest(f->main, &jp);
    int r4 = f->size(f->main, junk, &js), r5 = f->ser(f->main, junk, b, n);
    check(r1 >= 3 && r2 >= 3 && r3 >= 3 && r4 >= 3 && r5 >= 3 && jp == junk && !memcmp(junk, kept, sizeof junk) &&
          same_as_twin(f), "%s: 64 random bytes refused as a state by the five calls taking one, untouched", what);
    printf("msg junk %s: %s\n", what, last_error);
    /* the intact ones still work */
    void *got = NULL;
    int s1 = f->deser(f->main, good, n, &got);
    int s2 = s1 == 0 ? f->set(f->main, got) : -1;
    int s3 = f->set(f->main, st);
    void *again = st; /* a state of this FMU given back to be overwritten (FMI allows it) */
    int s4 = f->get(f->main, &again), s5 = f->deser(f->main, good, n, &again);
    check(s1 == 0 && s2 == 0 && s3 == 0 && s4 == 0 && s5 == 0 && again == st && same_as_twin(f),
          "%s: the intact state deserialised and set, and got and deserialised into its own block (%d, %d, %d, %d, %d)",
          what, s1, s2, s3, s4, s5);
    f->freest(f->main, &got);
    f->freest(f->main, &st);
    free(b);
    free(good);
}

int main(int argc, char **argv)
{
    if (argc < 4 + 8 || (argc - 4) % 8 != 0 || (argc - 4) / 8 > MAX_FMUS) {
        fprintf(stderr, "usage: state_host ITERATIONS SECONDS SEED (VERSION LIBRARY ID TOKEN IN_VRS IN_STARTS "
                        "OUT_VRS INT_VRS)...\n");
        return 2;
    }
    long iterations = atol(argv[1]);
    double seconds = atof(argv[2]);
    rng ^= strtoull(argv[3], NULL, 10) * 0x9E3779B97F4A7C15ull;
    for (int i = 4; i < argc; i += 8) load(&fmus[n_fmus++], argv + i);
    for (int i = 0; i < n_fmus; i++) {
        step_both(&fmus[i], 40);
        check(same_as_twin(&fmus[i]), "%s (FMI %d): main and twin alike after 40 steps", fmus[i].id, fmus[i].version);
    }
    for (int x = 0; x < n_fmus; x++)
        for (int y = 0; y < n_fmus; y++)
            if (x != y) foreign(&fmus[x], &fmus[y]);
    for (int i = 0; i < n_fmus; i++) damaged(&fmus[i], iterations, seconds / n_fmus);
    for (int i = 0; i < n_fmus; i++) {
        Fmu *f = &fmus[i];
        int alike = same_as_twin(f);
        for (int k = 0; k < 40 && alike; k++) {
            step_both(f, 1);
            alike = same_as_twin(f);
        }
        double y[2 * MAX_VRS];
        outputs(f, f->main, y);
        int finite = 1;
        for (size_t k = 0; k < f->n_out; k++) finite &= isfinite(y[k]) != 0;
        check(alike && finite, "%s (FMI %d): 40 more steps bit-identical to the twin, outputs finite", f->id,
              f->version);
        if (f->version == 2) f->freei2(f->main), f->freei2(f->twin);
        else f->freei3(f->main), f->freei3(f->twin);
    }
    printf("state_host: %d failure(s)\n", failures);
    return failures ? 1 : 0;
}
