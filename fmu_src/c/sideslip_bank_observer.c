/*
 * sideslip_bank_observer.c - paper 000's switched H-infinity PI observer of sideslip and road bank angle
 * (Menhour, Koenig, d'Andrea-Novel, ECC 2014), eq. (5) written out with Pi = T A - K_P C; the
 * behaviour (clamps, warnings, start, input hold, discretisation) is specified in
 * docs/runtime/sideslip_bank_observer.md, and the Python reference fmu_src/sideslip_bank_observer.py gives
 * the same outputs bit for bit. C99, libc and libm only.
 * Over ~600 lines: eq. (5) at any step and speed (the tables' step maps and Taylor series in 1/vx,
 * the maps for other steps, the clamps) kept whole, in the order of its Python reference.
 *
 * States s = [z (4); w^ (1)], w^ the bank angle; w = [y; delta], y = [yaw rate, roll angle, roll rate]:
 *     x^ = z + N y
 *     z'  = T A x^ + T B delta + T F w^ + K_P (y - C x^)
 *     w^' = K_I (y - C x^)                                            (eq. 5)
 * i.e. s' = M(v) s + G(v) w with M, G polynomials in v = 1/vx (model_data.h: PI_MC, PI_GC per map
 * index: the mode, or PI_N_MODES + mode with the integral frozen, w^'s row zero).
 *
 * Co-simulation, over a step [t, t + h] (t the start of the call): the mode (eq. 25 speed bands on
 * vx; eq. 27 tire modes on the slip angles of eq. (2) from beta^, r^ at t, with hysteresis), the
 * model speed (fixed, or the measured vx clamped to the mode's range) and `valid` are decided at t
 * and held; w follows the design's hold: zero-order w(t + tau) = w_k, or first-order
 * w(t + tau) = w_k + (tau / h) e, e = h (w_k - w_{k-1}) / h_{k-1} (0 at the first step, after a
 * frozen period and after model_initialize). The step is n = ceil(h / max_step - 1e-9) classical
 * RK4 substeps of s' = M s + G w(tau), evaluated as
 *   - h = PI_H0 (0.005 s, the FMU's default step): the composed map s+ = Phi s + Gam w (+ Gam_e e)
 *     from model_data.h: per map index a table over v of Taylor polynomials in d = v - center,
 *     the design's tables (synthesis/tables; a fixed-speed index: one exact map); about 0.3k
 *     multiply-adds per step, no matrix work;
 *   - another h, fixed model speed: the same composed map computed at the first step of each map
 *     index with that h (one substep's affine map, binary powering)
 *     and cached in the instance, one h at a time;
 *   - another h, measured model speed: the RK4 substeps themselves (about 0.15k multiply-adds per
 *     substep, so ~0.3 us for h = 2 ms at max_step 1 ms);
 * all the same discretisation up to rounding. Outputs at t + h: x^ = z + N y with the hold's y at
 * t + h, bank_angle_hat = w^, mode (1-based), valid.
 *
 * Clamps (one warning per entry): vx < vx_hold freezes everything, outputs held; vx outside the
 * design grid: the nearest mode / model speed; valid 1 -> 0 when max(|alpha_f|, |alpha_r|) >
 * alpha_max or |vx yaw_rate| > ay_max, back to 1 below the release fraction of both, one warning
 * per entry into valid = 0, at most one per INVALID_LOG_PERIOD of simulated time (the next counts
 * the entries not logged). A step needing more than MAX_SUBSTEPS RK4 substeps (h > 1000 s at
 * max_step 1 ms) is refused with an error, the state kept.
 *
 * ModelExchange: the continuous states are s, the derivatives s' = M(v) s + G(v) w at the current
 * (continuous, not held) measurements, with the mode's model at the measured vx clamped as above;
 * 0 while frozen (outputs held). The discrete state (mode, valid, frozen, outside the grid)
 * changes only in model_me_event_update, at the zero crossings of the event indicators, one per
 * relation that can change it from the current discrete state (q - T, T a threshold):
 *     z[EI_HOLD]        vx - vx_hold                               freeze / resume
 *     z[EI_EDGE + i]    vx - PI_EDGES[i]                           speed bands: eq. (25)'s edges;
 *                                                                  the design grid's ends (warning)
 *     z[EI_TIRE]        premise - (alpha* +- hysteresis)           tire modes: eq. (27), the
 *                                                                  threshold of the current mode
 *     z[EI_VALID + 0/1] max(|alpha_f|, |alpha_r|) - limit,         validity: the limits of the
 *                       |vx yaw_rate| - limit                      current state (release if 0)
 * A host places a located crossing where the indicator has its new sign or is exactly zero (a
 * linear input crosses exactly): where a relation is strict on the side the crossing goes to
 * (vx < vx_hold, vx < edge from above, premise > alpha* + hysteresis, ...), T is replaced by its
 * neighbouring double on that side (nextafter), so that zero lies on the new side too and the
 * event update, with the same comparisons as a co-simulation step, switches there.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "model.h"
#include "model_data.h"
#include "model_util.h"

#define NS PI_NS                       /* s = [z; w^] */
#define NZ (PI_NS - 1)                 /* z, x^ */
#define NY PI_NY                       /* y */
#define NW PI_NW                       /* w = [y; delta] */
#define NCOL PI_NCOL                   /* x = [s; w] or [s; w; e]: a step map's columns */
#define NA (PI_NS + PI_FOH * PI_NW)    /* the state of the system RK4 integrates (first-order hold: [s; w]) */
#define INVALID_LOG_PERIOD 1.0         /* s of simulated time between "valid = 0" messages */
#define MAX_SUBSTEPS 1e6               /* longer steps are refused */
/* s (2^-30): the shortest baseline of the first-order hold's slope and the shortest step that
 * extrapolates it (the runtime's FOH_MIN_BASE, which gives the reasons): a shorter step holds w
 * (e = 0) and keeps the hold's previous sample, its age grown by h */
