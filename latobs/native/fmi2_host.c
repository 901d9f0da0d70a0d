/*
 * fmi2_host.c - a plain C FMI 2.0 co-simulation host: runs an extracted FMU on recorded inputs, or
 * times it. Used by `latobs bench` (the cost of a step without any Python in the loop) and by the
 * tests (a non-Python host loading the FMU with dlopen). C99 + POSIX (dlopen, clock_gettime).
 *
 * usage: fmi2_host MODE LIBPYTHON DIR ID GUID H N IN_VRS OUT_VRS INT_VRS [REPEATS]
 *   MODE       run:   print the outputs after initialisation and after each of the N steps
 *                     (N + 1 lines: the Real outputs then the Integer outputs, %.17g)
 *              bench: time the steps REPEATS times (default 5) and print one JSON line with the
 *                     best and the median nanoseconds per step of (a) fmi2SetReal + fmi2DoStep +
 *                     fmi2GetReal + fmi2GetInteger with the recorded inputs, (b) fmi2DoStep alone
 *                     (inputs of the last row held), each over a fresh instance; each timing runs
 *                     the N rows over and over, as many times as make it last about TIMING_NS
 *                     (measured on a first pass), so that it lasts milliseconds, not microseconds
 *   LIBPYTHON  a libpython to dlopen with RTLD_GLOBAL first (pythonfmu FMUs need its symbols in
 *              the global scope), or "none"
 *   DIR        the extracted FMU; ID its modelIdentifier; GUID its guid; H the step (s)
 *   IN_VRS, OUT_VRS, INT_VRS  comma-separated value references ("-" for none)
 * stdin: N rows of the inputs (whitespace-separated, one column per IN_VR); row k is set before
 * step k (t_k = k H), row 0 also in initialisation mode.
 * Exit status: 0, or 1 if a call returned more than fmi2Warning (logged on stderr), 2 on bad usage.
 */
#define _POSIX_C_SOURCE 200809L

#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2Functions.h"

#define MAX_VARS 256
#define TIMING_NS 2e7 /* ns: the length of one timing, about */

typedef struct {
    fmi2InstantiateTYPE *instantiate;
    fmi2FreeInstanceTYPE *free_instance;
    fmi2SetupExperimentTYPE *setup;
    fmi2EnterInitializationModeTYPE *enter_init;
    fmi2ExitInitializationModeTYPE *exit_init;
    fmi2TerminateTYPE *terminate;
    fmi2SetRealTYPE *set_real;
    fmi2GetRealTYPE *get_real;
    fmi2GetIntegerTYPE *get_integer;
    fmi2DoStepTYPE *do_step;
} Api;

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    va_list ap;
    (void)env;
    if (status < fmi2Error) return;
    fprintf(stderr, "[%s] status %d %s: ", instance ? instance : "?", (int)status, category ? category : "");
    va_start(ap, message);
    vfprintf(stderr, message, ap);
    va_end(ap);
    fputc('\n', stderr);
}

static const fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};

static void *sym(void *lib, const char *name)
{
    void *p = dlsym(lib, name);
    if (p == NULL) {
        fprintf(stderr, "dlsym %s: %s\n", name, dlerror());
        exit(2);
    }
    return p;
}

static size_t parse_vrs(const char *text, fmi2ValueReference *vrs)
{
    size_t n = 0;
    if (strcmp(text, "-") == 0) return 0;
    for (const char *s = text; *s && n < MAX_VARS;) {
        char *end;
        vrs[n++] = (fmi2ValueReference)strtoul(s, &end, 10);
        s = (*end == ',') ? end + 1 : end;
        if (end == s && *s) break;
    }
    return n;
}

static double now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return 1e9 * (double)ts.tv_sec + (double)ts.tv_nsec;
}

static int check(fmi2Status s, const char *what)
{
    if (s > fmi2Warning) {
        fprintf(stderr, "%s returned status %d\n", what, (int)s);
        return 0;
    }
    return 1;
}

