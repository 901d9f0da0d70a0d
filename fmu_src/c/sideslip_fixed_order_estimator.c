/*
 * sideslip_fixed_order_estimator.c - paper 002's transfer-function sideslip estimator (Delibasi 2014),
 * beta^ = (y(s)/x(s)) r, one estimator or one per speed band; the native twin of
 * fmu_src/sideslip_fixed_order_estimator.py (same clamps, warnings, start and discretisation). C99, libc and libm.
 *
 * Realisation (controllable canonical form, model_data.h per band i): with x(s) monic,
 *     z' = A_i z + B_i r,  A_i companion (last row -a_0 .. -a_(n-1)), B_i = e_n,
 *     beta^ = C_i z + D_i r,  C_k = b_k - b_n a_k,  D = b_n.
 *
 * Co-simulation: r held over a step, the exact step z+ = Phi z + Gam r with [Phi | Gam] the top
 * rows of expm(h [[A, B], [0, 0]]) (Van Loan; la_zoh_map, the algorithm of fmu_src/linalg.py).
 * The maps of the default step TF_H0 come from the emitter (the Python runtime's own maps); for
 * another step h they are computed at the first step of each band with that h and cached in the
 * instance (one h at a time). After a step, beta^ = C z(t+h) + D r with the step's held r.
 * The sums run left to right from the same first term as the runtime's sum(...) (Python 3.11), so
 * at the default step the outputs equal the Python FMU's bit for bit.
 *
 * Clamps and warnings (as the runtime):
 *   - the start (model_initialize, or else the first step): steady state for the yaw rate,
 *     z = [r / a_0, 0, .., 0] (a_0 > 0: x(s) is Hurwitz), so beta^ = (y_0/x_0) r; the band of vx;
 *   - speed scheduling: band i for edges[i] <= vx < edges[i+1] (the last band up to its upper
 *     edge included); outside the grid the nearest band, one warning per excursion; switching
 *     is bumpless (z kept); a model file without a vx input keeps the first band;
 *   - a step whose result is not finite (an absurd h): refused with a warning, z held (the band
 *     already switched, as the runtime does).
 * The layer refuses a non-finite input or h <= 0 before any call.
 *
 * ModelExchange (n >= 1): the continuous states are z (n), z' = A_i z + B_i r at the current
 * (continuous) r; beta^ = C_i z + D_i r. The band i is the discrete state: it changes only in
 * model_me_event_update, at the zero crossings of the event indicators (scheduled data only)
 *     z0 = vx - edges[i]-       (i > 0; else 1)        the active band's lower edge
 *     z1 = edges[i+1] - vx      (i < last; else 1)     its upper edge
 *     z2 = vx - edges[0]-, z3 = edges[last]+ - vx      the grid's ends (the warning only; from
 *                                                      outside edges[0] and edges[last])
 * where e- / e+ is the double just below / above e (model_me_event_indicators says why).
 * An n = 0 estimator (a static gain) has no state and is co-simulation only.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model.h"
#include "model_data.h"
#include "model_util.h"
#include "linalg.h"

#define N TF_N                     /* estimator order (states) */
#define NW (TF_DIM + 1)            /* columns of a step map [Phi | Gam] */
#define N_MODES TF_N_MODES
#define N_INTS (N_INT_OUTPUTS > 0 ? N_INT_OUTPUTS : 1)

#ifdef IN_vx
#define HAS_VX 1                   /* the speed-scheduled model file: the band follows vx */
#else
#define HAS_VX 0
#endif

#if N_STATES != N || (N_EVENT_INDICATORS != 0 && N_EVENT_INDICATORS != 4)
#error "fmu_config.h does not match the sideslip_fixed_order_estimator emitter's states and event indicators"
#endif

struct Model {
    double z[TF_DIM];              /* estimator state (z_k in rad s^(n-k)) */
    int mode;                      /* active band, 0-based */
    int started;                   /* model_initialize (or the first step) has set z */
    int outside;                   /* vx below (-1) or above (+1) the scheduling grid (warned), else 0 */
    double y[N_OUTPUTS];           /* co-simulation outputs */
    int yi[N_INTS];
    double cache_h;                /* s, the step of the cached maps (0: none) */
    int cached[N_MODES];           /* phi[mode], gam[mode] hold the map of cache_h */
    double phi[N_MODES][TF_DIM][TF_DIM];
    double gam[N_MODES][TF_DIM];
};