#define FOH_MIN_BASE 0x1p-30

/* full unrolling of the short loops of eval_interval (a hint; other compilers ignore it) */
#if defined(__clang__)
#define UNROLL _Pragma("unroll")
#elif defined(__GNUC__) && __GNUC__ >= 8
#define UNROLL _Pragma("GCC unroll 16")
#else
#define UNROLL
#endif

#define EI_HOLD 0
#define EI_EDGE 1
#define EI_TIRE (EI_EDGE + PI_NEDGES)
#define EI_VALID (EI_TIRE + !PI_SPEED_BANDS)
#if EI_VALID + 2 * PI_VALIDITY != N_EVENT_INDICATORS || PI_NEI != N_EVENT_INDICATORS
#error "sideslip_bank_observer.c: the event indicators do not match the emitter's count"
#endif
#if (NZ != 4 && NZ != 6) || NY != 3 || N_STATES != NS
#error "sideslip_bank_observer.c: 4 states z (6 with the relaxed axle forces), 3 measurements"
#endif
#define NX_OUT 4                       /* x^'s estimated outputs: beta, r, phi, phidot (not the axle forces) */

struct Model {
    double vx_hold;                    /* m/s */
    double s[NS];                      /* [z; w^] */
    int mode;                          /* 0-based */
    int valid;                         /* 1/0 */
    int started;                       /* initialised (model_initialize, or the first step) */
    int holding;                       /* vx < vx_hold: frozen */
    int outside;                       /* vx outside the design grid (warned) */
    double t;                          /* s, simulated time (sum of the steps; validity messages) */
    int have_prev;                     /* first-order hold: the last step's inputs are known */
    double prev_w[NW];                 /* w_{k-1} */
    double prev_h;                     /* h_{k-1}, s */
    long invalid_entries;              /* entries into valid = 0 */
    long invalid_unlogged;             /* entries since the last message, not logged */
    int invalid_logged;                /* a "valid = 0" message was logged ... */
    double invalid_logged_t;           /* ... at this time, s */
    double y[N_OUTPUTS];               /* co-simulation outputs; ModelExchange: held while frozen */
    double nsub_h;                     /* s, the step of nsub (0: none) */
    int nsub;                          /* its RK4 substeps */
    double map_h;                      /* s, the step of map[] (0: none) */
    int map_ok[PI_NMAP];               /* map[idx] holds the fixed-speed map of map_h */
    double map[PI_NMAP][NS][NCOL];     /* [Phi | Gam (| Gam_e)] */
};

static const int OUT_X[NX_OUT] = {OUT_beta_hat, OUT_yaw_rate_hat, OUT_roll_angle_hat, OUT_roll_rate_hat};

