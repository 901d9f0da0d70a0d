/*
 * motorcycle_fault_observer.c - paper 003's switched PI observer (motorcycle roll angle and rider torque),
 * eq. (13); the native twin of fmu_src/motorcycle_fault_observer.py (same clamps, warnings, start and
 * discretisation). C99, libc and libm only.
 *
 * States x^ (5: vy, yaw rate, roll rate, steer angle, steer rate) and f^ (2: roll angle phi, rider
 * torque tau); u = 0 (torque not measured):
 *     x^' = A_s x^ + L_P,s (y - C x^) + E_f,s f^
 *     f^' = L_I,s (y - C x^)                                          (eq. 13)
 * written with s = [x^; f^] as s' = M_s s + G_s y (model_data.h: OBS_M, OBS_G of mode s).
 *
 * Co-simulation: y held over a step, the exact step s+ = Phi s + Gam y with [Phi | Gam] the top rows
 * of expm(h [[M_s, G_s], [0, 0]]) (Van Loan; la_zoh_map, the algorithm of fmu_src/linalg.py). The
 * maps of the default step OBS_H0 come from the emitter (the Python runtime's own maps); for another
 * step h they are computed at the first step of each mode with that h and cached in the instance
 * (one h at a time). Outputs (eq. 14 for the residual):
 *     roll_angle_hat = phi^, rider_torque_hat = tau^, vy_hat, steer_rate_hat,
 *     [Ff_hat, Fr_hat] = H_x x^ + H_phi phi^ (no Gamma), residual_norm = |y - C x^|_2, mode (1-based).
 * Clamps: |vx| < vx_hold freezes the observer (estimates held, one warning per entry, one at the
 * resumption); outside the design grid the nearest mode (one warning per excursion); the active
 * mode is kept while vx is in its band widened by the hysteresis; the start (model_initialize, or
 * else the first step) sets x^ = C' y, f^ = 0 and the mode of the initial speed.
 *
 * A measured-speed design (OBS_MEASURED 1: the roll angle a state, a PMI torque, synthesis/
 * motorcycle_fault_observer_lpv.py) has M(v) = M + v M_vx + M_ivx / v (G, F likewise) at the model
 * speed v, the measured vx clamped to the band's OBS_VX_RANGE; its step map is computed at each step
 * with la_zoh_map (reused while mode, v and h repeat), F(v) at the last step's v.
 *
 * ModelExchange: the continuous states are s (7, or 6 + the torque integrators), the derivatives eq. (13) at the current
 * (continuous) y; 0 while frozen. The discrete state (mode, frozen, outside the grid) changes
 * only in model_me_event_update, at the zero crossings of the event indicators
 *     z0 = vx - (edges[s] - hyst)       (s > 0; else 1)      the active mode's widened band
 *     z1 = (edges[s+1] + hyst) - vx     (s < last; else 1)
 *     z2 = |vx| - vx_hold                                    freeze / resume
 *     z3 = vx - edges[0], z4 = edges[last] - vx              the design grid (warning only)
 * with the co-simulation's rules, except that at an event a boundary reached counts as crossed
 * (see select_mode).
 */
#include <math.h>
#include <string.h>

#include "model.h"
#include "model_data.h"
#include "model_util.h"
#include "linalg.h"

#define NX OBS_NX                  /* x^ */
#define NS OBS_NS                  /* s = [x^; f^] */
#define NY OBS_NY                  /* y */
#define NW (OBS_NS + OBS_NY)       /* columns of a step map [Phi | Gam] */
#define N_MODES OBS_N_MODES

enum { S_VY, S_YAW_RATE, S_ROLL_RATE, S_STEER_ANGLE, S_STEER_RATE, S_PHI, S_TAU };  /* s = [x^; f^] (both designs) */

typedef const double MapRow[NW];   /* a row of a step map */

struct Model {
    double s[NS];                  /* [x^; f^] (SI units of STATES) */
    int mode;                      /* active mode, 0-based */
    int started;                   /* model_initialize (or the first step) has set s */
    int holding;                   /* |vx| < vx_hold: frozen */
    int outside;                   /* vx outside the design grid (warned) */
    double vx_hold;                /* m/s */
    double y[N_OUTPUTS];           /* co-simulation outputs */
    int yi[N_INT_OUTPUTS];
    double cache_h;                /* s, the step of the cached maps (0: none) */
    int cached[N_MODES];           /* cache[mode] holds the map of cache_h */
    double cache[N_MODES][NS][NW];
    double v;                      /* measured design: the model speed of the last step (m/s) */
    double cache_v;                /* measured design: cache[cache_mode] is the map at (cache_v, cache_h) */
    int cache_mode;
};

