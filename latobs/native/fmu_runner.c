/*
 * fmu_runner.c - a portable plain C FMI 2.0 and 3.0 co-simulation host (C99; POSIX or Windows, one code
 * path but the loader and the clock): runs an extracted FMU's binary on an input CSV and writes
 * its outputs, or times it. Compiled for each platform (zig cc), it proves an FMU's win64 binary
 * under Wine and its aarch64-linux binary under qemu give the linux64 numbers
 * (latobs.cbackend.runner); natively it is `latobs bench`'s host, with no Python in the loop.
 *
 * usage: fmu_runner MODE LIBRARY URI ID GUID IN.csv OUT.csv OUTPUTS STEP PRELOAD [VAR=VALUE...]
 *   MODE     run, or bench=REPEATS; prefixed "fmi3:" for an FMI 3.0 FMU (fmi3InstantiateCoSimulation,
 *            fmi3Get/SetFloat64, Int32, Boolean, fmi3DoStep; a step that asks to terminate the
 *            simulation counts as an error), else FMI 2.0
 *   LIBRARY  the FMU's shared library for this platform; URI its resources folder (FMI 2.0: a
 *            file:/// URI; FMI 3.0: a native path ending in a separator)
 *   ID, GUID the modelIdentifier and the guid (FMI 3.0: the instantiation token)
 *   IN.csv   header "time,VAR,..." then one row per communication point t_0 < ... < t_N; VAR is a
 *            type letter (r Real, i Integer, b Boolean) and a value reference, e.g. r12
 *   OUT.csv  run: header "time,status,OUTPUTS", then one row per communication point reached:
 *            the outputs at t_0 after initialisation and at t_k after the step from t_(k-1);
 *            status is the worst status of the calls that led to the row. A row whose status
 *            is above fmi2Warning is the last (outputs read after fmi2Discard, else nan).
 *            bench: one JSON line (ns per step: best and median of REPEATS fresh instances)
 *   OUTPUTS  comma-separated VARs to write ("-": none)
 *   STEP     the communication step of every doStep ("-": t_(k+1) - t_k)
 *   PRELOAD  a library loaded first with its symbols global (libpython, for a pythonfmu FMU), "-"
 *   VAR=VALUE  set after fmi2SetupExperiment, before initialisation (parameters, start values)
 * Row k's inputs are set before the step from t_k (row 0 also in initialisation mode); the
 * last row's inputs are not used. Numbers are written %.17g (round-trip exact), nan and +-inf
 * as such. Exit status: 0 (the run is in OUT.csv, failed steps included), 1 if the FMU cannot be
 * loaded or instantiated, 2 on bad usage or input.
 */
#ifdef _WIN32
#define WIN32_LEAN_AND_MEAN
#include <windows.h>
#else
#define _POSIX_C_SOURCE 200809L
#include <dlfcn.h>
#include <time.h>
#endif
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmi3Functions.h"

#define MAX_VARS 512
#define TIMING_NS 2e7 /* ns: the length of one timing, about */
#define WORSE(s, call)                   \
    do {                                 \
        fmi2Status s_ = (call);          \
        if (s_ > (s)) (s) = s_;          \
    } while (0)

typedef struct { /* variables by type (0 Real, 1 Integer, 2 Boolean): value refs, their columns */
    size_t n[3], col[3][MAX_VARS];
    fmi2ValueReference vr[3][MAX_VARS];
} Vars;

#define FMI_FUNCTIONS(X)                                                                                  \
    X(Instantiate) X(FreeInstance) X(SetupExperiment) X(EnterInitializationMode) X(ExitInitializationMode) \
    X(Terminate) X(DoStep) X(SetReal) X(SetInteger) X(SetBoolean) X(GetReal) X(GetInteger) X(GetBoolean)
#define FMI3_FUNCTIONS(X)                                                                                      \
    X(InstantiateCoSimulation) X(FreeInstance) X(EnterInitializationMode) X(ExitInitializationMode) X(Terminate) \
    X(DoStep) X(SetFloat64) X(SetInt32) X(SetBoolean) X(GetFloat64) X(GetInt32) X(GetBoolean)
#define DECLARE(name) fmi2##name##TYPE *name;
#define DECLARE3(name) fmi3##name##TYPE *name;
typedef struct { FMI_FUNCTIONS(DECLARE) } Api;
typedef struct { FMI3_FUNCTIONS(DECLARE3) } Api3;

