/* The co-simulation master's stepping loop (latobs/validation/master.py, CoSimulation), compiled:
 * for each communication point t_k, k = k0 .. k1-1, every FMU's inputs are set from row k of its
 * input matrices, every FMU is stepped from t_k by dt, every FMU's outputs are got into row k+1 of
 * its output matrices, then the observers' inputs of row k+1 are routed from the plant's outputs
 * of row k+1 (plus their measurement noise). The same FMI 2.0 calls, in the same order, on the
 * same matrices as the Python loop it replaces: the same results, bit for bit (tested).
 *
 * No maths but the noise addition; no allocation; the first call returning a status above
 * fmi2Warning stops the loop and is reported (the caller raises the harness's error for it). */
#include <stddef.h>
#include <stdint.h>

#if defined(_WIN32)
#define LATOBS_EXPORT __declspec(dllexport)
#else
#define LATOBS_EXPORT __attribute__((visibility("default")))
#endif

typedef int (*latobs_row_fn)(void *component, const unsigned int *vr, size_t n, void *values);
typedef int (*latobs_step_fn)(void *component, double t, double h, int no_set_fmu_state_prior);

/* an fmi2SetXxx or fmi2GetXxx call of one FMU and FMI type: row k of its values at row0 + k * stride (bytes) */
typedef struct {
    latobs_row_fn fn;
    void *component;
    const unsigned int *vr;
    size_t n;
    char *row0;
    ptrdiff_t stride;
} LatobsRow;

/* fmi2DoStep of one FMU */
typedef struct {
    latobs_step_fn fn;
    void *component;
} LatobsStep;

/* Real inputs of one observer from the plant's Real outputs: dst[k, dst_cols[i]] =
 * src[k, src_cols[i]] (+ noise[k, i] when noise is not NULL); strides in bytes */
typedef struct {
    char *dst;
    ptrdiff_t dst_stride;
    const intptr_t *dst_cols;
    const char *src;
    ptrdiff_t src_stride;
    const intptr_t *src_cols;
    const char *noise;
    ptrdiff_t noise_stride;
    size_t n;
} LatobsRoute;

/* what failed: 0 setting inputs, 1 doStep, 2 getting outputs */
enum { LATOBS_SET = 0, LATOBS_STEP = 1, LATOBS_GET = 2 };

/* Returns -1 when every step was made, else the k at which a call failed, with *what (above),
 * *which (its index in sets, steps or gets) and *status (the call's fmi2Status). */
LATOBS_EXPORT long latobs_master_loop(long k0, long k1, const double *t, double dt,
                                      const LatobsRow *sets, long n_sets, const LatobsStep *steps, long n_steps,
                                      const LatobsRow *gets, long n_gets, const LatobsRoute *routes, long n_routes,
                                      int *what, long *which, int *status)
{
    for (long k = k0; k < k1; k++) {
        const double tk = t[k];
        for (long i = 0; i < n_sets; i++) {
            const LatobsRow *r = &sets[i];
            int st = r->fn(r->component, r->vr, r->n, r->row0 + k * r->stride);
            if (st > 1) { *what = LATOBS_SET; *which = i; *status = st; return k; }
        }
        for (long i = 0; i < n_steps; i++) {
            int st = steps[i].fn(steps[i].component, tk, dt, 1);
            if (st > 1) { *what = LATOBS_STEP; *which = i; *status = st; return k; }
        }
        for (long i = 0; i < n_gets; i++) {
            const LatobsRow *r = &gets[i];
            int st = r->fn(r->component, r->vr, r->n, r->row0 + (k + 1) * r->stride);
            if (st > 1) { *what = LATOBS_GET; *which = i; *status = st; return k; }
        }
        for (long i = 0; i < n_routes; i++) {
            const LatobsRoute *r = &routes[i];
            double *dst = (double *)(r->dst + (k + 1) * r->dst_stride);
            const double *src = (const double *)(r->src + (k + 1) * r->src_stride);
            if (r->noise) {
                const double *nz = (const double *)(r->noise + (k + 1) * r->noise_stride);
                for (size_t j = 0; j < r->n; j++) dst[r->dst_cols[j]] = src[r->src_cols[j]] + nz[j];
            } else {
                for (size_t j = 0; j < r->n; j++) dst[r->dst_cols[j]] = src[r->src_cols[j]];
            }
        }
    }
    return -1;
}