#if OBS_MEASURED
/* M + v M_vx + (1/v) M_ivx for an r x c coefficient triple, entry by entry (the runtime's _at) */
static void at_speed(int r, int c, const double *M0, const double *M1, const double *M2, double v, double *out)
{
    double w = 1.0 / v;
    for (int i = 0; i < r * c; i++) out[i] = M0[i] + v * M1[i] + w * M2[i];
}

/* the model speed of `mode`: vx clamped to the band's range */
static double model_speed(int mode, double vx)
{
    double lo = OBS_VX_RANGE[mode][0], hi = OBS_VX_RANGE[mode][1];
    return !(vx >= lo) ? lo : (vx > hi ? hi : vx);
}
#endif

size_t model_size(void)
{
    return sizeof(Model);
}

static void measurements(const double *u, double y[NY])
{
    y[0] = u[IN_steer_angle];
    y[1] = u[IN_yaw_rate];
    y[2] = u[IN_roll_rate];
}

/* the outputs of state s in mode `mode` with measurement y (the runtime's _publish) */
static void outputs_of(const double s[NS], int mode, double v, const double y[NY], double *out, int *outi)
{
    double res = 0.0;
    for (int r = 0; r < NY; r++) {
        double e = y[r] - dot_from(0.0, OBS_C[mode][r], s, NX);
        res += e * e;
    }
    out[OUT_roll_angle_hat] = s[S_PHI];
    out[OUT_rider_torque_hat] = s[S_TAU];
    out[OUT_vy_hat] = s[S_VY];
    out[OUT_steer_rate_hat] = s[S_STEER_RATE];
#if OBS_MEASURED
    double F[2][NS];
    at_speed(2, NS, &OBS_F[mode][0][0], &OBS_F_VX[mode][0][0], &OBS_F_IVX[mode][0][0], v, &F[0][0]);
    out[OUT_Ff_hat] = dot_from(0.0, F[0], s, NS);
    out[OUT_Fr_hat] = dot_from(0.0, F[1], s, NS);
#else
    (void)v;
    out[OUT_Ff_hat] = dot_from(0.0, OBS_F[mode][0], s, NS);
    out[OUT_Fr_hat] = dot_from(0.0, OBS_F[mode][1], s, NS);
#endif
    out[OUT_residual_norm] = sqrt(res);
    outi[INT_mode] = mode + 1;
}

static void publish(Model *m, const double y[NY])
{
    outputs_of(m->s, m->mode, m->v, y, m->y, m->yi);
}

/* The discrete rules (the runtime's) take a flag `me`: 0 in co-simulation; 1 at a ModelExchange
 * event, where the indicator that fired may be exactly 0 (CVode reports a root where the indicator
 * is 0 or has changed sign): the boundary of the state being left then counts as crossed, else the
 * state would be kept at the root and the crossing lost (the indicator goes on from 0, with no
 * further sign change). The rules differ from the runtime's only at the boundary values. */

/* the band of vx: [edges[i], edges[i+1]) (bisect_right(edges, vx) - 1), the nearest band outside
 * the grid; left_limit: (edges[i], edges[i+1]], the band vx is reached in from above */
static int band_of(double vx, int left_limit)
{
    int i = -1;
    while (i + 1 <= N_MODES && (left_limit ? OBS_EDGES[i + 1] < vx : OBS_EDGES[i + 1] <= vx)) i++;
    if (i < 0) return 0;
    return i < N_MODES - 1 ? i : N_MODES - 1;
}

/* the mode of speed vx: the active one while vx is inside its band widened by the hysteresis
 * [lo, hi) (me: (lo, hi)), else the nearest grid speed */
static int select_mode(const Model *m, double vx, int me)
{
    int cur = m->mode;
    double lo = cur > 0 ? OBS_EDGES[cur] - OBS_HYST : -INFINITY;
    double hi = cur < N_MODES - 1 ? OBS_EDGES[cur + 1] + OBS_HYST : INFINITY;
    if ((me ? lo < vx : lo <= vx) && vx < hi) return cur;
    return band_of(vx, me && vx <= lo);
}

/* the out-of-grid warning, once per excursion; inside: [edges[0], edges[last]] (me, while inside:
 * the open interval) */
