/*
 * guard_host.c - a plain C FMI 2.0 host for tests/cbackend/test_guard.py.
 *
 * Loads an extracted FMU's binaries/linux64/<id>.so (the latobs guard) with
 * dlopen, like a simulation tool would, and checks the guard's behaviour.
 * pythonfmu's library needs libpython's symbols in the global scope, so the
 * host first dlopens libpython with RTLD_GLOBAL (path given on the command line;
 * "none" skips it, to show what a host that does not preload libpython gets).
 *
 * usage: guard_host LIBPYTHON MODE ID GUID IN_VRS OUT_VR DIR...
 *   IN_VRS: comma-separated Real input vrs, all set to 20 before every step
 *   MODE wrongguid  instantiate with the real library missing, a wrong guid, a NULL guid,
 *                   model exchange, NULL callbacks: each NULL (with an error logged),
 *                   then the right guid: runs
 *   MODE unknownvr  10 fmi2GetReal + 10 fmi2SetReal on vr 9999: each fmi2Error with a
 *                   logged error; then set IN_VRS, fmi2DoStep, get OUT_VR must work
 *   MODE reload     for each DIR: load, instantiate, run, free, dlclose, delete DIR
 *   MODE nopython   (with LIBPYTHON "none") the right guid is refused: NULL, with the loader's
 *                   error (libpython's symbols are missing) logged
 * Prints one line per check; exits 0 only if every check passed.
 */
#define _XOPEN_SOURCE 700 /* nftw */

#include <dlfcn.h>
#include <ftw.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

static int failures;
static int n_errors_logged;
static char last_message[2048];

#define CHECK(cond, ...)                                             \
    do {                                                             \
        if (cond) {                                                  \
            printf("ok   ");                                         \
        } else {                                                     \
            printf("FAIL ");                                         \
            failures++;                                              \
        }                                                            \
        printf(__VA_ARGS__);                                         \
        printf("\n");                                                \
        fflush(stdout);                                              \
    } while (0)

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                   fmi2String category, fmi2String message, ...)
{
    va_list ap;
    (void)env;
    va_start(ap, message);
    vsnprintf(last_message, sizeof last_message, message, ap);
    va_end(ap);
    if (status == fmi2Error) n_errors_logged++;
    printf("log  [%s] status=%d category=%s: %s\n", instance ? instance : "?", (int)status,
           category ? category : "", last_message);
    fflush(stdout);
}

static const fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};

typedef struct {
    void *handle;
    fmi2InstantiateTYPE *instantiate;
    fmi2FreeInstanceTYPE *freeInstance;
    fmi2SetupExperimentTYPE *setupExperiment;
    fmi2EnterInitializationModeTYPE *enterInit;
    fmi2ExitInitializationModeTYPE *exitInit;
    fmi2TerminateTYPE *terminate;
    fmi2GetRealTYPE *getReal;
    fmi2SetRealTYPE *setReal;
    fmi2DoStepTYPE *doStep;
} Fmu;

static void *sym(void *handle, const char *name)
{
    void *p = dlsym(handle, name);
    if (p == NULL) {
        printf("FAIL dlsym %s: %s\n", name, dlerror());
        exit(2);
    }
    return p;
}

static void load(Fmu *f, const char *dir, const char *id)
{
    char path[4096];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", dir, id);
    f->handle = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (f->handle == NULL) {
        printf("FAIL dlopen %s: %s\n", path, dlerror());
        exit(2);
    }
    *(void **)&f->instantiate = sym(f->handle, "fmi2Instantiate");
    *(void **)&f->freeInstance = sym(f->handle, "fmi2FreeInstance");
    *(void **)&f->setupExperiment = sym(f->handle, "fmi2SetupExperiment");
    *(void **)&f->enterInit = sym(f->handle, "fmi2EnterInitializationMode");
    *(void **)&f->exitInit = sym(f->handle, "fmi2ExitInitializationMode");
    *(void **)&f->terminate = sym(f->handle, "fmi2Terminate");
    *(void **)&f->getReal = sym(f->handle, "fmi2GetReal");
    *(void **)&f->setReal = sym(f->handle, "fmi2SetReal");
    *(void **)&f->doStep = sym(f->handle, "fmi2DoStep");
}

static fmi2Component instantiate(Fmu *f, const char *dir, const char *guid)
{
    char uri[4200];
    snprintf(uri, sizeof uri, "file://%s/resources", dir);
    return f->instantiate("host", fmi2CoSimulation, guid, uri, &callbacks, fmi2False, fmi2False);
}