typedef struct {
    Api api;
    Api3 api3;
    int fmi3; /* 1: an FMI 3.0 FMU (api3), else FMI 2.0 (api) */
    const char *uri, *id, *guid;
    double step, *rows, *params; /* rows: n rows of [time, inputs...] */
    size_t n, width, n_out;
    Vars in, out, par;
} Run;

static void die(int code, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    fputc('\n', stderr);
    exit(code);
}

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    va_list ap;
    (void)env;
    fprintf(stderr, "[%s] status %d %s: ", instance ? instance : "?", (int)status, category ? category : "");
    va_start(ap, message);
    vfprintf(stderr, message, ap);
    va_end(ap);
    fputc('\n', stderr);
}

static const fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};

static void logger3(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env;
    fprintf(stderr, "[fmi3] status %d %s: %s\n", (int)status, category ? category : "", message ? message : "");
}

static void *load(const char *path, int global)
{
#ifdef _WIN32
    wchar_t wide[4096];
    (void)global;
    if (MultiByteToWideChar(CP_UTF8, 0, path, -1, wide, 4096) == 0) return NULL;
    return (void *)LoadLibraryW(wide);
#else
    return dlopen(path, RTLD_NOW | (global ? RTLD_GLOBAL : RTLD_LOCAL));
#endif
}

static void sym(void *lib, const char *name, void *fn) /* fn: the address of a function pointer */
{
#ifdef _WIN32
    FARPROC p = GetProcAddress((HMODULE)lib, name);
#else
    void *p = dlsym(lib, name);
#endif
    if (p == NULL) die(1, "the FMU's library has no %s", name);
    memcpy(fn, &p, sizeof p);
}

static double now_ns(void)
{
#ifdef _WIN32
    LARGE_INTEGER t, f;
    QueryPerformanceCounter(&t);
    QueryPerformanceFrequency(&f);
    return 1e9 * (double)t.QuadPart / (double)f.QuadPart;
#else
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return 1e9 * (double)ts.tv_sec + (double)ts.tv_nsec;
#endif
}

/* a number; nan and [+-]inf spelled so by any C runtime */
static double number(const char *s, char **end)
{
    const char *w = s + (*s == '-' || *s == '+');
    if (strncmp(w, "nan", 3) == 0 || strncmp(w, "inf", 3) == 0) {
        *end = (char *)w + 3;
        return w[0] == 'n' ? NAN : *s == '-' ? -HUGE_VAL : HUGE_VAL;
    }
    return strtod(s, end);
}

/* "r12" -> variable in column col; 0 if malformed */
static int add_var(Vars *v, const char *tok, size_t col)
{
    const char *types = "rib", *t = strchr(types, tok[0]);
    char *end;
    if (tok[0] == '\0' || t == NULL || tok[1] < '0' || tok[1] > '9') return 0;
    size_t k = (size_t)(t - types), n = v->n[k];
    if (n == MAX_VARS) return 0;
    v->vr[k][n] = (fmi2ValueReference)strtoul(tok + 1, &end, 10);
    v->col[k][n] = col;
    v->n[k]++;
    return *end == '\0' || *end == '=';
}

/* Statuses: FMI 2.0's and 3.0's OK, Warning, Discard, Error, Fatal are 0..4 alike (fmi2Status). */
static fmi2Status set_vars(const Run *run, void *c, const Vars *v, const double *x)
{
    fmi2Real r[MAX_VARS];
    fmi2Integer i[MAX_VARS];
    fmi2Boolean b[MAX_VARS];
    fmi3Boolean b3[MAX_VARS];
    fmi2Status s = fmi2OK;
    const Api *a = &run->api;
    const Api3 *a3 = &run->api3;
    for (size_t k = 0; k < v->n[0]; k++) r[k] = x[v->col[0][k]];
    for (size_t k = 0; k < v->n[1]; k++) i[k] = isfinite(x[v->col[1][k]]) ? (fmi2Integer)x[v->col[1][k]] : 0;
    for (size_t k = 0; k < v->n[2]; k++) b[k] = x[v->col[2][k]] != 0.0, b3[k] = b[k] != 0;
    if (run->fmi3) {
        if (v->n[0]) WORSE(s, (fmi2Status)a3->SetFloat64(c, v->vr[0], v->n[0], r, v->n[0]));
        if (v->n[1]) WORSE(s, (fmi2Status)a3->SetInt32(c, v->vr[1], v->n[1], i, v->n[1]));
        if (v->n[2]) WORSE(s, (fmi2Status)a3->SetBoolean(c, v->vr[2], v->n[2], b3, v->n[2]));
        return s;
    }
    if (v->n[0]) WORSE(s, a->SetReal(c, v->vr[0], v->n[0], r));
    if (v->n[1]) WORSE(s, a->SetInteger(c, v->vr[1], v->n[1], i));
    if (v->n[2]) WORSE(s, a->SetBoolean(c, v->vr[2], v->n[2], b));
    return s;
}