size_t model_size(void)
{
    return sizeof(Model);
}

/* ------------------------------------------------------------------ small helpers */
static void measurements(const double *u, double w[NW])
{
    w[0] = u[IN_yaw_rate];
    w[1] = u[IN_roll_angle];
    w[2] = u[IN_roll_rate];
    w[3] = u[IN_delta];
}

/* beta^, r^ = the first two rows of x^ = z + N y (the premises of eq. 27 and of the validity) */
static void estimates01(const Model *m, const double w[NW], double *beta, double *r)
{
    *beta = m->s[0] + (PI_N[0][0] * w[0] + PI_N[0][1] * w[1] + PI_N[0][2] * w[2]);
    *r = m->s[1] + (PI_N[1][0] * w[0] + PI_N[1][1] * w[1] + PI_N[1][2] * w[2]);
}

/* max(|alpha_f|, |alpha_r|), the slip angles of eq. (2) from beta^, r^ (rad; vx > 0 m/s) */
static double slip(double beta, double r, double vx, double delta, double lf, double lr)
{
    double a_f = delta - beta - lf * r / vx;
    double a_r = -beta + lr * r / vx;
    return fabs(a_r) > fabs(a_f) ? fabs(a_r) : fabs(a_f);
}

/* ------------------------------------------------------------------ switching */
/* eq. (25): mode i on [edges[i], edges[i + 1]); outside the grid the nearest mode */
static int band(double vx)
{
    int i = -1;
    while (i + 1 < PI_NEDGES && PI_EDGES[i + 1] <= vx) i++;
    return i < 0 ? 0 : (i < PI_N_MODES - 1 ? i : PI_N_MODES - 1);
}

/* eq. (27) with a hysteresis band of +-hysteresis around alpha* (a departure from the paper,
 * which chatters when the estimated slip hovers at alpha*) */
static int tire_mode(int mode, double premise)
{
    if (mode == 0 && premise > PI_SLIP_UP) return 1;
    if (mode == 1 && premise < PI_SLIP_DOWN) return 0;
    return mode;
}

/* v = 1/vx of the mode's model: its fixed speed, or vx clamped to its range */
static double model_v(int mode, double vx)
{
    if (PI_FIXED_V[mode] != 0.0) return PI_FIXED_V[mode];
    double lo = PI_VX_LO[mode], hi = PI_VX_HI[mode];
    return 1.0 / (lo <= vx && vx <= hi ? vx : (vx < lo ? lo : hi));
}

/* one warning per excursion of vx outside the design grid */
static void check_grid(Model *m, double vx, const Log *log)
{
    if (PI_GRID_LO <= vx && vx <= PI_GRID_HI) {
        m->outside = 0;
        return;
    }
    if (!m->outside)
        log_event(log, LOG_WARNING, "vx = %.4g m/s outside the design grid [%.4g, %.4g] m/s: clamped to the "
                  "nearest grid mode/speed", vx, PI_GRID_LO, PI_GRID_HI);
    m->outside = 1;
}

/* one rate-limited warning per entry into valid = 0 (at time t, s) */
static void log_invalid(Model *m, double alpha, double ay, double vx, int inside, double t, const Log *log)
{
    m->invalid_entries++;
    if (m->invalid_logged && !(t - m->invalid_logged_t >= INVALID_LOG_PERIOD)) {
        m->invalid_unlogged++;
        return;
    }
    char more[96] = "";
    if (m->invalid_unlogged)
        snprintf(more, sizeof more, "; %ld more entries since the last message not logged", m->invalid_unlogged);
    char why[128] = "estimates outside the validity limits";
    if (!inside)
        snprintf(why, sizeof why, "vx = %.4g m/s outside the design grid [%.4g, %.4g] m/s, and", vx, PI_GRID_LO,
                 PI_GRID_HI);
    log_event(log, LOG_WARNING, "t = %.6g s: valid = 0, %s: "
              "max(|alpha_f|, |alpha_r|) = %.3g rad (limit %.3g), |vx yaw_rate| = %.3g m/s^2 (limit %.3g)%s "
              "(entry %ld%s)", t, why, alpha, PI_A_MAX, ay, PI_AY_MAX,
              PI_FREEZE ? "; bank estimate held until valid again" : "", m->invalid_entries, more);
    m->invalid_logged = 1;
    m->invalid_logged_t = t;
    m->invalid_unlogged = 0;
}