size_t model_size(void)
{
    return sizeof(Model);
}

/* beta^ = C z + D r of band `mode` (the runtime's _publish) */
static void outputs_of(const double *z, int mode, double r, double *out, int *outi)
{
    out[OUT_beta_hat] = dot_from(TF_D[mode] * r, TF_C[mode], z, N);
#ifdef INT_mode
    outi[INT_mode] = mode + 1;
#else
    (void)outi;
#endif
}

static void publish(Model *m, double r)
{
    outputs_of(m->z, m->mode, r, m->y, m->yi);
}

/* band i with edges[i] <= vx < edges[i+1] (the last band up to its upper edge); outside the grid
 * the nearest band, one warning per excursion (the runtime's _band) */
static int band(Model *m, double vx, const Log *log)
{
    const double lo = TF_EDGES[0], hi = TF_EDGES[N_MODES];
    if (lo <= vx && vx <= hi) {
        int i = 0;
        m->outside = 0;
        while (i < N_MODES - 1 && vx >= TF_EDGES[i + 1]) i++;
        return i;
    }
    if (!m->outside)
        log_event(log, LOG_WARNING, "vx = %.4g m/s outside the scheduling grid [%.4g, %.4g] m/s: the nearest "
                  "band's estimator is used", vx, lo, hi);
    m->outside = vx < lo ? -1 : 1;
    return vx < lo ? 0 : N_MODES - 1;
}

/* the band of the inputs u; the current one when the model file has no vx input */
static int band_of(Model *m, const double *u, const Log *log)
{
#if HAS_VX
    return band(m, u[IN_vx], log);
#else
    (void)u, (void)log, (void)band;
    return m->mode;
#endif
}

/* steady state for the current yaw rate, z = [r / a_0, 0, .., 0], in the band of vx */
static void start(Model *m, const double *u, const Log *log)
{
    double r = u[IN_yaw_rate];
    m->mode = band_of(m, u, log);
    for (int k = 0; k < N; k++) m->z[k] = k == 0 ? r / TF_A0[m->mode] : 0.0;
    m->started = 1;
    publish(m, r);
}

int model_setup(Model *m, const double *p, const Log *log)
{
    (void)p, (void)log;            /* no parameters: the estimators are the certified design */
    memset(m, 0, sizeof *m);
#ifdef INT_mode
    m->yi[INT_mode] = 1;
#endif
    return 0;
}

void model_initialize(Model *m, const double *u, const Log *log)
{
    start(m, u, log);
}

/* Phi, Gam of `mode` over h: the emitter's for the default step, else computed once per band
 * and h and cached in the instance. 0, or -1 if the map is not finite (h absurdly large). */
static int step_map(Model *m, int mode, double h, const double (**Phi)[TF_DIM], const double **Gam)
{
    if (h == TF_H0) {
        *Phi = TF_PHI_H0[mode];
        *Gam = TF_GAM_H0[mode];
        return 0;
    }
    if (h != m->cache_h) {
        m->cache_h = h;
        memset(m->cached, 0, sizeof m->cached);
    }
    if (!m->cached[mode]) {
        double E[TF_DIM * NW];                 /* [Phi | Gam], n rows of n + 1 */
        if (la_zoh_map(N, 1, &TF_A[mode][0][0], TF_B[mode], h, E) != 0) return -1;
        for (int i = 0; i < N; i++) {
            memcpy(m->phi[mode][i], E + i * (N + 1), sizeof(double) * N);
            m->gam[mode][i] = E[i * (N + 1) + N];
        }
        m->cached[mode] = 1;
    }
    *Phi = (const double (*)[TF_DIM])m->phi[mode];
    *Gam = m->gam[mode];
    return 0;
}