static fmi2Status get_vars(const Run *run, void *c, const Vars *v, double *y)
{
    fmi2Real r[MAX_VARS];
    fmi2Integer i[MAX_VARS];
    fmi2Boolean b[MAX_VARS];
    fmi3Boolean b3[MAX_VARS];
    fmi2Status s = fmi2OK;
    const Api *a = &run->api;
    const Api3 *a3 = &run->api3;
    if (run->fmi3) {
        if (v->n[0]) WORSE(s, (fmi2Status)a3->GetFloat64(c, v->vr[0], v->n[0], r, v->n[0]));
        if (v->n[1]) WORSE(s, (fmi2Status)a3->GetInt32(c, v->vr[1], v->n[1], i, v->n[1]));
        if (v->n[2]) WORSE(s, (fmi2Status)a3->GetBoolean(c, v->vr[2], v->n[2], b3, v->n[2]));
        for (size_t k = 0; k < v->n[2]; k++) b[k] = b3[k] ? fmi2True : fmi2False;
    } else {
        if (v->n[0]) WORSE(s, a->GetReal(c, v->vr[0], v->n[0], r));
        if (v->n[1]) WORSE(s, a->GetInteger(c, v->vr[1], v->n[1], i));
        if (v->n[2]) WORSE(s, a->GetBoolean(c, v->vr[2], v->n[2], b));
    }
    for (size_t k = 0; k < v->n[0]; k++) y[v->col[0][k]] = r[k];
    for (size_t k = 0; k < v->n[1]; k++) y[v->col[1][k]] = (double)i[k];
    for (size_t k = 0; k < v->n[2]; k++) y[v->col[2][k]] = b[k] ? 1.0 : 0.0;
    return s;
}

static fmi2Status do_step(const Run *r, void *c, double t, double h)
{
    if (!r->fmi3) return r->api.DoStep(c, t, h, fmi2True);
    fmi3Boolean event = fmi3False, terminate = fmi3False, early = fmi3False;
    fmi3Float64 last = t;
    fmi2Status s = (fmi2Status)r->api3.DoStep(c, t, h, fmi3True, &event, &terminate, &early, &last);
    return terminate && s < fmi2Error ? fmi2Error : s; /* asked to terminate: no further step */
}

static void *start(const Run *r, fmi2Status *s)
{
    const Api *a = &r->api;
    const Api3 *a3 = &r->api3;
    double t0 = r->rows[0], t1 = r->rows[(r->n - 1) * r->width];
    void *c;
    if (r->fmi3) {
        c = a3->InstantiateCoSimulation(r->id, r->guid, r->uri, fmi3False, fmi3True, fmi3False, fmi3False, NULL, 0,
                                        NULL, logger3, NULL);
        if (c == NULL) die(1, "fmi3InstantiateCoSimulation returned NULL");
        *s = set_vars(r, c, &r->par, r->params);
        if (*s <= fmi2Warning) WORSE(*s, (fmi2Status)a3->EnterInitializationMode(c, fmi3False, 0.0, t0, fmi3True, t1));
        if (*s <= fmi2Warning) WORSE(*s, set_vars(r, c, &r->in, r->rows));
        if (*s <= fmi2Warning) WORSE(*s, (fmi2Status)a3->ExitInitializationMode(c));
        return c;
    }
    c = a->Instantiate(r->id, fmi2CoSimulation, r->guid, r->uri, &callbacks, fmi2False, fmi2True);
    if (c == NULL) die(1, "fmi2Instantiate returned NULL");
    *s = a->SetupExperiment(c, fmi2False, 0.0, t0, fmi2True, t1);
    if (*s <= fmi2Warning) WORSE(*s, set_vars(r, c, &r->par, r->params));
    if (*s <= fmi2Warning) WORSE(*s, a->EnterInitializationMode(c));
    if (*s <= fmi2Warning) WORSE(*s, set_vars(r, c, &r->in, r->rows));
    if (*s <= fmi2Warning) WORSE(*s, a->ExitInitializationMode(c));
    return c;
}