/* valid for the step starting at t: the slip angles from beta^, r^ and |vx yaw_rate| against the
 * limits, with the release hysteresis, and vx inside the design grid (neither in the paper; the
 * runtime's ``check_validity``) */
static int check_validity(Model *m, double beta, double r, double vx, const double w[NW], double t, const Log *log)
{
    double alpha = slip(beta, r, vx, w[3], PI_VAL_LF, PI_VAL_LR);
    double ay = fabs(vx * w[0]);
    int inside = PI_GRID_LO <= vx && vx <= PI_GRID_HI;
    if (m->valid) {
        if (alpha > PI_A_MAX || ay > PI_AY_MAX || !inside) {
            m->valid = 0;
            log_invalid(m, alpha, ay, vx, inside, t, log);
        }
    } else if (alpha < PI_A_REL && ay < PI_AY_REL && inside) {
        m->valid = 1;
    }
    return m->valid;
}

/* the discrete state at the start of a step or at an event: mode (eq. 25 / 27) and validity;
 * returns the map index */
static int decide(Model *m, double vx, const double w[NW], double t, const Log *log)
{
    double beta = 0.0, r = 0.0;
    if (!PI_SPEED_BANDS || PI_VALIDITY) estimates01(m, w, &beta, &r);
    if (PI_SPEED_BANDS) m->mode = band(vx);
    else m->mode = tire_mode(m->mode, slip(beta, r, vx, w[3], PI_SLIP_LF, PI_SLIP_LR));
    if (PI_VALIDITY && !check_validity(m, beta, r, vx, w, t, log) && PI_FREEZE) return m->mode + PI_N_MODES;
    return m->mode;
}

/* vx < vx_hold (standstill, reversing): frozen, one warning per entry and one at the resumption.
 * Returns 1 while frozen. */
static int check_hold(Model *m, double vx, const Log *log)
{
    if (vx < m->vx_hold) {
        if (!m->holding)
            log_event(log, LOG_WARNING, "vx = %.3g m/s < vx_hold = %g m/s (standstill or reversing): observer "
                      "frozen, every estimate held", vx, m->vx_hold);
        m->holding = 1;
        return 1;
    }
    if (m->holding) log_event(log, LOG_WARNING, "vx = %.3g m/s: observer resumes", vx);
    m->holding = 0;
    return 0;
}

/* ------------------------------------------------------------------ the model and its step maps */
/* M(v), G(v) of map index idx: sum_k PI_MC[idx][k] v**(k + PI_P0) (v**-1 as 1 / v: a term in vx) */
static void system_at(int idx, double v, double M[NS][NS], double G[NS][NW])
{
    memset(M, 0, sizeof(double) * NS * NS);
    memset(G, 0, sizeof(double) * NS * NW);
    for (int k = 0; k < PI_NV; k++) {
        int p = k + PI_P0;
        double vk = p == 0 ? 1.0 : p == -1 ? 1.0 / v : pow(v, (double)p);
        for (int i = 0; i < NS; i++) {
            for (int j = 0; j < NS; j++) M[i][j] += PI_MC[idx][k][i][j] * vk;
            for (int j = 0; j < NW; j++) G[i][j] += PI_GC[idx][k][i][j] * vk;
        }
    }
}

/* RK4 stage: k = M s + b */
static void stage(double M[NS][NS], const double s[NS], const double b[NS], double k[NS])
{
    for (int i = 0; i < NS; i++) k[i] = dot_from(0.0, M[i], s, NS) + b[i];
}

/* nsub classical RK4 substeps of s' = M s + G w(tau) at v: x = [s; w(; e)]
 * in, s+ out; w(tau) = w + (tau / h) e with the first-order hold */