typedef struct {
    Api api;
    const char *uri, *id, *guid;
    double h;
    size_t n, n_in, n_out, n_int;
    fmi2ValueReference in[MAX_VARS], out[MAX_VARS], ints[MAX_VARS];
    double *rows;
    size_t passes; /* bench: the rows are run this many times per timing */
} Run;

static fmi2Component start(const Run *r)
{
    const Api *a = &r->api;
    fmi2Component c = a->instantiate(r->id, fmi2CoSimulation, r->guid, r->uri, &callbacks, fmi2False, fmi2False);
    if (c == NULL) {
        fprintf(stderr, "fmi2Instantiate returned NULL\n");
        exit(1);
    }
    int ok = check(a->setup(c, fmi2False, 0.0, 0.0, fmi2False, 0.0), "fmi2SetupExperiment")
             && check(a->enter_init(c), "fmi2EnterInitializationMode")
             && check(a->set_real(c, r->in, r->n_in, r->rows), "fmi2SetReal")
             && check(a->exit_init(c), "fmi2ExitInitializationMode");
    if (!ok) exit(1);
    return c;
}

static int print_outputs(const Run *r, fmi2Component c)
{
    double y[MAX_VARS];
    fmi2Integer yi[MAX_VARS];
    if (!check(r->api.get_real(c, r->out, r->n_out, y), "fmi2GetReal")
        || !check(r->api.get_integer(c, r->ints, r->n_int, yi), "fmi2GetInteger"))
        return 0;
    for (size_t j = 0; j < r->n_out; j++) printf("%s%.17g", j ? " " : "", y[j]);
    for (size_t j = 0; j < r->n_int; j++) printf("%s%d", (j || r->n_out) ? " " : "", (int)yi[j]);
    printf("\n");
    return 1;
}

static int run(const Run *r)
{
    const Api *a = &r->api;
    fmi2Component c = start(r);
    int ok = print_outputs(r, c);
    for (size_t k = 0; ok && k < r->n; k++) {
        ok = check(a->set_real(c, r->in, r->n_in, r->rows + k * r->n_in), "fmi2SetReal")
             && check(a->do_step(c, (double)k * r->h, r->h, fmi2True), "fmi2DoStep") && print_outputs(r, c);
    }
    a->terminate(c);
    a->free_instance(c);
    return ok;
}