static void stop(const Run *r, void *c, fmi2Status s)
{
    if (r->fmi3) {
        if (s <= fmi2Warning) r->api3.Terminate(c);
        if (s < fmi2Fatal) r->api3.FreeInstance(c);
        return;
    }
    if (s <= fmi2Warning) r->api.Terminate(c);
    if (s < fmi2Fatal) r->api.FreeInstance(c);
}

static void put(FILE *f, double x)
{
    if (isnan(x)) fputs("nan", f);
    else if (isinf(x)) fputs(x > 0 ? "inf" : "-inf", f);
    else fprintf(f, "%.17g", x);
}

static void run(const Run *r, FILE *f)
{
    double y[MAX_VARS];
    fmi2Status s;
    void *c = start(r, &s);
    for (size_t k = 0;; k++) {
        const double *row = r->rows + k * r->width;
        for (size_t j = 0; j < r->n_out; j++) y[j] = NAN;
        if (s <= fmi2Discard) WORSE(s, get_vars(r, c, &r->out, y));
        put(f, row[0]);
        fprintf(f, ",%d", (int)s);
        for (size_t j = 0; j < r->n_out; j++) fputc(',', f), put(f, y[j]);
        fputc('\n', f);
        if (s > fmi2Warning || k + 1 == r->n) break;
        s = set_vars(r, c, &r->in, row);
        if (s <= fmi2Warning) WORSE(s, do_step(r, c, row[0], r->step > 0 ? r->step : row[r->width] - row[0]));
    }
    stop(r, c, s);
}