static void rk4(int idx, double v, double h, int nsub, const double x[NCOL], double s[NS])
{
    double M[NS][NS], G[NS][NW], b[NS], g[NS] = {0.0}, k1[NS], k2[NS], k3[NS], k4[NS], tmp[NS], b1[NS], b2[NS],
        b4[NS];
    double hs = h / nsub;
    system_at(idx, v, M, G);
    for (int i = 0; i < NS; i++) {
        b[i] = dot_from(0.0, G[i], x + NS, NW);
        if (PI_FOH) g[i] = dot_from(0.0, G[i], x + NS + NW, NW) / h;
        s[i] = x[i];
    }
    for (int j = 0; j < nsub; j++) {
        double t1 = j * hs, t2 = (j + 0.5) * hs, t4 = (j + 1) * hs;
        for (int i = 0; i < NS; i++) {
            b1[i] = b[i] + t1 * g[i];
            b2[i] = b[i] + t2 * g[i];
            b4[i] = b[i] + t4 * g[i];
        }
        stage(M, s, b1, k1);
        for (int i = 0; i < NS; i++) tmp[i] = s[i] + 0.5 * hs * k1[i];
        stage(M, tmp, b2, k2);
        for (int i = 0; i < NS; i++) tmp[i] = s[i] + 0.5 * hs * k2[i];
        stage(M, tmp, b2, k3);
        for (int i = 0; i < NS; i++) tmp[i] = s[i] + hs * k3[i];
        stage(M, tmp, b4, k4);
        for (int i = 0; i < NS; i++) s[i] = s[i] + hs / 6.0 * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i]);
    }
}

/* the table interval of map index idx holding v (clamped to the table) */
static int interval(int idx, double v)
{
    int k = (int)((v - PI_TAB_VLO[idx]) * PI_TAB_SCALE[idx]);
    if (k >= PI_TAB_K[idx]) k = PI_TAB_K[idx] - 1;
    else if (k < 0) k = 0;
    return PI_TAB_FIRST[idx] + k;
}

/* s+ of interval t at d = v - center: per degree j the rows p_j = C_j x (the additions column by
 * column, as the Python reference runtime), then Horner in d per row. The loops over j and r are
 * unrolled so that the (PI_DEG + 1) NS sums stay in registers over the column loop (measured on
 * the default design: 70 ns per step, 84 ns with one block of NS sums per degree). */
static void eval_interval(int t, double d, const double x[NCOL], double a[NS])
{
    const double(*k)[NCOL][NS] = PI_TAB_COEF[t];
    double p[PI_DEG + 1][NS] = {{0.0}};
    for (int c = 0; c < NCOL; c++) {
        double xc = x[c];
        UNROLL for (int j = 0; j <= PI_DEG; j++)
            UNROLL for (int r = 0; r < NS; r++) p[j][r] += k[j][c][r] * xc;
    }
    UNROLL for (int r = 0; r < NS; r++) {
        double acc = p[PI_DEG][r];
        UNROLL for (int j = PI_DEG - 1; j >= 0; j--) acc = p[j][r] + d * acc;
        a[r] = acc;
    }
}

/* C = A B, A n x n, B n x cols (row-major, leading dimension ld), sums from left to right */
static void matmul(int n, int cols, int ld, const double *A, const double *B, double *C)
{
    for (int i = 0; i < n; i++)
        for (int j = 0; j < cols; j++) {
            double acc = 0.0;
            for (int k = 0; k < n; k++) acc += A[i * ld + k] * B[k * ld + j];
            C[i * ld + j] = acc;
        }
}

/* the affine map W2 after W1, each [A | b] (NA rows, NA + NW columns): [A2 A1 | A2 b1 + b2] */
static void compose(double W2[NA][NA + NW], double W1[NA][NA + NW], double out[NA][NA + NW])
{
    matmul(NA, NA + NW, NA + NW, &W2[0][0], &W1[0][0], &out[0][0]);
    for (int i = 0; i < NA; i++)
        for (int c = NA; c < NA + NW; c++) out[i][c] += W2[i][c];
}

/* One RK4 substep of hs with held input as the affine map W = [R | S Gi] of a' = Ma a + Gi i (as
 * synthesis/tables/series.py): X = hs Ma, Q = I + X/2 (I + X/3 (I + X/4)), R = I + X Q, S Gi = hs Q Gi */