static void check_grid(Model *m, double vx, int me, const Log *log)
{
    double lo = OBS_EDGES[0], hi = OBS_EDGES[N_MODES];
    int inside = me && !m->outside ? lo < vx && vx < hi : lo <= vx && vx <= hi;
    if (inside) {
        m->outside = 0;
        return;
    }
    if (!m->outside)
        log_event(log, LOG_WARNING, "vx = %.4g m/s outside the design grid [%.4g, %.4g] m/s: the nearest mode (%d) "
                  "is used", vx, lo, hi, select_mode(m, vx, me) + 1);
    m->outside = 1;
}

/* x^(0) = C' y(0) (the measured states; C of the first mode, as the runtime), f^(0) = 0, the mode
 * of the initial speed */
static void start(Model *m, const double *u, const Log *log)
{
    double y[NY];
    measurements(u, y);
    for (int j = 0; j < NX; j++) {
        double acc = 0.0;
        for (int r = 0; r < NY; r++) acc += OBS_C[0][r][j] * y[r];
        m->s[j] = acc;
    }
    for (int j = NX; j < NS; j++) m->s[j] = 0.0;
    m->started = 1;
    double vx = u[IN_vx];
    if (fabs(vx) >= m->vx_hold) {
        m->mode = band_of(vx, 0);           /* no active mode yet: no hysteresis */
        check_grid(m, vx, 0, log);
    }
#if OBS_MEASURED
    m->v = model_speed(m->mode, fabs(vx) >= m->vx_hold ? vx : OBS_VX_RANGE[m->mode][0]);
#endif
    publish(m, y);
}

int model_setup(Model *m, const double *p, const Log *log)
{
    double hold = p[PAR_vx_hold];
    if (!(isfinite(hold) && hold >= 0.0)) {
        log_event(log, LOG_ERROR, "parameter vx_hold must be finite and >= 0 m/s, got %g", hold);
        return -1;
    }
    memset(m, 0, sizeof *m);
    m->vx_hold = hold;
    m->yi[INT_mode] = 1;
    return 0;
}

void model_initialize(Model *m, const double *u, const Log *log)
{
    start(m, u, log);
}

/* [Phi | Gam] of `mode` over h: the emitter's for the default step, else cached in the instance;
 * NULL if the map is not finite (h absurdly large) */
static MapRow *step_map(Model *m, int mode, double vx, double h)
{
#if OBS_MEASURED
    /* the map of s' = M(v) s + G(v) y at the model speed v, the last one reused */
    double v = model_speed(mode, vx);
    if (!(m->cache_h == h && m->cache_v == v && m->cache_mode == mode && m->cached[0])) {
        double M[NS][NS], G[NS][NY];
        at_speed(NS, NS, &OBS_M[mode][0][0], &OBS_M_VX[mode][0][0], &OBS_M_IVX[mode][0][0], v, &M[0][0]);
        at_speed(NS, NY, &OBS_G[mode][0][0], &OBS_G_VX[mode][0][0], &OBS_G_IVX[mode][0][0], v, &G[0][0]);
        m->cached[0] = 0;
        if (la_zoh_map(NS, NY, &M[0][0], &G[0][0], h, &m->cache[0][0][0]) != 0) return NULL;
        m->cache_h = h;
        m->cache_v = v;
        m->cache_mode = mode;
        m->cached[0] = 1;
    }
    return (MapRow *)m->cache[0];
#else
    (void)vx;
    if (h == OBS_H0) return OBS_MAP_H0[mode];
    if (h != m->cache_h) {
        m->cache_h = h;
        memset(m->cached, 0, sizeof m->cached);
    }
    if (!m->cached[mode]) {
        if (la_zoh_map(NS, NY, &OBS_M[mode][0][0], &OBS_G[mode][0][0], h, &m->cache[mode][0][0]) != 0) return NULL;
        m->cached[mode] = 1;
    }
    return (MapRow *)m->cache[mode];
#endif
}

/* frozen: |vx| < vx_hold (the runtime's -hold < vx < hold; me, while running: |vx| <= vx_hold) */
static int frozen_at(const Model *m, double vx, int me)
{
    return me && !m->holding ? fabs(vx) <= m->vx_hold : fabs(vx) < m->vx_hold;
}

/* the freeze and the resumption with their warnings; 1 if frozen */
static int update_hold(Model *m, double vx, int me, const Log *log)
{
    if (frozen_at(m, vx, me)) {
        if (!m->holding)
            log_event(log, LOG_WARNING, "|vx| = %.3g m/s < vx_hold = %g m/s: observer frozen, estimates held",
                      fabs(vx), m->vx_hold);
        m->holding = 1;
        return 1;
    }
    if (m->holding) log_event(log, LOG_WARNING, "vx = %.3g m/s: observer resumes", vx);
    m->holding = 0;
    return 0;
}