static int by_value(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* ns per step over `repeats` fresh instances, sorted (best first), each running the rows
 * `passes` times; full: set + step + get, else doStep alone (the last row's inputs held) */
static void time_steps(const Run *r, int full, size_t passes, int repeats, double *times)
{
    double y[MAX_VARS], h = r->step > 0 ? r->step : r->rows[r->width] - r->rows[0];
    size_t steps = r->n - 1, total = steps * passes;
    for (int rep = 0; rep < repeats; rep++) {
        fmi2Status s;
        void *c = start(r, &s);
        if (!full) WORSE(s, set_vars(r, c, &r->in, r->rows + (steps - 1) * r->width));
        double t0 = now_ns();
        for (size_t k = 0, row = 0; k < total; k++, row = (row + 1 == steps) ? 0 : row + 1) {
            if (full) WORSE(s, set_vars(r, c, &r->in, r->rows + row * r->width));
            WORSE(s, do_step(r, c, r->rows[0] + (double)k * h, h));
            if (full) WORSE(s, get_vars(r, c, &r->out, y));
        }
        times[rep] = (now_ns() - t0) / (double)total;
        stop(r, c, s);
        if (s > fmi2Warning) die(1, "a call returned status %d while timing", (int)s);
    }
    qsort(times, (size_t)repeats, sizeof *times, by_value);
}

static void bench(const Run *r, int repeats, FILE *f)
{
    double *full = (double *)malloc(sizeof(double) * 2 * (size_t)repeats), *step = full + repeats;
    if (full == NULL) die(2, "out of memory");
    time_steps(r, 1, 1, 1, full); /* one pass: how many make a timing of about TIMING_NS */
    double passes = TIMING_NS / (full[0] * (double)(r->n - 1));
    size_t p = passes < 1.0 ? 1 : passes > 1e4 ? 10000 : (size_t)passes;
    time_steps(r, 1, p, repeats, full);
    time_steps(r, 0, p, repeats, step);
    fprintf(f, "{\"ns_per_step_with_io\": %.6g, \"ns_per_doStep\": %.6g, \"median_ns_per_step_with_io\": %.6g, "
               "\"median_ns_per_doStep\": %.6g, \"steps_per_timing\": %lu, \"repeats\": %d}\n", full[0], step[0],
            full[repeats / 2], step[repeats / 2], (unsigned long)((r->n - 1) * p), repeats);
    free(full);
}

static void read_csv(Run *r, const char *path)
{
    static char line[1 << 16];
    size_t cap = 0;
    FILE *f = fopen(path, "r");
    if (f == NULL || fgets(line, sizeof line, f) == NULL || strncmp(line, "time", 4) != 0)
        die(2, "%s: no header \"time,...\"", path);
    r->width = 1;
    for (char *tok = strtok(line + 4, ",\r\n"); tok; tok = strtok(NULL, ",\r\n"))
        if (!add_var(&r->in, tok, r->width++)) die(2, "%s: bad column %s (r, i or b and a value reference)", path, tok);
    while (fgets(line, sizeof line, f) != NULL) {
        if (r->n == cap) {
            cap = cap ? 2 * cap : 1024;
            r->rows = (double *)realloc(r->rows, sizeof(double) * cap * r->width);
            if (r->rows == NULL) die(2, "out of memory");
        }
        char *p = line, *end;
        for (size_t j = 0; j < r->width; j++, p = end + 1) {
            r->rows[r->n * r->width + j] = number(p, &end);
            if (end == p || (j + 1 < r->width ? *end != ',' : end[strspn(end, " \r\n")] != '\0'))
                die(2, "%s line %lu: expected %lu numbers", path, (unsigned long)(r->n + 2), (unsigned long)r->width);
        }
        if (r->n > 0 && !(r->rows[r->n * r->width] > r->rows[(r->n - 1) * r->width]))
            die(2, "%s line %lu: the times must increase", path, (unsigned long)(r->n + 2));
        r->n++;
    }
    fclose(f);
    if (r->n < 2) die(2, "%s: fewer than two communication points", path);
}

int main(int argc, char **argv)
{
    static Run r;
    static double params[MAX_VARS];
    if (argc < 11) die(2, "usage: %s run|bench=N LIBRARY URI ID GUID IN.csv OUT.csv OUTPUTS STEP PRELOAD [VAR=VALUE...]", argv[0]);
    const char *mode = argv[1];
    r.fmi3 = strncmp(mode, "fmi3:", 5) == 0;
    mode += r.fmi3 ? 5 : 0;
    int repeats = strncmp(mode, "bench=", 6) == 0 ? atoi(mode + 6) : 0;
    if (strcmp(mode, "run") != 0 && repeats < 1) die(2, "MODE: [fmi3:]run or [fmi3:]bench=REPEATS (REPEATS > 0)");
    r.uri = argv[3];
    r.id = argv[4];
    r.guid = argv[5];
    read_csv(&r, argv[6]);
    char outputs[1 << 14];
    snprintf(outputs, sizeof outputs, "%s", strcmp(argv[8], "-") ? argv[8] : "");
    if (outputs[0])
        for (char *tok = strtok(outputs, ","); tok; tok = strtok(NULL, ","))
            if (r.n_out == MAX_VARS || !add_var(&r.out, tok, r.n_out++)) die(2, "OUTPUTS: bad variable %s", tok);
    r.step = strcmp(argv[9], "-") == 0 ? 0.0 : atof(argv[9]);
    r.params = params;
    if (argc - 11 > MAX_VARS) die(2, "more than %d VAR=VALUE", MAX_VARS);
    for (int k = 11; k < argc; k++) {
        char *eq = strchr(argv[k], '='), *end;
        if (eq == NULL || !add_var(&r.par, argv[k], (size_t)(k - 11)) || (params[k - 11] = number(eq + 1, &end), *end))
            die(2, "bad VAR=VALUE %s", argv[k]);
    }
    if (strcmp(argv[10], "-") != 0 && load(argv[10], 1) == NULL) die(1, "cannot load %s", argv[10]);
    void *lib = load(argv[2], 0);
    if (lib == NULL) die(1, "cannot load the FMU's library %s", argv[2]);
    Api *a = &r.api;
    Api3 *a3 = &r.api3;
#define LOAD(name) sym(lib, "fmi2" #name, &a->name);
#define LOAD3(name) sym(lib, "fmi3" #name, &a3->name);
    if (r.fmi3) {
        FMI3_FUNCTIONS(LOAD3)
    } else {
        FMI_FUNCTIONS(LOAD)
    }
    FILE *f = fopen(argv[7], "w");
    if (f == NULL) die(2, "cannot write %s", argv[7]);
    if (repeats) {
        bench(&r, repeats, f);
    } else {
        fprintf(f, "time,status%s%s\n", r.n_out ? "," : "", r.n_out ? argv[8] : "");
        run(&r, f);
    }
    /* no dlclose: a pythonfmu library cannot be unloaded (see latobs.fmu_src.framework) */
    return fclose(f) == 0 ? 0 : 2;
}