static void substep_map(double Ma[NA][NA], double Gi[NA][NW], double hs, double W[NA][NA + NW])
{
    double X[NA][NA], Q[NA][NA], T[NA][NA];
    static const double inv[3] = {1.0 / 4.0, 1.0 / 3.0, 1.0 / 2.0};
    for (int i = 0; i < NA; i++)
        for (int j = 0; j < NA; j++) {
            X[i][j] = Ma[i][j] * hs;
            Q[i][j] = i == j ? 1.0 : 0.0;
        }
    for (int c = 0; c < 3; c++) {
        matmul(NA, NA, NA, &X[0][0], &Q[0][0], &T[0][0]);
        for (int i = 0; i < NA; i++)
            for (int j = 0; j < NA; j++) Q[i][j] = (i == j ? 1.0 : 0.0) + T[i][j] * inv[c];
    }
    matmul(NA, NA, NA, &X[0][0], &Q[0][0], &T[0][0]);
    for (int i = 0; i < NA; i++) {
        for (int j = 0; j < NA; j++) W[i][j] = (i == j ? 1.0 : 0.0) + T[i][j];
        for (int j = 0; j < NW; j++) {
            double acc = 0.0;
            for (int k = 0; k < NA; k++) acc += Q[i][k] * Gi[k][j];
            W[i][NA + j] = acc * hs;
        }
    }
}

/* The composed map of nsub substeps for fixed-speed map index idx at step h: first-order hold on the augmented system [s; w]' = [[M, G], [0, 0]] [s; w] +
 * [[0], [I / h]] e (input e), else s' = M s + G w (input w); top rows into m->map[idx]. */
static void build_map(Model *m, int idx, double h, int nsub)
{
    double Ma[NA][NA] = {{0.0}}, Gi[NA][NW] = {{0.0}}, M[NS][NS], G[NS][NW];
    double W[NA][NA + NW], R[NA][NA + NW], tmp[NA][NA + NW];
    system_at(idx, PI_FIXED_V[idx % PI_N_MODES], M, G);
    for (int i = 0; i < NS; i++) {
        for (int j = 0; j < NS; j++) Ma[i][j] = M[i][j];
        for (int j = 0; j < NW; j++) {
            if (PI_FOH) Ma[i][NS + j] = G[i][j];  /* the hold's w is a state ... */
            else Gi[i][j] = G[i][j];              /* ... or the held input */
        }
    }
    /* below FOH_MIN_BASE e = 0, its column unused: 0, not 1/h (inf below ~5.6e-309 s, 0 * inf = NaN) */
    for (int j = 0; PI_FOH && j < NW; j++) Gi[NS + j][j] = h >= FOH_MIN_BASE ? 1.0 / h : 0.0;
    substep_map(Ma, Gi, h / nsub, W);
    int have = 0;
    for (unsigned k = (unsigned)nsub;;) {          /* binary powering: all factors commute */
        if (k & 1u) {
            if (have) {
                compose(W, R, tmp);
                memcpy(R, tmp, sizeof R);
            } else {
                memcpy(R, W, sizeof R);
            }
            have = 1;
        }
        k >>= 1;
        if (!k) break;
        compose(W, W, tmp);
        memcpy(W, tmp, sizeof W);
    }
    for (int i = 0; i < NS; i++) memcpy(m->map[idx][i], R[i], sizeof(double) * NCOL);
}

/* s+ = the step over h from x = [s; w(; e)] with map index idx at v */
static void advance(Model *m, int idx, double v, double h, int nsub, const double x[NCOL], double a[NS])
{
    if (h == PI_H0) {
        int t = interval(idx, v);
        if (!PI_TAB_RK4[t]) {
            eval_interval(t, v - PI_TAB_CENTER[t], x, a);
            return;
        }
    } else if (PI_FIXED_V[idx % PI_N_MODES] != 0.0) {
        if (m->map_h != h) {
            memset(m->map_ok, 0, sizeof m->map_ok);
            m->map_h = h;
        }
        if (!m->map_ok[idx]) {
            build_map(m, idx, h, nsub);
            m->map_ok[idx] = 1;
        }
        for (int i = 0; i < NS; i++) a[i] = dot_from(0.0, m->map[idx][i], x, NCOL);
        return;
    }
    rk4(idx, v, h, nsub, x, a);
}

/* ------------------------------------------------------------------ co-simulation */
int model_setup(Model *m, const double *p, const Log *log)
{
    double hold = p[PAR_vx_hold];
    memset(m, 0, sizeof *m);
    if (!(isfinite(hold) && hold > 0.0)) {       /* 0 would reach 1/vx at vx = 0 */
        log_event(log, LOG_ERROR, "parameter vx_hold must be finite and > 0 m/s, got %g", hold);
        return -1;
    }
    m->vx_hold = hold;
    m->valid = 1;
    return 0;
}