int model_do_step(Model *m, double h, const double *u, const Log *log)
{
    double vx = u[IN_vx], y[NY], v[NW];
    MapRow *W = NULL;
    if (!frozen_at(m, vx, 0)) {            /* the map first: a refused step changes nothing */
        W = step_map(m, m->started ? select_mode(m, vx, 0) : band_of(vx, 0), vx, h);   /* start's mode */
        if (W == NULL) {
            log_event(log, LOG_ERROR, "step refused: the step map over h = %g s is not finite", h);
            return -1;
        }
    }
    if (!m->started) start(m, u, log);
    measurements(u, y);
    if (update_hold(m, vx, 0, log)) {
        publish(m, y);
        return 0;
    }
    check_grid(m, vx, 0, log);
    m->mode = select_mode(m, vx, 0);
#if OBS_MEASURED
    m->v = model_speed(m->mode, vx);
#endif
    memcpy(v, m->s, sizeof m->s);
    memcpy(v + NS, y, sizeof y);
    for (int i = 0; i < NS; i++) m->s[i] = dot_from(0.0, W[i], v, NW);
    publish(m, y);
    return 0;
}

void model_outputs(const Model *m, double *y, int *yi)
{
    memcpy(y, m->y, sizeof m->y);
    memcpy(yi, m->yi, sizeof m->yi);
}

/* ------------------------------------------------------------------ model exchange */
void model_me_get_states(const Model *m, double *x)
{
    memcpy(x, m->s, sizeof m->s);
}

void model_me_set_states(Model *m, const double *x)
{
    memcpy(m->s, x, sizeof m->s);
}

void model_me_nominals(const Model *m, double *nominal)
{
    (void)m;
    for (int i = 0; i < NS; i++) nominal[i] = 1.0;
}

/* eq. (13): s' = M_s s + G_s y at the current (continuous) y; 0 while frozen */
void model_me_derivatives(const Model *m, const double *u, double *dx)
{
    double y[NY];
    measurements(u, y);
#if OBS_MEASURED
    double M[NS][NS], G[NS][NY], v = model_speed(m->mode, u[IN_vx]);
    at_speed(NS, NS, &OBS_M[m->mode][0][0], &OBS_M_VX[m->mode][0][0], &OBS_M_IVX[m->mode][0][0], v, &M[0][0]);
    at_speed(NS, NY, &OBS_G[m->mode][0][0], &OBS_G_VX[m->mode][0][0], &OBS_G_IVX[m->mode][0][0], v, &G[0][0]);
    for (int i = 0; i < NS; i++)
        dx[i] = m->holding ? 0.0 : dot_from(0.0, M[i], m->s, NS) + dot_from(0.0, G[i], y, NY);
#else
    for (int i = 0; i < NS; i++)
        dx[i] = m->holding ? 0.0 : dot_from(0.0, OBS_M[m->mode][i], m->s, NS) + dot_from(0.0, OBS_G[m->mode][i], y, NY);
#endif
}

void model_me_event_indicators(const Model *m, const double *u, double *z)
{
    double vx = u[IN_vx];
    z[0] = m->mode > 0 ? vx - (OBS_EDGES[m->mode] - OBS_HYST) : 1.0;
    z[1] = m->mode < N_MODES - 1 ? (OBS_EDGES[m->mode + 1] + OBS_HYST) - vx : 1.0;
    z[2] = fabs(vx) - m->vx_hold;
    z[3] = vx - OBS_EDGES[0];
    z[4] = OBS_EDGES[N_MODES] - vx;
}

/* the discrete part of a co-simulation step: the start, the freeze, the grid warning, the mode */
int model_me_event_update(Model *m, double t, const double *u, const Log *log)
{
    double vx = u[IN_vx];
    int changed = !m->started;
    (void)t;
    if (!m->started) start(m, u, log);
    if (update_hold(m, vx, 1, log)) return changed;
    check_grid(m, vx, 1, log);
    m->mode = select_mode(m, vx, 1);
    return changed;
}

void model_me_outputs(const Model *m, const double *u, double *y, int *yi)
{
    double meas[NY];
    measurements(u, meas);
#if OBS_MEASURED
    double v = m->holding ? m->v : model_speed(m->mode, u[IN_vx]);
#else
    double v = 0.0;
#endif
    outputs_of(m->s, m->mode, v, meas, y, yi);
}