static fmi2ValueReference in_vrs[64];
static fmi2Real in_values[64];
static size_t n_in;

/* Initialise, set the inputs, take `steps` steps; returns 1 if every call returned fmi2OK. */
static int run(Fmu *f, fmi2Component c, fmi2ValueReference out_vr, int steps, double *out)
{
    int ok = f->setupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) == fmi2OK;
    ok = ok && f->enterInit(c) == fmi2OK && f->exitInit(c) == fmi2OK;
    for (int k = 0; ok && k < steps; k++) {
        ok = f->setReal(c, in_vrs, n_in, in_values) == fmi2OK
             && f->doStep(c, k * 0.005, 0.005, fmi2True) == fmi2OK
             && f->getReal(c, &out_vr, 1, out) == fmi2OK;
    }
    return ok;
}

static int rm_entry(const char *path, const struct stat *sb, int flag, struct FTW *ftw)
{
    (void)sb; (void)flag; (void)ftw;
    return remove(path);
}

/* Number of lines of /proc/self/maps naming a path that contains `needle`. */
static int mapped(const char *needle)
{
    char line[4096];
    int n = 0;
    FILE *fp = fopen("/proc/self/maps", "r");
    if (fp == NULL) return -1;
    while (fgets(line, sizeof line, fp))
        if (strstr(line, needle)) n++;
    fclose(fp);
    return n;
}