/* z+ = Phi z + Gam r over h in the band of vx; 0, or -1 if the result is not finite (z kept) */
static int advance(Model *m, double h, double r)
{
    const double (*Phi)[TF_DIM], *Gam;
    double zn[TF_DIM];
    if (step_map(m, m->mode, h, &Phi, &Gam) != 0) return -1;
    for (int i = 0; i < N; i++) {
        zn[i] = dot_from(Gam[i] * r, Phi[i], m->z, N);
        if (!isfinite(zn[i])) return -1;
    }
    memcpy(m->z, zn, sizeof(double) * N);
    return 0;
}

int model_do_step(Model *m, double h, const double *u, const Log *log)
{
    double r = u[IN_yaw_rate];
    if (!m->started) start(m, u, log);
    m->mode = band_of(m, u, log);              /* bumpless: z is kept as it is */
    if (N > 0 && advance(m, h, r) != 0) {
        char text[32];
        log_event(log, LOG_WARNING, "the step map over h = %s s is not finite: step refused, state held",
                  py_repr(h, text));
        return 0;
    }
    publish(m, r);
    return 0;
}

void model_outputs(const Model *m, double *y, int *yi)
{
    memcpy(y, m->y, sizeof m->y);
    memcpy(yi, m->yi, sizeof(int) * N_INT_OUTPUTS);
}

/* ------------------------------------------------------------------ model exchange */
#if N_STATES > 0
void model_me_get_states(const Model *m, double *x)
{
    memcpy(x, m->z, sizeof(double) * N);
}

void model_me_set_states(Model *m, const double *x)
{
    memcpy(m->z, x, sizeof(double) * N);
}

/* |z_k| per rad/s of yaw rate (the emitter's TF_NOMINAL) */
void model_me_nominals(const Model *m, double *nominal)
{
    (void)m;
    memcpy(nominal, TF_NOMINAL, sizeof(double) * N);
}

/* z' = A_i z + B_i r at the current (continuous) r */
void model_me_derivatives(const Model *m, const double *u, double *dx)
{
    for (int i = 0; i < N; i++)
        dx[i] = dot_from(TF_B[m->mode][i] * u[IN_yaw_rate], TF_A[m->mode][i], m->z, N);
}

/* Each indicator's zero lies on the first double of the region it leads into, so that at a
 * root (CVode stops where the indicator is <= 0 after a sign change, often exactly 0) band()
 * already gives the new band: band i holds edges[i] <= vx < edges[i+1], hence the lower edge's
 * zero is at the largest double below edges[i] (a root exactly on edges[i] would keep band i
 * and the crossing would be lost), the upper edge's at edges[i+1] itself; the grid's ends
 * likewise, from inside (edges[0] <= vx <= edges[last]) and from outside. */
void model_me_event_indicators(const Model *m, const double *u, double *z)
{
#if N_EVENT_INDICATORS > 0
    const int i = m->mode;
#if HAS_VX
    const double vx = u[IN_vx];
    z[0] = i > 0 ? vx - nextafter(TF_EDGES[i], -INFINITY) : 1.0;
    z[1] = i < N_MODES - 1 ? TF_EDGES[i + 1] - vx : 1.0;
    z[2] = vx - (m->outside < 0 ? TF_EDGES[0] : nextafter(TF_EDGES[0], -INFINITY));
    z[3] = (m->outside > 0 ? TF_EDGES[N_MODES] : nextafter(TF_EDGES[N_MODES], INFINITY)) - vx;
#else
    (void)i, (void)u;
    for (int k = 0; k < N_EVENT_INDICATORS; k++) z[k] = 1.0;   /* no vx: the band never changes */
#endif
#else
    (void)m, (void)u, (void)z;
#endif
}

/* the discrete part of a co-simulation step: the start, the band (with its warning) */
int model_me_event_update(Model *m, double t, const double *u, const Log *log)
{
    int changed = !m->started;
    (void)t;
    if (!m->started) start(m, u, log);
    m->mode = band_of(m, u, log);
    return changed;
}

void model_me_outputs(const Model *m, const double *u, double *y, int *yi)
{
    outputs_of(m->z, m->mode, u[IN_yaw_rate], y, yi);
}
#endif