/* x^ = [0, y] (beta^ = 0, the measured r, phi, phidot; relaxed axle forces: [0, y, 0, 0]), z = x^ - N y,
 * the mode of the initial speed; the first-order hold restarts */
static void start(Model *m, const double *u)
{
    double w[NW], ny[NZ];
    measurements(u, w);
    for (int i = 0; i < NZ; i++) {
        ny[i] = dot_from(0.0, PI_N[i], w, NY);
        m->s[i] = (i == 0 || i > NY ? 0.0 : w[i - 1]) - ny[i];
    }
    m->started = 1;
    m->have_prev = 0;
    if (PI_SPEED_BANDS && u[IN_vx] >= m->vx_hold) m->mode = band(u[IN_vx]);
    for (int i = 0; i < NX_OUT; i++) m->y[OUT_X[i]] = m->s[i] + ny[i];
    m->y[OUT_bank_angle_hat] = m->s[NZ];
}

void model_initialize(Model *m, const double *u, const Log *log)
{
    (void)log;
    start(m, u);
}

/* first-order hold: e = the increment of w_k + tau (w_k - w_a) / (t_k - t_a) over h, w_a the hold's
 * previous sample (prev_w, its age prev_h); 0 after a restart, and when the age or h is below
 * FOH_MIN_BASE. Remembers w_k, h; after a step below FOH_MIN_BASE keeps w_a, its age grown by h */
static void hold_increment(Model *m, double h, const double w[NW], double e[NW])
{
    int slope = m->have_prev && m->prev_h >= FOH_MIN_BASE && h >= FOH_MIN_BASE;
    double c = !slope ? 0.0 : h == m->prev_h ? 1.0 : h / m->prev_h;   /* h / h == 1 exactly */
    int keep = m->have_prev && h < FOH_MIN_BASE;
    for (int j = 0; j < NW; j++) {
        e[j] = slope ? (w[j] - m->prev_w[j]) * c : 0.0;
        if (!keep) m->prev_w[j] = w[j];
    }
    m->prev_h = keep ? m->prev_h + h : h;
    m->have_prev = 1;
}

/* the RK4 substeps of a step h: n = max(1, ceil(h / max_step - 1e-9)), remembered for the last h;
 * 0 (an error logged) beyond MAX_SUBSTEPS */
static int substeps(Model *m, double h, const Log *log)
{
    if (h == m->nsub_h) return m->nsub;
    double q = ceil(h / PI_MAX_STEP - 1e-9);
    if (!(q <= MAX_SUBSTEPS)) {
        log_event(log, LOG_ERROR, "step refused: h = %g s needs %g RK4 substeps of max_step = %g s (at most %g)",
                  h, q, PI_MAX_STEP, MAX_SUBSTEPS);
        return 0;
    }
    m->nsub_h = h;
    m->nsub = q < 1.0 ? 1 : (int)q;
    return m->nsub;
}

int model_do_step(Model *m, double h, const double *u, const Log *log)
{
    double x[NCOL], a[NS];
    int nsub = substeps(m, h, log);
    if (nsub == 0) return -1;
    double vx = u[IN_vx], t = m->t;
    if (!m->started) start(m, u);
    if (PI_VALIDITY) m->t = t + h;
    if (check_hold(m, vx, log)) {
        m->have_prev = 0;                          /* the first-order hold restarts with slope 0 */
        return 0;
    }
    check_grid(m, vx, log);
    memcpy(x, m->s, sizeof m->s);
    measurements(u, x + NS);
    int idx = decide(m, vx, x + NS, t, log);
    if (PI_FOH) hold_increment(m, h, x + NS, x + NCOL - NW);
    advance(m, idx, model_v(m->mode, vx), h, nsub, x, a);
    memcpy(m->s, a, sizeof m->s);
    for (int i = 0; i < NX_OUT; i++) {             /* x^ = z+ + N y(t + h), the outputs */
        double acc = a[i];
        for (int j = 0; j < NY; j++) acc += PI_N[i][j] * x[NS + j];
        for (int j = 0; PI_FOH && j < NY; j++) acc += PI_N[i][j] * x[NCOL - NW + j];
        m->y[OUT_X[i]] = acc;
    }
    m->y[OUT_bank_angle_hat] = a[NZ];
    return 0;
}