static int by_value(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* ns per step over `repeats` fresh instances, sorted (best first); full: set + step + get, else
 * doStep alone */
static void time_steps(const Run *r, int full, int repeats, double *times)
{
    const Api *a = &r->api;
    double y[MAX_VARS];
    fmi2Integer yi[MAX_VARS];
    size_t total = r->n * r->passes;
    for (int rep = 0; rep < repeats; rep++) {
        fmi2Component c = start(r);
        int bad = 0;
        if (!full) bad |= a->set_real(c, r->in, r->n_in, r->rows + (r->n - 1) * r->n_in) > fmi2Warning;
        double t0 = now_ns();
        for (size_t k = 0, row = 0; k < total; k++, row = (row + 1 == r->n) ? 0 : row + 1) {
            if (full) {
                bad |= a->set_real(c, r->in, r->n_in, r->rows + row * r->n_in) > fmi2Warning;
                bad |= a->do_step(c, (double)k * r->h, r->h, fmi2True) > fmi2Warning;
                bad |= a->get_real(c, r->out, r->n_out, y) > fmi2Warning;
                bad |= a->get_integer(c, r->ints, r->n_int, yi) > fmi2Warning;
            } else {
                bad |= a->do_step(c, (double)k * r->h, r->h, fmi2True) > fmi2Warning;
            }
        }
        times[rep] = (now_ns() - t0) / (double)total;
        a->terminate(c);
        a->free_instance(c);
        if (bad) {
            fprintf(stderr, "a call failed while timing\n");
            exit(1);
        }
    }
    qsort(times, (size_t)repeats, sizeof *times, by_value);
}

int main(int argc, char **argv)
{
    if (argc < 11) {
        fprintf(stderr, "usage: %s run|bench LIBPYTHON DIR ID GUID H N IN_VRS OUT_VRS INT_VRS [REPEATS]\n", argv[0]);
        return 2;
    }
    const char *mode = argv[1], *libpython = argv[2], *dir = argv[3];
    Run r;
    memset(&r, 0, sizeof r);
    r.id = argv[4];
    r.guid = argv[5];
    r.h = atof(argv[6]);
    r.n = (size_t)strtoul(argv[7], NULL, 10);
    r.n_in = parse_vrs(argv[8], r.in);
    r.n_out = parse_vrs(argv[9], r.out);
    r.n_int = parse_vrs(argv[10], r.ints);
    int repeats = argc > 11 ? atoi(argv[11]) : 5;
    if (r.n == 0 || !(r.h > 0) || repeats < 1) {
        fprintf(stderr, "N, H and REPEATS must be positive\n");
        return 2;
    }
    if (strcmp(libpython, "none") != 0 && dlopen(libpython, RTLD_NOW | RTLD_GLOBAL) == NULL) {
        fprintf(stderr, "dlopen %s: %s\n", libpython, dlerror());
        return 2;
    }
    r.rows = (double *)malloc(sizeof(double) * r.n * (r.n_in ? r.n_in : 1));
    for (size_t i = 0; i < r.n * r.n_in; i++)
        if (scanf("%lf", &r.rows[i]) != 1) {
            fprintf(stderr, "stdin: expected %zu input values, got %zu\n", r.n * r.n_in, i);
            return 2;
        }
    char path[4096], uri[4200];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", dir, r.id);
    snprintf(uri, sizeof uri, "file://%s/resources", dir);
    r.uri = uri;
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (lib == NULL) {
        fprintf(stderr, "dlopen %s: %s\n", path, dlerror());
        return 2;
    }
    Api *a = &r.api;
    *(void **)&a->instantiate = sym(lib, "fmi2Instantiate");
    *(void **)&a->free_instance = sym(lib, "fmi2FreeInstance");
    *(void **)&a->setup = sym(lib, "fmi2SetupExperiment");
    *(void **)&a->enter_init = sym(lib, "fmi2EnterInitializationMode");
    *(void **)&a->exit_init = sym(lib, "fmi2ExitInitializationMode");
    *(void **)&a->terminate = sym(lib, "fmi2Terminate");
    *(void **)&a->set_real = sym(lib, "fmi2SetReal");
    *(void **)&a->get_real = sym(lib, "fmi2GetReal");
    *(void **)&a->get_integer = sym(lib, "fmi2GetInteger");
    *(void **)&a->do_step = sym(lib, "fmi2DoStep");
    int ok = 1;
    if (strcmp(mode, "run") == 0) {
        ok = run(&r);
    } else if (strcmp(mode, "bench") == 0) {
        double *full = (double *)malloc(sizeof(double) * (size_t)repeats);
        double *step = (double *)malloc(sizeof(double) * (size_t)repeats);
        r.passes = 1;
        time_steps(&r, 1, 1, full); /* one pass: how many make a timing of about TIMING_NS */
        double passes = TIMING_NS / (full[0] * (double)r.n);
        r.passes = passes < 1.0 ? 1 : passes > 1e4 ? 10000 : (size_t)passes;
        time_steps(&r, 1, repeats, full);
        time_steps(&r, 0, repeats, step);
        printf("{\"ns_per_step_with_io\": %.6g, \"ns_per_doStep\": %.6g, \"median_ns_per_step_with_io\": %.6g, "
               "\"median_ns_per_doStep\": %.6g, \"steps_per_timing\": %zu, \"repeats\": %d}\n", full[0], step[0],
               full[repeats / 2], step[repeats / 2], r.n * r.passes, repeats);
        free(full);
        free(step);
    } else {
        fprintf(stderr, "unknown mode %s\n", mode);
        return 2;
    }
    free(r.rows);
    fflush(stdout);
    /* no dlclose: a pythonfmu library cannot be unloaded (see latobs.fmu_src.framework) */
    return ok ? 0 : 1;
}