int main(int argc, char **argv)
{
    const char *mode, *id, *guid;
    fmi2ValueReference out_vr;
    char *p;
    Fmu f;
    double y = 0.0;

    if (argc < 8) {
        fprintf(stderr, "usage: %s LIBPYTHON MODE ID GUID IN_VRS OUT_VR DIR...\n", argv[0]);
        return 2;
    }
    if (strcmp(argv[1], "none") != 0 && dlopen(argv[1], RTLD_NOW | RTLD_GLOBAL) == NULL) {
        printf("FAIL dlopen %s: %s\n", argv[1], dlerror());
        return 2;
    }
    mode = argv[2];
    id = argv[3];
    guid = argv[4];
    for (p = argv[5]; *p && n_in < 64; p += (*p == ',')) {
        in_vrs[n_in] = (fmi2ValueReference)strtoul(p, &p, 10);
        in_values[n_in++] = 1.5; /* every input inside its declared range (angles up to pi/2) */
    }
    out_vr = (fmi2ValueReference)strtoul(argv[6], NULL, 10);

    if (strcmp(mode, "wrongguid") == 0) {
        char real[4200], moved[4300];
        load(&f, argv[7], id);
        /* first, before the real library was ever loaded: hide it */
        snprintf(real, sizeof real, "%s/binaries/linux64/%s_pythonfmu.so", argv[7], id);
        snprintf(moved, sizeof moved, "%s.away", real);
        n_errors_logged = 0;
        CHECK(rename(real, moved) == 0 && instantiate(&f, argv[7], guid) == NULL && n_errors_logged == 1
                  && strstr(last_message, "cannot load"),
              "real library missing: fmi2Instantiate returned NULL, dlopen error logged");
        CHECK(rename(moved, real) == 0, "real library restored");
        n_errors_logged = 0;
        fmi2Component c = instantiate(&f, argv[7], "{not-the-guid}");
        CHECK(c == NULL, "wrong guid: fmi2Instantiate returned NULL");
        CHECK(n_errors_logged == 1 && strstr(last_message, guid) && strstr(last_message, "{not-the-guid}"),
              "wrong guid: one error logged naming both guids");
        n_errors_logged = 0;
        c = instantiate(&f, argv[7], NULL);
        CHECK(c == NULL && n_errors_logged == 1, "NULL guid: refused with an error logged");
        n_errors_logged = 0;
        c = f.instantiate("host", fmi2ModelExchange, guid, "file:///nowhere", &callbacks, 0, 0);
        CHECK(c == NULL && n_errors_logged == 1, "model exchange: refused with an error logged");
        c = f.instantiate("host", fmi2CoSimulation, guid, "file:///nowhere", NULL, 0, 0);
        CHECK(c == NULL, "NULL callbacks: refused");
        c = instantiate(&f, argv[7], guid);
        CHECK(c != NULL, "right guid: instantiated");
        if (c) {
            CHECK(run(&f, c, out_vr, 5, &y), "right guid: 5 steps run");
            f.terminate(c);
            f.freeInstance(c);
        }
        CHECK(dlclose(f.handle) == 0, "dlclose");
    } else if (strcmp(mode, "nopython") == 0) {
        load(&f, argv[7], id);
        n_errors_logged = 0;
        fmi2Component c = instantiate(&f, argv[7], guid);
        CHECK(c == NULL && n_errors_logged == 1 && strstr(last_message, "undefined symbol: _Py"),
              "no libpython in the process: fmi2Instantiate returned NULL, loader error logged: %s",
              last_message);
        CHECK(dlclose(f.handle) == 0, "dlclose");
    } else if (strcmp(mode, "unknownvr") == 0) {
        fmi2ValueReference bad = 9999;
        fmi2Real v = 1.0;
        load(&f, argv[7], id);
        fmi2Component c = instantiate(&f, argv[7], guid);
        CHECK(c != NULL, "instantiated");
        if (c == NULL) return 1;
        CHECK(run(&f, c, out_vr, 1, &y), "initialised, 1 step");
        for (int i = 0; i < 10; i++) {
            n_errors_logged = 0;
            fmi2Status s = f.getReal(c, &bad, 1, &v);
            CHECK(s == fmi2Error && n_errors_logged == 1 && strstr(last_message, "9999"),
                  "fmi2GetReal(vr 9999) #%d -> status %d, error logged", i + 1, (int)s);
        }
        for (int i = 0; i < 10; i++) {
            n_errors_logged = 0;
            fmi2Status s = f.setReal(c, &bad, 1, &v);
            CHECK(s == fmi2Error && n_errors_logged == 1 && strstr(last_message, "9999"),
                  "fmi2SetReal(vr 9999) #%d -> status %d, error logged", i + 1, (int)s);
        }
        n_errors_logged = 0;
        CHECK(f.setReal(c, &out_vr, 1, &v) == fmi2Error && n_errors_logged == 1,
              "fmi2SetReal on the output vr %u refused", (unsigned)out_vr);
        CHECK(f.getReal(c, NULL, 1, &v) == fmi2Error, "fmi2GetReal with a NULL vr array refused");
        CHECK(f.getReal(c, &out_vr, 0, NULL) == fmi2OK, "fmi2GetReal with nvr = 0 forwarded");
        CHECK(f.setReal(c, in_vrs, n_in, in_values) == fmi2OK, "fmi2SetReal(inputs) after the errors");
        CHECK(f.doStep(c, 0.005, 0.005, fmi2True) == fmi2OK, "fmi2DoStep after the errors");
        y = -12345.0;
        CHECK(f.getReal(c, &out_vr, 1, &y) == fmi2OK && y != -12345.0 && y != 0.0,
              "fmi2GetReal(vr %u) after the errors = %g", (unsigned)out_vr, y);
        CHECK(f.terminate(c) == fmi2OK, "fmi2Terminate");
        f.freeInstance(c);
        CHECK(dlclose(f.handle) == 0, "dlclose");
    } else if (strcmp(mode, "reload") == 0) {
        for (int i = 7; i < argc; i++) {
            const char *dir = argv[i];
            load(&f, dir, id);
            fmi2Component c = instantiate(&f, dir, guid);
            CHECK(c != NULL, "cycle %d: instantiated from %s", i - 6, dir);
            if (c == NULL) return 1;
            y = -12345.0;
            CHECK(run(&f, c, out_vr, 20, &y) && y != -12345.0 && y != 0.0, "cycle %d: 20 steps, output %g", i - 6, y);
            fmi2Real v;
            fmi2ValueReference bad = 9999;
            CHECK(f.getReal(c, &bad, 1, &v) == fmi2Error, "cycle %d: unknown vr refused", i - 6);
            f.terminate(c);
            f.freeInstance(c);
            CHECK(dlclose(f.handle) == 0, "cycle %d: dlclose", i - 6);
            char guard[4200];
            snprintf(guard, sizeof guard, "%s/binaries/linux64/%s.so", dir, id);
            CHECK(mapped(guard) == 0, "cycle %d: guard library unmapped after dlclose", i - 6);
            CHECK(nftw(dir, rm_entry, 16, FTW_DEPTH | FTW_PHYS) == 0, "cycle %d: deleted %s", i - 6, dir);
            printf("info cycle %d: %d mappings of files in the deleted folder remain\n",
                   i - 6, mapped(dir));
        }
    } else {
        fprintf(stderr, "unknown mode %s\n", mode);
        return 2;
    }
    printf("%s: %d failure(s)\n", mode, failures);
    return failures == 0 ? 0 : 1;
}