void model_outputs(const Model *m, double *y, int *yi)
{
    memcpy(y, m->y, sizeof m->y);
    yi[INT_mode] = m->mode + 1;
    yi[INT_valid] = m->valid;
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

void model_me_derivatives(const Model *m, const double *u, double *dx)
{
    double M[NS][NS], G[NS][NW], w[NW];
    if (m->holding) {
        memset(dx, 0, sizeof(double) * NS);
        return;
    }
    int idx = m->mode + (PI_FREEZE && !m->valid ? PI_N_MODES : 0);
    system_at(idx, model_v(m->mode, u[IN_vx]), M, G);
    measurements(u, w);
    for (int i = 0; i < NS; i++) dx[i] = dot_from(0.0, M[i], m->s, NS) + dot_from(0.0, G[i], w, NW);
}

/* q - T, with T moved to its neighbouring double below (above) when the relation q < T (q > T)
 * becomes true as q decreases (increases) through it: the indicator is then <= 0 (>= 0), zero
 * included, exactly where the relation holds (see the file's header) */
static double below(double q, double T)
{
    return q - nextafter(T, -INFINITY);
}

static double above(double q, double T)
{
    return q - nextafter(T, INFINITY);
}

void model_me_event_indicators(const Model *m, const double *u, double *z)
{
    double vx = u[IN_vx], w[NW], beta, r;
    double vs = vx > m->vx_hold ? vx : m->vx_hold;  /* the slip angles' 1/vx, finite while frozen */
    measurements(u, w);
    estimates01(m, w, &beta, &r);
    z[EI_HOLD] = m->holding ? vx - m->vx_hold : below(vx, m->vx_hold);
    for (int i = 1; i < PI_NEDGES - 1; i++)      /* eq. (25): mode >= i iff vx >= edge i */
        z[EI_EDGE + i] = m->mode >= i ? below(vx, PI_EDGES[i]) : vx - PI_EDGES[i];
    z[EI_EDGE] = m->outside ? vx - PI_GRID_LO : below(vx, PI_GRID_LO);
    z[EI_EDGE + PI_NEDGES - 1] = m->outside ? vx - PI_GRID_HI : above(vx, PI_GRID_HI);
    if (!PI_SPEED_BANDS) {
        double premise = slip(beta, r, vs, w[3], PI_SLIP_LF, PI_SLIP_LR);
        z[EI_TIRE] = m->mode == 0 ? above(premise, PI_SLIP_UP) : below(premise, PI_SLIP_DOWN);
    }
    if (PI_VALIDITY) {
        double alpha = slip(beta, r, vs, w[3], PI_VAL_LF, PI_VAL_LR), ay = fabs(vx * w[0]);
        z[EI_VALID] = m->valid ? above(alpha, PI_A_MAX) : below(alpha, PI_A_REL);
        z[EI_VALID + 1] = m->valid ? above(ay, PI_AY_MAX) : below(ay, PI_AY_REL);
    }
}

/* x^ = z + N y, bank_angle_hat = w^ at the current states and measurements */
static void me_estimates(const Model *m, const double *u, double *y)
{
    double w[NW];
    measurements(u, w);
    for (int i = 0; i < NX_OUT; i++) y[OUT_X[i]] = m->s[i] + dot_from(0.0, PI_N[i], w, NY);
    y[OUT_bank_angle_hat] = m->s[NZ];
}

void model_me_outputs(const Model *m, const double *u, double *y, int *yi)
{
    yi[INT_mode] = m->mode + 1;
    yi[INT_valid] = m->valid;
    if (m->holding) memcpy(y, m->y, sizeof m->y);   /* held while frozen */
    else me_estimates(m, u, y);
}

int model_me_event_update(Model *m, double t, const double *u, const Log *log)
{
    double vx = u[IN_vx], w[NW];
    int changed = !m->started;
    if (changed) start(m, u);
    if (!m->holding && vx < m->vx_hold) me_estimates(m, u, m->y);   /* the outputs to hold */
    if (check_hold(m, vx, log)) return changed;
    check_grid(m, vx, log);
    measurements(u, w);
    decide(m, vx, w, t, log);
    return changed;
}
