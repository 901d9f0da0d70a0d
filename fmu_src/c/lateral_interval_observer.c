/*
 * lateral_interval_observer.c - paper 001's switched interval observer (Ifqir, Ichalal, Ait-Oufroukh,
 * Mammar, ACC 2020), eq. (23), with guaranteed bounds between the communication points; the native
 * twin of fmu_src/lateral_interval_observer.py (specified in docs/runtime/lateral_interval_observer.md; this file implements the
 * same steps, in the same floating-point order, so that both give the same bounds). C99, libm.
 * Over ~600 lines for its Python twin's reason: the guarantee between the samples needs more than
 * eq. (23) (the a priori enclosure of each step, the sampled-measurement correction), kept in one
 * file that reads beside the Python reference operation by operation.
 *
 * Model (eq. 9, the relaxation term's sign corrected): x = [vy (m/s), r (rad/s), x3 = ay (m/s^2), x4 (rad/s^2)],
 *     x' = (A0 + vx A1 + dA) x + vx (B1 + dB1) delta,  y = [r, ay] = C x,
 * dA, dB1 in the elementwise bounds of the stiffness box (eq. 18). Mode j (eq. 44: speed bands)
 * has the gains N, E, J, H, P = I - E C of eq. (23)/(30)/(33) (model_data.h, IV_*).
 *
 * Co-simulation (the runtime's ``step``; the observer runs ONE STEP BEHIND the published box):
 *  1. measurement intersection of the published box with [y - nu, y + nu] (ay's nu widened by the
 *     small-angle error of the paper's y = C x for a steered car's accelerometer: ``ay_nu``); an empty one (beyond
 *     IV_CONSISTENCY_TOL) sets consistent = 0 and restarts the bounds (one warning per episode);
 *  2. correction of the previous step (eq. 23 exactly discretised with exp(N s) >= 0: ``correct``);
 *  3. mode of vx (eq. 44; nearest mode outside the grid, one warning per excursion); |vx| < vx_hold
 *     freezes everything (outputs held, one warning per entry, a restart at the resumption);
 *  4. a priori enclosure T of x over the step (``enclose``, else the comparison bound
 *     ``comparison_enclosure``, one warning per episode; substeps when h rho(|A|) > IV_SUBSTEP_RHO_H);
 *  5. the predicted box at t + h (``predict``), published; its correction waits for y(t + h);
 *  6. outputs: vy, beta = atan(vy / vx), r, and the axle forces by eq. (8) inverted (eq. 45, with
 *     the lower bound of Fyr from the UPPER bound of x4: eq. (45)'s misprint).
 * The step maps (Phi, Gam, Gam1, Gam2) of (mode, h) are the runtime's ``phi_gamma``: from the
 * emitter for the default step IV_H0, otherwise computed here by the same algorithm; the
 * correction's coefficients derived from them are cached per mode (one step size at a time).
 * Beside the correction of step 2, the sampled-measurement correction (the runtime's
 * ``_sampled_predict`` at step 5 and ``_sampled_correct`` at step 2; not in the paper): x propagated
 * by the model alone over IV_SAMPLED_SUBSTEP substeps, the measurement entering only at the samples
 * through gains L (x = (I - L C) x + L y, exact for any L); both boxes are intersected (the
 * predicted one too), for steps h >= IV_SAMPLED_MIN_STEP. Its maps (``sampled_fill``: the runtime's ``_sampled_maps``, same order of
 * operations) are computed here per (model speed, step), the model speed vx rounded to
 * IV_SAMPLED_DV (the mismatch bounded exactly), and cached (SM_CACHE entries).
 * A step longer than IV_MAX_COMM_STEP (the runtime's ``max_communication_step``: the longest at
 * which the design's bounds contract), whose step maps are not finite (|vx| near the double range) or that would need
 * more than MAX_SUBSTEPS enclosure substeps is refused with an error, the state unchanged.
 *
 * Model exchange: the paper's continuous-time observer eq. (23) itself,
 *     xi_up' = N xi_up + J y + H delta + Omega_up,   xi_lo' = N xi_lo + J y + H delta + Omega_lo,
 * states xi_lo, xi_up (bounds of xi = P x of the active mode), x in [xi_lo + E y, xi_up + E y]
 * (+-|E| nu), Omega by eq. (24) from the omega bounds of eq. (25) over that box (the speed mismatch
 * at the measured vx, the input part exactly, the structured stiffness part: the same bounds as the
 * co-simulation's). It has no measurement intersection, so no consistency test (consistent = 1) and
 * no restart but at the resumption from a freeze, and no one-step delay. The discrete state changes
 * only in model_me_event_update: a mode switch re-bases xi := hull of P_new x over the box (eq. 20;
 * the bounds of x stay continuous), a freeze holds the bounds. Event indicators (of the
 * current discrete state: mode j, frozen or not):
 *     z0 = vx - (edges[j] - ME_HYST)   (j > 0, else 1)    band j left downward
 *     z1 = edges[j + 1] - vx           (j < last, else 1) band j left upward
 *     z2 = |vx| - (vx_hold - ME_HYST) running, vx_hold - |vx| frozen: freeze / resume
 *     z3 = vx - (edges[0] - ME_HYST), z4 = edges[last] + ME_HYST - vx: the design grid (warning)
 * The co-simulation's thresholds, moved ME_HYST = 1e-6 m/s outward on the sides its rule includes
 * (an event located exactly on a threshold must switch; a constant vx on one must not).
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "model.h"
#include "model_data.h"

#define NX 4                       /* states */
#define NB (2 * NX)                /* a box: [lower0..3, upper0..3] */
#define NY 2                       /* measured states */
#define N_MODES IV_N_MODES
#define N_MAPS 4                   /* Phi, Gam, Gam1, Gam2 */
#define MAXM (N_MAPS * NX)         /* the largest block matrix of ``expm_taylor`` */
#define MAX_SUBSTEPS 100000        /* enclosure substeps of one step (h rho / IV_SUBSTEP_RHO_H) */
#define ME_HYST 1e-6               /* m/s, see model_me_event_indicators */

static const int MEAS[NY] = {1, 2};        /* y = [r, ay] = [x2, x3] (the runtime checks model.C) */
static const int UNMEAS[NY] = {0, 3};
#define ROW_AY 2                   /* rows of the stiffness part (x3', x4'), eq. (9) */
#define ROW_YAW_ACC 3

/* The correction of one (mode, h) (the runtime's ``_core`` coefficients): with
 * W1 = Gam1/h, W0 = Gam - W1, W2 = |h Gam1/2 - Gam2|, W3 = 2 W2/h (all >= 0) */
typedef struct {
    double h;                      /* s; 0: empty */
    int nsub;                      /* enclosure substeps of hs = h / nsub */
    double hs;
    double phi[NX][NX];            /* exp(N h) */
    double w0j[NX][NY], aw0j[NX][NY], w1j[NX][NY], aw1j[NX][NY];   /* W0 J, |W0 J|, W1 J, |W1 J| */
    double w2j_neg[NX][NY];        /* -W2 J on the smooth measured rows (else 0) */
    double w2aj[NX][NY];           /* W2 |J| on the smooth measured rows (else 0) */
    double w3aj2[NX][NY];          /* 2 W3 |J| on the other measured rows (else 0) */
    double gp[NX][NX], gap[NX][NX], g1p[NX][NX], g1ap[NX][NX];      /* Gam P, Gam |P|, Gam1 P, Gam1 |P| */
    double gh[NX];                 /* Gam H */
    /* the coefficients' error bounds (each entry; the runtime's ``_core``): of phi, the W0 J, W1 J,
     * W2 J and 2 W3 |J| groups, Gam P and Gam1 P (and their |P| forms), Gam H */
    double err_phi, err_w0j, err_w1j, err_w2j, err_w3j, err_gp, err_gh;
    double gsum[NX];               /* Gam's row sums, rounded up: the weight of the design residuals */
} Core;

/* the step awaiting its correction (the runtime's ``_pending``) */
typedef struct {
    int mode;
    double h, vx, d;               /* s, m/s, rad */
    double X[NB];                  /* the box at its start */
    double xi[NB];                 /* the xi bounds at its start (+-inf: none) */
    double Fb[NB];                 /* the hull of F over T */
    int has_sm;                    /* the sampled-measurement correction (``sampled_predict``): */
    double sm_vq;                  /* its model speed (m/s), the box at the start (midpoint, radius) */
    double sm_c0[NX], sm_r0[NX];   /* and the bounds of omega per substep (midpoint, radius) */
    double sm_mo[IV_SAMPLED_MAX_SUBSTEPS][NX], sm_ro[IV_SAMPLED_MAX_SUBSTEPS][NX];
    double sm_so[IV_SAMPLED_MAX_SUBSTEPS], sm_s0;  /* sum |mid| + rad of each omega and of the start box */
} Pending;

/* one gain of the sampled-measurement correction (the runtime's ``_sampled_maps``: gains) */
typedef struct {
    double L[NX][NY], aL[NX][NY];  /* L, |L| */
    double kphi[NX][NX], akphi[NX][NX], kgb[NX];    /* K phi[n], |K phi[n]|, K gamb[n]; K = I - L C */
    double kpg[IV_SAMPLED_MAX_SUBSTEPS][NX][NX];    /* K pg[i] */
    double akpg[IV_SAMPLED_MAX_SUBSTEPS][NX][NX];   /* |K phi[i]| Gam_M(hs) */
    double ekphi, ekgb;                             /* their error bounds (entrywise) */
    double ekpg[IV_SAMPLED_MAX_SUBSTEPS], eakpg[IV_SAMPLED_MAX_SUBSTEPS];
} SampledGain;

#define SM_GAINS (1 + NY * NY)      /* the deadbeat gain, one column by one measurement */
#define SM_CACHE 2                  /* (speed, step) maps kept */

/* the maps of the sampled-measurement correction at one (model speed vq, step h) */
typedef struct {
    int valid, n, nc;              /* n substeps of hs; nc gains */
    double vq, h, hs;
    double phi[IV_SAMPLED_MAX_SUBSTEPS + 1][NX][NX], aphi[IV_SAMPLED_MAX_SUBSTEPS + 1][NX][NX];
    double gamb[IV_SAMPLED_MAX_SUBSTEPS + 1][NX];
    double pg[IV_SAMPLED_MAX_SUBSTEPS][NX][NX], apg[IV_SAMPLED_MAX_SUBSTEPS][NX][NX];
    double ephi[IV_SAMPLED_MAX_SUBSTEPS + 1], egamb[IV_SAMPLED_MAX_SUBSTEPS + 1];   /* error bounds */
    double epg[IV_SAMPLED_MAX_SUBSTEPS], eapg[IV_SAMPLED_MAX_SUBSTEPS];
    SampledGain c[SM_GAINS];
} Sampled;

/* everything a step may change (restored when a step is refused) */
typedef struct {
    double box[NB];                /* the published bounds of x */
    double xi[NB];                 /* xi bounds at the current time ... */
    int xi_mode;                   /* ... for the P of this mode (-1: none) */
    int has_pending;
    Pending p;
    double vx_pub;                 /* m/s, the speed of the published beta bounds */
    int mode;                      /* 0-based */
    int consistent;
    int started, holding, outside, inconsistent, fallback_episode;
    double me_xi[NB];              /* model exchange: [xi_lo; xi_up] of eq. (23) */
    double nu[NY];                 /* |measured - true| of [r, ay]: the FMU parameters
                                      yaw_rate_error_bound (rad/s), ay_error_bound (m/s2) */
    double d_last;                 /* rad: the steering of the last call (held over the step just ended) */
} State;

struct Model {
    double vx_hold;                /* m/s */
    State s;
    Core core[N_MODES];            /* cache, one step size per mode */
    Sampled sm[SM_CACHE];          /* cache of the sampled-measurement maps, round robin */
    int sm_next;
};

size_t model_size(void)
{
    return sizeof(Model);
}

/* ------------------------------------------------------------------ helpers */
/* Python's min(a, b) and max(a, b) (the first argument unless the second is strictly beyond) */
static double py_min(double a, double b)
{
    return b < a ? b : a;
}

static double py_max(double a, double b)
{
    return b > a ? b : a;
}

/* s + sum_j c[j] x[j] over the NONZERO c[j], left to right (the runtime's ``_acc``: zero
 * coefficients skipped, the terms chained onto the running sum) */
static double acc(double s, const double *c, const double *x, int n)
{
    for (int j = 0; j < n; j++)
        if (c[j] != 0.0) s += c[j] * x[j];
    return s;
}

/* s + sum_j |c[j]| x[j] over the nonzero c[j] */
static double acc_abs(double s, const double *c, const double *x, int n)
{
    for (int j = 0; j < n; j++)
        if (c[j] != 0.0) s += fabs(c[j]) * x[j];
    return s;
}

static int all_finite(const double *x, int n)
{
    for (int i = 0; i < n; i++)
        if (!isfinite(x[i])) return 0;
    return 1;
}

/* ------------------------------------------------------------------ rigorous rounding */
/* (the runtime's DEPARTURE, see there): every bound contains the exact real value of what it bounds.
 * A single operation's result is rounded outward by one ulp (dn, up); a sum of n products in
 * midpoint-radius form (mid s, radius t, shadow a = sum |c| |m|) within s -+ radius(t, a, e, n),
 * e the coefficients' errors. */
#define U_RND 0x1p-53              /* unit roundoff */
#define ETA_RND 0x1p-1074          /* the smallest subnormal */
#define SLACK (1.0 + 0x1p-20)      /* the margin of an error bound's own roundings */

/* nextafter(x, +-INFINITY) without the libm call (the same results, NaN and the infinities included:
 * a finite nonzero double's neighbour is one step of its bit pattern) */
static double up(double x)
{
    uint64_t b;
    if (x != x || x == INFINITY) return x;
    if (x == 0.0) return 0x1p-1074;
    memcpy(&b, &x, sizeof b);
    b = x > 0.0 ? b + 1 : b - 1;
    memcpy(&x, &b, sizeof b);
    return x;
}

static double dn(double x)
{
    return -up(-x);
}

static double radius(double t, double a, double e, int n)
{
    double k = 2 * n + 4;
    return up(t + e + k * U_RND * (a + t + e) + k * ETA_RND);
}

/* midpoint and radius of a box [lower0..n-1, upper0..n-1], the radius rounded up (the runtime's
 * ``_mid_rad``) */
static void mid_rad_n(const double *X, int n, double *c, double *r)
{
    for (int j = 0; j < n; j++) {
        c[j] = (X[j] + X[n + j]) * 0.5;
        r[j] = up(py_max(X[n + j] - c[j], c[j] - X[j]));
    }
}

static void mid_rad(const double *X, double c[NX], double r[NX])
{
    mid_rad_n(X, NX, c, r);
}

/* sum |x|, from the left (the runtime's ``total(map(abs, x))``) */
static double sum_abs(const double *x, int n)
{
    double s = 0.0;
    for (int j = 0; j < n; j++) s += fabs(x[j]);
    return s;
}

static void measurements(const double *u, double y[NY])
{
    y[0] = u[IN_yaw_rate];
    y[1] = u[IN_ay];
}

static int row_nonzero(const double *row)
{
    for (int j = 0; j < NX; j++)
        if (row[j] != 0.0) return 1;
    return 0;
}

/* A0 and A1 without the diagonal of the damped rows (the tables' damped rows: integrated exactly) */
static double a0u(int i, int j)
{
    return (i == j && IV_DAMPED[i]) ? 0.0 : IV_A0[i][j];
}

static double a1u(int i, int j)
{
    return (i == j && IV_DAMPED[i]) ? 0.0 : IV_A1[i][j];
}

/* [alo, ahi] containing -d_i(vx) = -(A0_ii + vx A1_ii): the known decay rate of a damped row (1/s) */
static void decay(int i, double vx, double *alo, double *ahi)
{
    double a0 = IV_A0[i][i], a1 = IV_A1[i][i];
    *alo = dn(-a0 - up(vx * a1));
    *ahi = up(-a0 - dn(vx * a1));
}

/* ------------------------------------------------------------------ Lemma 3 and the stiffness part */
/* [al, au] * [l, u] (the runtime's ``_product_hull``): the exact interval product, by the signs of the
 * constant factor; symmetric (up to rounding): +-a max(|l|, |u|) */
static void product_hull(double al, double au, double l, double u, double *lo, double *hi)
{
    if (al == au) {
        *lo = dn(al >= 0.0 ? al * l : al * u);
        *hi = up(al >= 0.0 ? al * u : al * l);
    } else if (al >= 0.0) {
        *lo = dn(l >= 0.0 ? l * al : l * au);
        *hi = up(u >= 0.0 ? u * au : u * al);
    } else if (au <= 0.0) {
        *lo = dn(u >= 0.0 ? u * al : u * au);
        *hi = up(l >= 0.0 ? l * au : l * al);
    } else if (fabs(al + au) <= 1e-9 * py_max(-al, au)) {
        double a = py_max(-al, au), mag = u > -l ? u : -l;
        *lo = dn(-a * mag);
        *hi = up(a * mag);
    } else {
        *lo = dn(py_min(l * au, u * al));
        *hi = up(py_max(l * al, u * au));
    }
}

/* [th_lo, th_hi] containing theta(a, h) = (1 - exp(-a h))/a for a in [alo, ahi], alo > 0 (the
 * runtime's ``_theta``: libm's expm1 within 2 ulps, rounded by 3) */
static void theta(double alo, double ahi, double h, double *tl, double *th)
{
    double hi = -expm1(dn(-alo * h)), lo = -expm1(up(-ahi * h));
    for (int k = 0; k < 3; k++) {
        hi = up(hi);
        lo = dn(lo);
    }
    *tl = py_max(0.0, dn(lo / ahi));
    *th = up(hi / alo);
}

/* An asymmetric stiffness box: the structured rows [rl, ru] intersected with the elementwise bound
 * [dA][x] + vd [dB1] (exact interval products entry by entry); both contain the true value. */
static void intersect_elementwise(const double *l, const double *u, int with_input, double vd,
                                  double rl[2], double ru[2])
{
    for (int k = 0; k < 2; k++) {
        int i = ROW_AY + k;
        double el = 0.0, eu = 0.0, pl, pu;
        for (int j = 0; j < NX; j++) {
            if (IV_DA_LO[i][j] == 0.0 && IV_DA_UP[i][j] == 0.0) continue;
            product_hull(IV_DA_LO[i][j], IV_DA_UP[i][j], l[j], u[j], &pl, &pu);
            el = dn(el + pl);
            eu = up(eu + pu);
        }
        double bl = IV_DB1_LO[i], bu = IV_DB1_UP[i];
        if (with_input && (bl != 0.0 || bu != 0.0)) {
            product_hull(bl, bu, dn(vd), up(vd), &pl, &pu);
            el = dn(el + pl);
            eu = up(eu + pu);
        }
        double sl = rl[k], su = ru[k];
        if (el > sl) sl = el;
        if (eu < su) su = eu;
        if (sl > su) {              /* rounding only: both contain the value */
            double t = sl;
            sl = su;
            su = t;
        }
        rl[k] = sl;
        ru[k] = su;
    }
}

/* Adds to lo/hi (rows x3', x4') the bound of the stiffness part dA(dc) x + vx dB1(dc) delta over x in
 * [l, u] and the stiffness box, by its structure (the runtime's ``_stiffness``): with the slip angles of
 * eq. (4) multiplied out, uf = vx af = vx delta - x1 - lf x2, ur = vx ar = -x1 + lr x2,
 *     dA x + vx dB1 delta = [0, 0, (p + q)/(m sigma), (lf p - lr q)/(Iz sigma)], p = dcf uf, q = dcr ur,
 * by interval arithmetic (exact: p and q are independent). with_input = 0: dA x alone. */
static void stiffness(const double *l, const double *u, int with_input, double vd, double *lo, double *hi)
{
    double ufl, ufu;               /* every operation rounded outward */
    if (with_input) {
        ufl = dn(dn(dn(vd) - u[0]) - up(IV_LF * u[1]));
        ufu = up(up(up(vd) - l[0]) - dn(IV_LF * l[1]));
    } else {
        ufl = dn(-u[0] - up(IV_LF * u[1]));
        ufu = up(-l[0] - dn(IV_LF * l[1]));
    }
    double url = dn(dn(IV_LR * l[1]) - u[0]);
    double uru = up(up(IV_LR * u[1]) - l[0]);
    double pl, pu, ql, qu;
    product_hull(IV_DCF[0], IV_DCF[1], ufl, ufu, &pl, &pu);
    product_hull(IV_DCR[0], IV_DCR[1], url, uru, &ql, &qu);
    double rl[2] = {dn(IV_K3 * dn(pl + ql)), dn(dn(IV_K4F * pl) - up(IV_K4R * qu))};
    double ru[2] = {up(IV_K3 * up(pu + qu)), up(up(IV_K4F * pu) - dn(IV_K4R * ql))};
    if (!IV_STIFF_SYMMETRIC) intersect_elementwise(l, u, with_input, vd, rl, ru);
    for (int k = 0; k < 2; k++) {
        lo[ROW_AY + k] = dn(lo[ROW_AY + k] + rl[k]);
        hi[ROW_AY + k] = up(hi[ROW_AY + k] + ru[k]);
    }
}

/* ------------------------------------------------------------------ the model's right-hand side */
/* G (the runtime's ``G``): the hull [Fg[0..3], Fg[4..7]] of A(vx, c) x + B(vx, c) delta over x in the box
 * X and c in the stiffness box, WITHOUT the diagonal terms of the damped rows; the point matrix
 * A0 + vx A1 by eq. (20) in midpoint-radius form, plus the disturbance bound w. */
static void G(double vx, double d, const double X[NB], double Fg[NB])
{
    double avx = vx >= 0.0 ? vx : -vx, vd = vx * d, c[NX], r[NX], ac[NX];
    mid_rad(X, c, r);
    for (int j = 0; j < NX; j++) ac[j] = fabs(c[j]);
    for (int i = 0; i < NX; i++) {
        double m = 0.0, m1 = 0.0, w = 0.0, w1 = 0.0, a = 0.0, sa1 = 0.0;   /* mid, radius, shadow */
        int has1 = 0, hasr1 = 0;
        for (int j = 0; j < NX; j++) {
            double a0 = a0u(i, j), a1 = a1u(i, j);
            if (a0 != 0.0) {
                m += a0 * c[j];
                a += fabs(a0) * ac[j];
            }
            if (a1 != 0.0) {
                m1 += a1 * c[j];
                sa1 += fabs(a1) * ac[j];
                has1 = 1;
            }
            if (a0 != 0.0 && a1 == 0.0) w += fabs(a0) * r[j];
            if (a0 == 0.0 && a1 != 0.0) {
                w1 += fabs(a1) * r[j];
                hasr1 = 1;
            }
        }
        if (has1) {
            m += vx * m1;
            a += avx * sa1;
        }
        if (hasr1) w += avx * w1;
        for (int j = 0; j < NX; j++)
            if (a0u(i, j) != 0.0 && a1u(i, j) != 0.0) {
                w += fabs(a0u(i, j) + vx * a1u(i, j)) * r[j];
                a += (fabs(a0u(i, j)) + avx * fabs(a1u(i, j))) * r[j];
            }
        if (IV_B1[i] != 0.0) {
            m += vd * IV_B1[i];
            a += fabs(vd * IV_B1[i]);
        }
        if (IV_W[i] != 0.0) w += IV_W[i];
        double R = radius(w, a, 0.0, 16);
        Fg[i] = dn(m - R);
        Fg[NX + i] = up(m + R);
    }
    stiffness(X, X + NX, 1, vd, Fg, Fg + NX);
}

/* F (the runtime's ``F``): G plus the damped rows' diagonal terms d_i(vx) [x_i] */
static void F_hull(double vx, double d, const double X[NB], double F[NB])
{
    G(vx, d, X, F);
    for (int i = 0; i < NX; i++) {
        double alo, ahi, pl, pu;
        if (!IV_DAMPED[i]) continue;
        decay(i, vx, &alo, &ahi);
        product_hull(-ahi, -alo, X[i], X[NX + i], &pl, &pu);
        F[i] = dn(F[i] + pl);
        F[NX + i] = up(F[NX + i] + pu);
    }
}

/* ------------------------------------------------------------------ step maps */
/* max_i sum_j |M[i][j]| of the leading rows x cols block, rows from the first (Python's max) */
static double rows_abs_max(const double M[MAXM][MAXM], int rows, int cols)
{
    double best = 0.0;
    for (int i = 0; i < rows; i++) {
        double t = 0.0;
        for (int j = 0; j < cols; j++) t += fabs(M[i][j]);
        best = i == 0 ? t : py_max(best, t);
    }
    return best;
}

/* exp(M) of the leading mm x mm block (the runtime's ``expm_taylor``, with_error): scaling X = M / 2^s
 * with ||X||_inf <= 1/2, Horner's Taylor series of degree 16, s squarings; *err >= ||E - exp(M)||_inf
 * (the running bound of the runtime's docstring). 0, or -1 if ||M||_inf is not finite or above 1e300
 * (the runtime raises). M is scaled in place. */
static int expm_taylor(double M[MAXM][MAXM], int mm, double E[MAXM][MAXM], double *err)
{
    double P[MAXM][MAXM], norm = 0.0;
    for (int i = 0; i < mm; i++) {
        double row = 0.0;
        for (int j = 0; j < mm; j++) row += fabs(M[i][j]);
        norm = py_max(norm, row);
    }
    if (!(norm <= 1e300)) return -1;
    int s = norm > 0.5 ? (int)ceil(log2(norm / 0.5)) : 0;
    if (s < 0) s = 0;
    double scale = ldexp(1.0, -s);
    for (int i = 0; i < mm; i++)
        for (int j = 0; j < mm; j++) {
            M[i][j] *= scale;
            E[i][j] = i == j ? 1.0 : 0.0;
        }
    double nx = rows_abs_max(M, mm, mm) * (1.0 + 0x1p-40) + mm * ETA_RND, gam = (mm + 2) * U_RND * 1.01;
    double nE = 1.0, e = 0.0;
    for (int k = 16; k > 0; k--) {          /* Horner: I + X/1 (I + X/2 (... (I + X/16))) */
        for (int i = 0; i < mm; i++)
            for (int j = 0; j < mm; j++) {
                double t = 0.0;
                for (int q = 0; q < mm; q++) t += M[i][q] * E[q][j];
                P[i][j] = t;
            }
        for (int i = 0; i < mm; i++)
            for (int j = 0; j < mm; j++) E[i][j] = (i == j ? 1.0 : 0.0) + P[i][j] / k;
        double nE1 = rows_abs_max(E, mm, mm) * (1.0 + 0x1p-40);
        e = (nx * e + gam * nx * nE + mm * ETA_RND) / k + U_RND * nE1;
        nE = nE1;
    }
    e += pow(nx, 17) / 355687428096000.0 / (1.0 - nx / 18.0);     /* the series remainder (17!) */
    double gm = mm * U_RND * 1.01;
    for (int q = 0; q < s; q++) {
        e = e * (2.0 * nE + e) + gm * nE * nE + mm * ETA_RND;
        for (int i = 0; i < mm; i++)
            for (int j = 0; j < mm; j++) {
                double t = 0.0;
                for (int k = 0; k < mm; k++) t += E[i][k] * E[k][j];
                P[i][j] = t;
            }
        for (int i = 0; i < mm; i++)
            for (int j = 0; j < mm; j++) E[i][j] = P[i][j];
        nE = rows_abs_max(E, mm, mm) * (1.0 + 0x1p-40);
    }
    *err = up(e * SLACK);
    return 0;
}

/* (Phi, Gam[, Gam1, Gam2]) = (exp(N h), int_0^h exp(N s) ds, ...) for a Metzler N with N + eta I >= 0
 * (the runtime's ``phi_gamma`` with_error, nb = order + 1 blocks): exp of the nonnegative block matrix
 * [[N + eta I, I, ..], [0, eta I, I, ..], ..] h by scaling (||X||_inf <= 1/2), Horner's Taylor
 * series of degree 16 and squaring, times exp(-eta h); *err >= every entry's error (infinite: no
 * useful bound). 0, or -1 if the norm is not finite or an entry is negative (the runtime raises). */
static int phi_gamma(const double N[NX][NX], double h, double eta, int nb, double out[][NX][NX], double *err)
{
    int mm = nb * NX;
    double M[MAXM][MAXM], E[MAXM][MAXM], e;
    memset(M, 0, sizeof M);
    for (int i = 0; i < NX; i++)
        for (int j = 0; j < NX; j++) M[i][j] = (N[i][j] + (i == j ? eta : 0.0)) * h;
    for (int b = 1; b < nb; b++)
        for (int i = 0; i < NX; i++) {
            M[(b - 1) * NX + i][b * NX + i] = h;
            M[b * NX + i][b * NX + i] = eta * h;
        }
    for (int i = 0; i < mm; i++)
        for (int j = 0; j < mm; j++)
            if (!(M[i][j] >= 0.0)) return -1;
    double damp = exp(-eta * h), nM = 0.0;
    for (int i = 0; i < mm; i++) {
        double t = 0.0;
        for (int j = 0; j < mm; j++) t += M[i][j];
        nM = i == 0 ? t : py_max(nM, t);
    }
    nM *= 1.0 + 0x1p-40;
    if (expm_taylor(M, mm, E, &e) != 0) return -1;
    double nE = rows_abs_max(E, mm, mm) * (1.0 + 0x1p-40), eps = 2.01 * U_RND, eh = eta * h;
    e += eps * nM * exp(eps * nM) * (nE + e);
    e = up((e * (1.0 + 8.0 * U_RND) + nE * (6.0 * U_RND + 2.0 * U_RND * eh)) * damp * SLACK);
    *err = isfinite(e) ? e : INFINITY;
    for (int b = 0; b < nb; b++)
        for (int i = 0; i < NX; i++)
            for (int j = 0; j < NX; j++) out[b][i][j] = E[i][b * NX + j] * damp;
    return 0;
}

/* C = A B for A (NX x NX) and B (NX x NY), sums from the left (the runtime's ``_matmul``) */
static void mul_nxy(const double A[NX][NX], const double B[NX][NY], double C[NX][NY])
{
    for (int i = 0; i < NX; i++)
        for (int c = 0; c < NY; c++) {
            double t = 0.0;
            for (int k = 0; k < NX; k++) t += A[i][k] * B[k][c];
            C[i][c] = t;
        }
}

static void mul_nxx(const double A[NX][NX], const double B[NX][NX], double C[NX][NX])
{
    for (int i = 0; i < NX; i++)
        for (int c = 0; c < NX; c++) {
            double t = 0.0;
            for (int k = 0; k < NX; k++) t += A[i][k] * B[k][c];
            C[i][c] = t;
        }
}

/* the correction coefficients of (mode, h) from its maps (the runtime's ``_core``) */
static void core_fill(Core *k, int mode, double h, const double maps[N_MAPS][NX][NX], double e)
{
    const double (*Gam)[NX] = maps[1], (*Gam1)[NX] = maps[2], (*Gam2)[NX] = maps[3];
    const double (*J)[NY] = IV_J[mode], (*P)[NX] = IV_P[mode];
    double W0[NX][NX], W1[NX][NX], W2[NX][NX], W3[NX][NX], aJ[NX][NY], aP[NX][NX];
    double W0J[NX][NY], W1J[NX][NY], W2J[NX][NY], W2aJ[NX][NY], W3aJ[NX][NY];
    for (int i = 0; i < NX; i++) {
        for (int j = 0; j < NX; j++) {
            W1[i][j] = Gam1[i][j] / h;
            W0[i][j] = Gam[i][j] - W1[i][j];
            W2[i][j] = fabs(h * Gam1[i][j] / 2 - Gam2[i][j]);
            W3[i][j] = 2 * W2[i][j] / h;
            aP[i][j] = fabs(P[i][j]);
        }
        for (int c = 0; c < NY; c++) aJ[i][c] = fabs(J[i][c]);
    }
    mul_nxy(W0, J, W0J);
    mul_nxy(W1, J, W1J);
    mul_nxy(W2, J, W2J);
    mul_nxy(W2, aJ, W2aJ);
    mul_nxy(W3, aJ, W3aJ);
    for (int i = 0; i < NX; i++) {
        for (int c = 0; c < NY; c++) {
            int smooth = IV_SMOOTH[MEAS[c]];
            k->w0j[i][c] = W0J[i][c];
            k->aw0j[i][c] = fabs(W0J[i][c]);
            k->w1j[i][c] = W1J[i][c];
            k->aw1j[i][c] = fabs(W1J[i][c]);
            k->w2j_neg[i][c] = smooth ? -W2J[i][c] : 0.0;
            k->w2aj[i][c] = smooth ? W2aJ[i][c] : 0.0;
            k->w3aj2[i][c] = smooth ? 0.0 : 2.0 * W3aJ[i][c];
        }
        double t = 0.0;
        for (int j = 0; j < NX; j++) t += Gam[i][j] * IV_H[mode][j];
        k->gh[i] = t;
    }
    memcpy(k->phi, maps[0], sizeof k->phi);
    /* the coefficients' error bounds and Gam's row sums (the runtime's ``_core``) */
    double g = 0.0, cJ = 0.0, cP = 0.0, sH = 0.0, t;
    int first = 1;
    for (int b = 0; b < N_MAPS; b++)
        for (int i = 0; i < NX; i++)
            for (int j = 0; j < NX; j++) {
                g = first ? fabs(maps[b][i][j]) : py_max(g, fabs(maps[b][i][j]));
                first = 0;
            }
    for (int c = 0; c < NY; c++) {
        t = 0.0;
        for (int i = 0; i < NX; i++) t += fabs(J[i][c]);
        cJ = c == 0 ? t : py_max(cJ, t);
    }
    for (int c = 0; c < NX; c++) {
        t = 0.0;
        for (int i = 0; i < NX; i++) t += fabs(P[i][c]);
        cP = c == 0 ? t : py_max(cP, t);
    }
    for (int j = 0; j < NX; j++) sH += fabs(IV_H[mode][j]);
    double eW1 = (e + U_RND * g) / h, eW0 = e + eW1 + U_RND * (g + g / h);
    double eW2 = e * (1.0 + h) + 2.0 * U_RND * g * (1.0 + h), eW3 = 2.0 * eW2 / h + U_RND * g * (1.0 + 2.0 / h);
    double gW = g * (2.0 + 2.0 / h);
    k->err_phi = e;
    k->err_w0j = up((eW0 + 5.0 * U_RND * gW) * cJ * SLACK);
    k->err_w1j = up((eW1 + 5.0 * U_RND * gW) * cJ * SLACK);
    k->err_w2j = up((eW2 + 5.0 * U_RND * gW) * cJ * SLACK);
    k->err_w3j = up(2.0 * (eW3 + 5.0 * U_RND * gW) * cJ * SLACK);
    k->err_gp = up((e + 5.0 * U_RND * g) * cP * SLACK);
    k->err_gh = up((e + 5.0 * U_RND * g) * sH * SLACK);
    for (int i = 0; i < NX; i++) {
        t = 0.0;
        for (int j = 0; j < NX; j++) t += Gam[i][j];
        k->gsum[i] = up(t * (1.0 + 8.0 * U_RND) + 4.0 * e);
    }
    mul_nxx(Gam, P, k->gp);
    mul_nxx(Gam, aP, k->gap);
    mul_nxx(Gam1, P, k->g1p);
    mul_nxx(Gam1, aP, k->g1ap);
}

/* The correction of (mode, h) (the runtime's ``_core``): cached; the enclosure's substeps hs = h /
 * nsub with hs rho(|A|) <= IV_SUBSTEP_RHO_H at the band's top speed. NULL (an error logged) if
 * its maps are not finite or it needs more than MAX_SUBSTEPS substeps. */
static const Core *core_for(Model *m, int mode, double h, const Log *log)
{
    Core *k = &m->core[mode];
    double maps[N_MAPS][NX][NX], nsub = ceil(h * IV_RHO[mode] / IV_SUBSTEP_RHO_H - 1e-9), e;
    if (k->h == h) return k;
    if (!(nsub <= MAX_SUBSTEPS)) {
        log_event(log, LOG_ERROR, "step refused: h = %g s would need %g enclosure substeps (at most %d)", h, nsub,
                  MAX_SUBSTEPS);
        return NULL;
    }
    if (h == IV_H0) {
        memcpy(maps, IV_MAPS_H0[mode], sizeof maps);
        e = IV_MAPS_H0_ERROR[mode];
    } else if (phi_gamma(IV_N[mode], h, IV_ETA[mode], N_MAPS, maps, &e) != 0 || !isfinite(e)) {
        log_event(log, LOG_ERROR, "step refused: no finite step map of mode %d for h = %g s", mode + 1, h);
        return NULL;
    }
    core_fill(k, mode, h, maps, e);
    k->nsub = nsub > 1.0 ? (int)nsub : 1;
    k->hs = h / k->nsub;
    k->h = h;
    return k;
}

/* ------------------------------------------------------------------ a priori enclosure (step 4) */
/* T(S) (the runtime's ``_extents``), rounded outward: the enclosure of x over a substep hs from the box
 * X and G's values Fg over S: a damped row with a in [alo, ahi], alo > 0, by the convex combination
 * x_i(s) = x_i(0) + theta(s) (g - a x_i(0)), theta in [0, th]; another damped row x_i(0) + [0, hs]
 * (g - a S_i); otherwise x_i(s) in x_i(0) + [0, hs] G_i(S). */
static void extents(double hs, const double alo[NX], const double ahi[NX], const double th[NX],
                    const double X[NB], const double Fg[NB], const double S[NB], double T[NB])
{
    for (int i = 0; i < NX; i++) {
        double l = X[i], u = X[NX + i], gl = Fg[i], gu = Fg[NX + i], t, pl, pu;
        if (IV_DAMPED[i]) {
            if (alo[i] > 0.0) {
                product_hull(alo[i], ahi[i], l, l, &pl, &pu);
                t = dn(gl - pu);
                T[i] = t < 0.0 ? dn(l + dn(th[i] * t)) : l;
                product_hull(alo[i], ahi[i], u, u, &pl, &pu);
                t = up(gu - pl);
                T[NX + i] = t > 0.0 ? up(u + up(th[i] * t)) : u;
                continue;
            }
            product_hull(alo[i], ahi[i], S[i], S[NX + i], &pl, &pu);
            gl = dn(gl - pu);
            gu = up(gu - pl);
        }
        T[i] = gl < 0.0 ? dn(l + dn(hs * gl)) : l;
        T[NX + i] = gu > 0.0 ? up(u + up(hs * gu)) : u;
    }
}

/* The a priori enclosure T of x over [0, hs] from the box X (the runtime's ``_enclose``): S is accepted
 * when T(S) lies in S (then x(s) is in T(S) for all s), starting from X extended by
 * IV_ENCLOSURE_GROW times the extents of T(X), then by that factor times the never-shrinking
 * extents of the last T(S); one refining pass T(T). 0, or -1 after IV_ENCLOSURE_TRIES tries. */
static int enclose(double hs, double vx, double d, const double X[NB], double T[NB])
{
    double alo[NX] = {0.0}, ahi[NX] = {0.0}, th[NX] = {0.0}, Fg[NB], S[NB], e[NB], tl;
    for (int i = 0; i < NX; i++) {
        if (!IV_DAMPED[i]) continue;
        decay(i, vx, &alo[i], &ahi[i]);
        if (alo[i] > 0.0) theta(alo[i], ahi[i], hs, &tl, &th[i]);
    }
    G(vx, d, X, Fg);
    extents(hs, alo, ahi, th, X, Fg, X, T);
    for (int i = 0; i < NB; i++) e[i] = T[i] - X[i];
    double grow = IV_ENCLOSURE_GROW;
    for (int k = 0; k < IV_ENCLOSURE_TRIES; k++) {
        int inside = 1;
        for (int i = 0; i < NB; i++) S[i] = X[i] + grow * e[i];
        G(vx, d, S, Fg);
        extents(hs, alo, ahi, th, X, Fg, S, T);
        for (int i = 0; i < NX; i++) inside = inside && T[i] >= S[i] && T[NX + i] <= S[NX + i];
        if (inside) {                 /* x(s) in T for all s, hence in T(T), a subset */
            G(vx, d, T, Fg);
            memcpy(S, T, sizeof S);
            extents(hs, alo, ahi, th, X, Fg, S, T);
            return 0;
        }
        for (int i = 0; i < NX; i++) {    /* the extents never shrink */
            double t = T[i] - X[i];
            if (t < e[i]) e[i] = t;
            t = T[NX + i] - X[NX + i];
            if (t > e[NX + i]) e[NX + i] = t;
        }
        if (IV_ENCLOSURE_MULT != 1.0) grow = IV_ENCLOSURE_MULT * grow;
    }
    return -1;
}

/* Metzler majorant of A(vx, c) over the stiffness box (the runtime's ``_majorant``): the largest
 * diagonal entries and the largest |off-diagonal| entries, rounded up */
static void majorant(double vx, double M[NX][NX])
{
    for (int i = 0; i < NX; i++)
        for (int j = 0; j < NX; j++) {
            double a0 = IV_A0[i][j], a1 = IV_A1[i][j];
            double lo = dn(dn(a0 + dn(vx * a1)) + IV_DA_LO[i][j]), hi = up(up(a0 + up(vx * a1)) + IV_DA_UP[i][j]);
            M[i][j] = i == j ? hi : py_max(fabs(lo), fabs(hi));
        }
}

/* Fallback enclosure for any hs (``_comparison_enclosure``): |x(s) - x_k| <= Gamma(M, hs) g with M
 * the Metzler majorant and g = max |F(X)| (comparison principle; Gamma within its bracket, the sum
 * rounded up), intersected with X + [0, hs] F(S). 0, or -1 if Gamma(M, hs) has no finite bound. */
static int comparison_enclosure(double hs, double vx, double d, const double X[NB], double T[NB])
{
    double f[NB], g[NX], M[NX][NX], maps[2][NX][NX], S[NB], shift = 0.0, e, sg = 0.0;
    F_hull(vx, d, X, f);
    for (int i = 0; i < NX; i++) g[i] = py_max(fabs(f[i]), fabs(f[NX + i]));
    majorant(vx, M);
    double top = -M[0][0];
    for (int i = 1; i < NX; i++) top = py_max(top, -M[i][i]);
    shift = py_max(0.0, top);
    if (phi_gamma(M, hs, shift, 2, maps, &e) != 0 || !isfinite(e)) return -1;
    for (int i = 0; i < NX; i++) sg += g[i];
    for (int i = 0; i < NX; i++) {
        double R = 0.0;
        for (int j = 0; j < NX; j++) R += maps[1][i][j] * g[j];
        R = up(R * (1.0 + 8.0 * U_RND) + e * sg * (1.0 + 8.0 * U_RND));
        S[i] = dn(X[i] - R);
        S[NX + i] = up(X[NX + i] + R);
    }
    F_hull(vx, d, S, f);
    for (int i = 0; i < NX; i++) {
        double lo = f[i] < 0.0 ? dn(X[i] + dn(hs * f[i])) : X[i];
        double hi = f[NX + i] > 0.0 ? up(X[NX + i] + up(hs * f[NX + i])) : X[NX + i];
        T[i] = py_max(S[i], lo);
        T[NX + i] = py_min(S[NX + i], hi);
    }
    return 0;
}

/* ------------------------------------------------------------------ the sampled-measurement correction */
/* (Phi, Gam) = (exp(A h), int_0^h exp(A s) ds) for ANY A (the runtime's ``expm_gamma``): exp of
 * [[A, I], [0, 0]] h by scaling (||X||_inf <= 1/2), Horner's Taylor series of degree 16, squaring;
 * *err >= every entry's error for any exact A' within dA (inf-norm) of A. 0, or -1 if the norm is
 * not finite (the runtime raises). */
static int expm_gamma(const double A[NX][NX], double h, double dA, double Phi[NX][NX], double Gam[NX][NX],
                      double *err)
{
    double M[MAXM][MAXM], E[MAXM][MAXM], e;
    memset(M, 0, sizeof M);
    for (int i = 0; i < NX; i++) {
        for (int j = 0; j < NX; j++) M[i][j] = A[i][j] * h;
        M[i][NX + i] = h;
    }
    double nM = rows_abs_max(M, 2 * NX, 2 * NX);
    if (expm_taylor(M, 2 * NX, E, &e) != 0) return -1;
    double nD = (dA * h + 2.0 * U_RND * nM) * SLACK + 2 * NX * ETA_RND;
    e = up((e + nD * exp(nM + nD)) * SLACK);
    *err = isfinite(e) ? e : INFINITY;
    for (int i = 0; i < NX; i++)
        for (int j = 0; j < NX; j++) {
            Phi[i][j] = E[i][j];
            Gam[i][j] = E[i][NX + j];
        }
    return 0;
}

static void mat_abs(const double A[NX][NX], double B[NX][NX])
{
    for (int i = 0; i < NX; i++)
        for (int j = 0; j < NX; j++) B[i][j] = fabs(A[i][j]);
}

/* y = A x (sums from the left, the runtime's ``_matvec``) */
static void matvec(const double A[NX][NX], const double *x, double *y)
{
    for (int i = 0; i < NX; i++) {
        double t = 0.0;
        for (int j = 0; j < NX; j++) t += A[i][j] * x[j];
        y[i] = t;
    }
}

/* y = |A| x */
static void matvec_abs(const double A[NX][NX], const double *x, double *y)
{
    for (int i = 0; i < NX; i++) {
        double t = 0.0;
        for (int j = 0; j < NX; j++) t += fabs(A[i][j]) * x[j];
        y[i] = t;
    }
}

static void matvec_y(const double A[NX][NY], const double *x, double *y)
{
    for (int i = 0; i < NX; i++) {
        double t = 0.0;
        for (int j = 0; j < NY; j++) t += A[i][j] * x[j];
        y[i] = t;
    }
}

/* max row sum of |A| (the runtime's ``_norm_rows``: rounded up); of A' when by_columns */
static double norm_abs(const double A[NX][NX], int by_columns)
{
    double best = 0.0;
    for (int i = 0; i < NX; i++) {
        double t = 0.0;
        for (int j = 0; j < NX; j++) t += fabs(by_columns ? A[j][i] : A[i][j]);
        best = i == 0 ? t : py_max(best, t);
    }
    return up(best * (1.0 + 4.0 * U_RND));
}

static double max_abs(const double *x, int n)
{
    double best = fabs(x[0]);
    for (int j = 1; j < n; j++) best = py_max(best, fabs(x[j]));
    return best;
}

/* C = A B and the bound of its entries' errors (the runtime's ``_mm_err``) */
static double mm_err(const double A[NX][NX], double eA, const double B[NX][NX], double eB, double C[NX][NX])
{
    double ra = norm_abs(A, 0), cb = norm_abs(B, 1), bmax = max_abs(&B[0][0], NX * NX);
    mul_nxx(A, B, C);
    return up((ra * eB + eA * cb + NX * eA * eB + (NX + 2) * U_RND * ra * bmax) * SLACK + NX * ETA_RND);
}

/* y = A v and the bound of its entries' errors (the runtime's ``_mv_err``) */
static double mv_err(const double A[NX][NX], double eA, const double v[NX], double ev, double y[NX])
{
    double ra = norm_abs(A, 0), va = sum_abs(v, NX), vmax = max_abs(v, NX);
    matvec(A, v, y);
    return up((ra * ev + eA * va + NX * eA * ev + (NX + 2) * U_RND * ra * vmax) * SLACK + NX * ETA_RND);
}

/* The maps of (vq, h) (the runtime's ``_sampled_maps``, same order of operations), each with the
 * bound of its entries' errors: 0, or -1 (none). */
static int sampled_fill(Sampled *sm, double vq, double h)
{
    double A[NX][NX], Al[NX][NX], Au[NX][NX], W[NX][NX], Bv[NX], phid[NX][NX], gamd[NX][NX], Mj[NX][NX];
    double gm[2][NX][NX], gdb[NX], t[NX], eye[NX][NX], shift = 0.0, top, ed, eM, eBv, egdb;
    sm->valid = 0;
    for (int i = 0; i < NX; i++) {
        for (int j = 0; j < NX; j++) {
            A[i][j] = IV_A0[i][j] + vq * IV_A1[i][j];
            Al[i][j] = dn(IV_A0[i][j] + dn(vq * IV_A1[i][j]));
            Au[i][j] = up(IV_A0[i][j] + up(vq * IV_A1[i][j]));
            eye[i][j] = i == j ? 1.0 : 0.0;
        }
        Bv[i] = vq * IV_B1[i];
    }
    for (int i = 0; i < NX; i++)
        for (int j = 0; j < NX; j++) W[i][j] = Au[i][j] - Al[i][j];
    double dA = norm_abs(W, 0);
    eBv = up(max_abs(Bv, NX) * 2.0 * U_RND);
    double nd = ceil(h / IV_SAMPLED_SUBSTEP - 1e-9);
    int n = !(nd >= 1.0) ? 1 : nd > IV_SAMPLED_MAX_SUBSTEPS ? IV_SAMPLED_MAX_SUBSTEPS : (int)nd, p2 = 1;
    while (p2 < n) p2 <<= 1;             /* a power of two: h / n exact */
    if (p2 > IV_SAMPLED_MAX_SUBSTEPS) return -1;
    n = p2;
    double hs = h / n, norm = 0.0;
    for (int i = 0; i < NX; i++) {
        double row = 0.0;
        for (int j = 0; j < NX; j++) row += fabs(A[i][j]);
        norm = i == 0 ? row : py_max(norm, row);
    }
    if (!(norm * hs <= IV_SAMPLED_MAX_NORM)) return -1;     /* |vx| far beyond any vehicle */
    if (expm_gamma(A, hs, dA, phid, gamd, &ed) != 0) return -1;
    for (int i = 0; i < NX; i++)
        for (int j = 0; j < NX; j++) Mj[i][j] = i == j ? Au[i][j] : py_max(fabs(Al[i][j]), fabs(Au[i][j]));
    top = -Mj[0][0];
    for (int i = 1; i < NX; i++) top = py_max(top, -Mj[i][i]);
    shift = py_max(0.0, top);
    if (phi_gamma(Mj, hs, shift, 2, gm, &eM) != 0) return -1;
    egdb = mv_err(gamd, ed, Bv, eBv, gdb);
    /* phi[m] = phi[m-1] phid: errors summed against the computed powers (linear in m, see the runtime) */
    double nphi[IV_SAMPLED_MAX_SUBSTEPS + 1], cs[IV_SAMPLED_MAX_SUBSTEPS], ndd = norm_abs(phid, 0);
    memcpy(sm->phi[0], eye, sizeof eye);
    for (int i = 0; i < NX; i++) sm->gamb[0][i] = 0.0;
    sm->ephi[0] = 0.0;
    sm->egamb[0] = 0.0;
    nphi[0] = 1.0;
    for (int m = 1; m <= n; m++) {
        double eg = mv_err(sm->phi[m - 1], sm->ephi[m - 1], gdb, egdb, t);
        for (int i = 0; i < NX; i++) sm->gamb[m][i] = sm->gamb[m - 1][i] + t[i];
        sm->egamb[m] = up((sm->egamb[m - 1] + eg + 2.0 * U_RND * max_abs(sm->gamb[m], NX)) * SLACK);
        cs[m - 1] = (nphi[m - 1] * ed + 6.0 * U_RND * nphi[m - 1] * ndd) * SLACK + NX * ETA_RND;
        mul_nxx(sm->phi[m - 1], phid, sm->phi[m]);
        nphi[m] = norm_abs(sm->phi[m], 0);
        double e = 0.0;
        for (int k = 1; k <= m; k++) e += cs[k - 1] * (nphi[m - k] + sm->ephi[m - k]);
        sm->ephi[m] = up(e * SLACK);
    }
    for (int m = 0; m <= n; m++) mat_abs(sm->phi[m], sm->aphi[m]);
    for (int m = 0; m < n; m++) {
        sm->epg[m] = mm_err(sm->phi[m], sm->ephi[m], gamd, ed, sm->pg[m]);
        sm->eapg[m] = mm_err(sm->aphi[m], sm->ephi[m], gm[1], eM, sm->apg[m]);
    }
    /* the gains: the deadbeat one, one column by one measurement (``_sampled_maps``) */
    const double (*ph)[NX] = sm->phi[n];
    double opts[1 + NY * NY][NY][NY];   /* per option: the unmeasured rows' L (row k = UNMEAS[k]) */
    int nopt = 0;
    double D[NY][NY];
    for (int q = 0; q < NY; q++)
        for (int k = 0; k < NY; k++) D[q][k] = ph[MEAS[q]][UNMEAS[k]];
    double det = D[0][0] * D[1][1] - D[0][1] * D[1][0];
    if (det != 0.0 && isfinite(det)) {
        double inv[NY][NY] = {{D[1][1] / det, -D[0][1] / det}, {-D[1][0] / det, D[0][0] / det}};
        for (int r = 0; r < NY; r++)
            for (int q = 0; q < NY; q++) {
                double s = 0.0;
                for (int k = 0; k < NY; k++) s += ph[UNMEAS[r]][UNMEAS[k]] * inv[k][q];
                opts[nopt][r][q] = s;
            }
        nopt++;
    }
    for (int kj = 0; kj < NY; kj++) {
        int j = UNMEAS[kj];
        for (int q = 0; q < NY; q++) {
            int jm = MEAS[q];
            if (ph[jm][j] == 0.0) continue;
            for (int r = 0; r < NY; r++)
                for (int qq = 0; qq < NY; qq++) opts[nopt][r][qq] = qq == q ? ph[UNMEAS[r]][j] / ph[jm][j] : 0.0;
            nopt++;
        }
    }
    sm->nc = 0;
    for (int o = 0; o < nopt; o++) {
        SampledGain *g = &sm->c[sm->nc];
        double K[NX][NX], KP[NX][NX], eK;
        int finite = 1;
        memset(g->L, 0, sizeof g->L);
        for (int q = 0; q < NY; q++) g->L[MEAS[q]][q] = 1.0;
        for (int r = 0; r < NY; r++)
            for (int q = 0; q < NY; q++) g->L[UNMEAS[r]][q] = opts[o][r][q];
        for (int i = 0; i < NX; i++)
            for (int q = 0; q < NY; q++) finite = finite && isfinite(g->L[i][q]);
        if (!finite) continue;
        for (int i = 0; i < NX; i++) {
            for (int q = 0; q < NY; q++) g->aL[i][q] = fabs(g->L[i][q]);
            for (int j = 0; j < NX; j++) {
                double s = 0.0;
                for (int q = 0; q < NY; q++)
                    if (MEAS[q] == j) s += g->L[i][q];
                K[i][j] = eye[i][j] - s;
            }
        }
        eK = up(max_abs(&K[0][0], NX * NX) * U_RND);
        g->ekphi = mm_err(K, eK, ph, sm->ephi[n], g->kphi);
        mat_abs(g->kphi, g->akphi);
        g->ekgb = mv_err(K, eK, sm->gamb[n], sm->egamb[n], g->kgb);
        for (int m = 0; m < n; m++) {
            g->ekpg[m] = mm_err(K, eK, sm->pg[m], sm->epg[m], g->kpg[m]);
            double ek = mm_err(K, eK, sm->phi[m], sm->ephi[m], KP);
            mat_abs(KP, KP);
            g->eakpg[m] = mm_err(KP, ek, gm[1], eM, g->akpg[m]);
        }
        sm->nc++;
    }
    sm->n = n;
    sm->hs = hs;
    sm->vq = vq;
    sm->h = h;
    sm->valid = 1;
    return 0;
}

/* the maps of (vq, h) from the cache (SM_CACHE entries, the oldest replaced); NULL: none */
static const Sampled *sampled_get(Model *m, double vq, double h)
{
    for (int k = 0; k < SM_CACHE; k++)
        if (m->sm[k].valid && m->sm[k].vq == vq && m->sm[k].h == h) return &m->sm[k];
    Sampled *sm = &m->sm[m->sm_next];
    m->sm_next = (m->sm_next + 1) % SM_CACHE;
    return sampled_fill(sm, vq, h) == 0 ? sm : NULL;
}

/* The box of x(t + h) by the model alone from the box X of x(t) (the runtime's ``_sampled_predict``,
 * rounded rigorously), and what ``sampled_correct`` needs (p->sm_*). 0, or -1 (skipped: no map or no
 * finite enclosure). */
static int sampled_predict(Model *m, double h, double vx, double d, const double X[NB], double Bm[NB], Pending *p)
{
    double vq = IV_SAMPLED_DV * rint(vx / IV_SAMPLED_DV), dv = vx - vq, adv = fabs(dv), ad = fabs(d);
    const Sampled *sm = sampled_get(m, vq, h);
    double c[NX], r[NX], a[NX], t[NX], ac0[NX], amo[NX], T[NB], S[NB], tc[NX], tr[NX], atc[NX], ms[NX], rs[NX];
    if (sm == NULL) return -1;
    p->sm_vq = vq;
    mid_rad(X, p->sm_c0, p->sm_r0);
    for (int i = 0; i < NX; i++) ac0[i] = fabs(p->sm_c0[i]);
    p->sm_s0 = sum_abs(p->sm_c0, NX);
    {
        double s = 0.0;
        for (int i = 0; i < NX; i++) s += p->sm_r0[i];
        p->sm_s0 = p->sm_s0 + s;
    }
    for (int k = 0; k <= sm->n; k++) {
        matvec(sm->phi[k], p->sm_c0, c);
        for (int i = 0; i < NX; i++) c[i] = c[i] + sm->gamb[k][i] * d;
        matvec(sm->aphi[k], p->sm_r0, r);
        matvec(sm->aphi[k], ac0, a);
        for (int i = 0; i < NX; i++) a[i] = a[i] + fabs(sm->gamb[k][i] * d);
        double e = sm->ephi[k] * p->sm_s0 + sm->egamb[k] * ad;
        for (int i = 0; i < k; i++) {
            matvec(sm->pg[k - 1 - i], p->sm_mo[i], t);
            for (int j = 0; j < NX; j++) c[j] = c[j] + t[j];
            matvec(sm->apg[k - 1 - i], p->sm_ro[i], t);
            for (int j = 0; j < NX; j++) r[j] = r[j] + t[j];
            for (int j = 0; j < NX; j++) amo[j] = fabs(p->sm_mo[i][j]);
            matvec_abs(sm->pg[k - 1 - i], amo, t);
            for (int j = 0; j < NX; j++) a[j] = a[j] + t[j];
            double sro = 0.0;
            for (int j = 0; j < NX; j++) sro += p->sm_ro[i][j];
            e += sm->epg[k - 1 - i] * p->sm_so[i] + sm->eapg[k - 1 - i] * sro;
        }
        for (int i = 0; i < NX; i++) {
            double R = radius(r[i], a[i], e, 8 * k + 8);
            Bm[i] = dn(c[i] - R);
            Bm[NX + i] = up(c[i] + R);
        }
        if (k == sm->n) break;
        if (enclose(sm->hs, vx, d, Bm, T) != 0 && comparison_enclosure(sm->hs, vx, d, Bm, T) != 0) return -1;
        for (int i = 0; i < NB; i++) S[i] = 0.0;
        stiffness(T, T + NX, 1, vx * d, S, S + NX);
        mid_rad(T, tc, tr);
        mid_rad(S, ms, rs);
        for (int j = 0; j < NX; j++) atc[j] = fabs(tc[j]);
        for (int i = 0; i < NX; i++) {
            double x = 0.0, ar = 0.0, aa = 0.0, b1 = IV_B1[i];
            for (int j = 0; j < NX; j++) x += IV_A1[i][j] * tc[j];
            x = x + b1 * d;
            p->sm_mo[k][i] = ms[i] + dv * x;
            for (int j = 0; j < NX; j++) ar += fabs(IV_A1[i][j]) * tr[j];
            double tt = rs[i] + IV_W[i] + adv * ar;
            for (int j = 0; j < NX; j++) aa += fabs(IV_A1[i][j]) * atc[j];
            double sa = fabs(ms[i]) + adv * (aa + fabs(b1 * d));
            p->sm_ro[k][i] = radius(tt, sa, 0.0, 12);
        }
        {
            double s = sum_abs(p->sm_mo[k], NX), s2 = 0.0;
            for (int i = 0; i < NX; i++) s2 += p->sm_ro[k][i];
            p->sm_so[k] = s + s2;
        }
    }
    return all_finite(Bm, NB) ? 0 : -1;
}

/* The box of x(t + h) once the measured states lie in [ylo, yhi] (the runtime's ``_sampled_correct``):
 * every gain's enclosure, rounded rigorously, intersected row by row. 0, or -1 (no map). */
static int sampled_correct(Model *m, const Pending *p, const double ylo[NY], const double yhi[NY], double out[NB])
{
    const Sampled *sm = sampled_get(m, p->sm_vq, p->h);
    double Y[2 * NY], yc[NY], yr[NY], ayc[NY], ac0[NX], c[NX], r[NX], a[NX], t[NX], amo[NX], ad = fabs(p->d);
    double sro[IV_SAMPLED_MAX_SUBSTEPS];
    if (sm == NULL) return -1;
    for (int q = 0; q < NY; q++) {
        Y[q] = ylo[q];
        Y[NY + q] = yhi[q];
    }
    mid_rad_n(Y, NY, yc, yr);
    for (int q = 0; q < NY; q++) ayc[q] = fabs(yc[q]);
    for (int i = 0; i < NX; i++) ac0[i] = fabs(p->sm_c0[i]);
    for (int i = 0; i < sm->n; i++) {
        double s = 0.0;
        for (int j = 0; j < NX; j++) s += p->sm_ro[i][j];
        sro[i] = s;
    }
    for (int i = 0; i < NX; i++) {
        out[i] = -INFINITY;
        out[NX + i] = INFINITY;
    }
    for (int g = 0; g < sm->nc; g++) {
        const SampledGain *k = &sm->c[g];
        matvec(k->kphi, p->sm_c0, c);
        for (int i = 0; i < NX; i++) c[i] = c[i] + k->kgb[i] * p->d;
        matvec_y(k->L, yc, t);
        for (int i = 0; i < NX; i++) c[i] = c[i] + t[i];
        matvec(k->akphi, p->sm_r0, r);
        matvec_y(k->aL, yr, t);
        for (int i = 0; i < NX; i++) r[i] = r[i] + t[i];
        matvec(k->akphi, ac0, a);
        for (int i = 0; i < NX; i++) a[i] = a[i] + fabs(k->kgb[i] * p->d);
        matvec_y(k->aL, ayc, t);
        for (int i = 0; i < NX; i++) a[i] = a[i] + t[i];
        double e = k->ekphi * p->sm_s0 + k->ekgb * ad;
        for (int i = 0; i < sm->n; i++) {
            matvec(k->kpg[sm->n - 1 - i], p->sm_mo[i], t);
            for (int j = 0; j < NX; j++) c[j] = c[j] + t[j];
            matvec(k->akpg[sm->n - 1 - i], p->sm_ro[i], t);
            for (int j = 0; j < NX; j++) r[j] = r[j] + t[j];
            for (int j = 0; j < NX; j++) amo[j] = fabs(p->sm_mo[i][j]);
            matvec_abs(k->kpg[sm->n - 1 - i], amo, t);
            for (int j = 0; j < NX; j++) a[j] = a[j] + t[j];
            e += k->ekpg[sm->n - 1 - i] * p->sm_so[i] + k->eakpg[sm->n - 1 - i] * sro[i];
        }
        for (int i = 0; i < NX; i++) {
            double R = radius(r[i], a[i], e, 8 * sm->n + 8), lo = dn(c[i] - R), hi = up(c[i] + R);
            if (lo > out[i]) out[i] = lo;
            if (hi < out[NX + i]) out[NX + i] = hi;
        }
    }
    return 0;
}

/* lo/hi of a box intersected with another, row by row, where the intersection is not empty */
static void intersect_box(double *B, const double *S)
{
    for (int i = 0; i < NX; i++) {
        double lo = py_max(B[i], S[i]), hi = py_min(B[NX + i], S[NX + i]);
        if (lo <= hi) {
            B[i] = lo;
            B[NX + i] = hi;
        }
    }
}

/* The prediction (the runtime's ``_predict``): out = [Fbar (8), B (8)], Fbar the hull of F over T and B the
 * box of x(t + h) from the box X of x(t): a damped row with a > 0 exactly (convex combination, theta(h)
 * in [th_lo, th_hi]), the others x(h) in x(0) + h Fbar; intersected with T; rounded outward. */
static void predict(double h, double vx, double d, const double X[NB], const double T[NB], double out[2 * NB])
{
    double *fl = out, *fu = out + NX, *bl = out + NB, *bu = out + NB + NX;
    G(vx, d, T, out);
    for (int i = 0; i < NX; i++) {
        double l = X[i], u = X[NX + i], alo, ahi, pl, pu, tl, th, t;
        if (IV_DAMPED[i]) {
            decay(i, vx, &alo, &ahi);
            if (alo > 0.0) {
                theta(alo, ahi, h, &tl, &th);
                product_hull(alo, ahi, l, l, &pl, &pu);
                t = dn(fl[i] - pu);
                bl[i] = dn(l + py_min(dn(tl * t), dn(th * t)));
                product_hull(alo, ahi, u, u, &pl, &pu);
                t = up(fu[i] - pl);
                bu[i] = up(u + py_max(up(tl * t), up(th * t)));
            }
            product_hull(-ahi, -alo, T[i], T[NX + i], &pl, &pu);
            fl[i] = dn(fl[i] + pl);
            fu[i] = up(fu[i] + pu);
            if (alo <= 0.0) {
                bl[i] = dn(l + dn(h * fl[i]));
                bu[i] = up(u + up(h * fu[i]));
            }
        } else {
            bl[i] = dn(l + dn(h * fl[i]));
            bu[i] = up(u + up(h * fu[i]));
        }
        if (bl[i] < T[i]) bl[i] = T[i];
        if (bu[i] > T[NX + i]) bu[i] = T[NX + i];
    }
}

/* ------------------------------------------------------------------ eq. (23) over a step (step 2) */
/* midpoint oc and radius orad of omega = (vx - vx_j) A1 x + the stiffness part over the box
 * [lo, hi] (midpoint c, radius r), plus, with_input, the input part (vx - vx_j) B1 delta (exact)
 * and the disturbance bound (the runtime's ``_omega``; eq. 25 via Lemma 3); the radius rigorous */
static void omega(int mode, double vx, double d, const double *lo, const double *hi, const double c[NX],
                  const double r[NX], int with_input, double oc[NX], double orad[NX])
{
    double dv = vx - IV_MODE_VX[mode], adv = dv >= 0.0 ? dv : -dv, dvd = dv * d, vd = vx * d, ac[NX];
    double sl[NX] = {0.0}, su[NX] = {0.0};
    for (int j = 0; j < NX; j++) ac[j] = fabs(c[j]);
    stiffness(lo, hi, with_input, vd, sl, su);
    for (int i = 0; i < NX; i++) {
        double mid = 0.0, rad = 0.0, sh = 0.0;
        if (row_nonzero(IV_A1[i])) {
            mid += dv * acc(0.0, IV_A1[i], c, NX);
            rad += adv * acc_abs(0.0, IV_A1[i], r, NX);
            sh += adv * acc_abs(0.0, IV_A1[i], ac, NX);
        }
        if (with_input && IV_B1[i] != 0.0) {
            mid += dvd * IV_B1[i];
            sh += fabs(dvd * IV_B1[i]);
        }
        if (with_input && IV_W[i] != 0.0) rad += IV_W[i];
        if (i == ROW_AY || i == ROW_YAW_ACC) {
            double ms = (sl[i] + su[i]) * 0.5;
            mid += ms;
            rad += up(py_max(su[i] - ms, ms - sl[i]));
            sh += fabs(ms);
        }
        oc[i] = mid;
        orad[i] = radius(rad, sh, 0.0, 12);
    }
}

/* [a, b] := [a, b] intersected with the hull of P x over the box of midpoint c, radius r (eq. 20,
 * rounded outward); the hull alone where they do not meet ([-inf, inf]: no xi) */
static void rebase(const double P[NX][NX], const double c[NX], const double r[NX], double xi[NB])
{
    double ac[NX];
    for (int j = 0; j < NX; j++) ac[j] = fabs(c[j]);
    for (int i = 0; i < NX; i++) {
        double p = acc(0.0, P[i], c, NX), q = acc_abs(0.0, P[i], r, NX);
        double R = radius(q, acc_abs(0.0, P[i], ac, NX), 0.0, 4), pl = dn(p - R), pu = up(p + R);
        if (pl > xi[i]) xi[i] = pl;
        if (pu < xi[NX + i]) xi[NX + i] = pu;
        if (xi[i] > xi[NX + i]) {
            xi[i] = pl;
            xi[NX + i] = pu;
        }
    }
}

/* sum |mid| + sum rad (the runtime's ``S`` in ``_correct``) */
static double size_mr(const double *mid, const double *rad, int n)
{
    double s = sum_abs(mid, n), t = 0.0;
    for (int j = 0; j < n; j++) t += rad[j];
    return s + t;
}

/* The correction of the pending step [t - h', t] once y(t) is known (the runtime's ``_correct``): xi(t) =
 * Phi xi + int_0^h' exp(N (h' - s)) (J y(s) + H delta + P omega(s)) ds, bounded term by term with
 * nonnegative kernels (order preserving); y(s) the interpolation of its samples (weights W0, W1)
 * plus a remainder (W2 with [y''] on the smooth rows, W3 otherwise); omega over the box at the
 * start (Gam) and its growth over Fbar (Gam1); Omega by eq. (24). Then the box at t, x = xi + E y,
 * intersected with the current box B and, on the measured rows, with [ylo, yhi]. Rounded rigorously
 * (the coefficients' error k->err, the design residuals IV_RESIDUAL, the sums'). out = [box; xi]. */
static void correct(const Core *k, const Pending *p, const double ylo[NY], const double yhi[NY],
                    const double B[NB], double out[2 * NB])
{
    const int mode = p->mode;
    const double *l = p->X, vx = p->vx, d = p->d, h = p->h;
    double xi[NB], c[NX], r[NX], xc[NX], xr[NX], fc[NX], fr[NX], afc[NX], Y[2 * NY], yc[NY], yr[NY];
    double c0[NY], r0[NY], dc[NY] = {0.0}, dr[NY] = {0.0}, frm[NY], oc0[NX], or0[NX], oc1[NX], or1[NX];
    double ax[NX], a0[NY], ay[NY], adc[NY], ao0[NX], ao1[NX], avx = fabs(vx), ad = fabs(d);
    mid_rad(l, c, r);
    memcpy(xi, p->xi, sizeof xi);
    rebase(IV_P[mode], c, r, xi);
    mid_rad(xi, xc, xr);
    mid_rad(p->Fb, fc, fr);
    for (int q = 0; q < NY; q++) {
        Y[q] = ylo[q];
        Y[NY + q] = yhi[q];
    }
    mid_rad_n(Y, NY, yc, yr);
    for (int j = 0; j < NX; j++) afc[j] = fabs(fc[j]);
    for (int q = 0; q < NY; q++) {
        int j = MEAS[q];
        c0[q] = c[j];
        r0[q] = r[j];
        frm[q] = fr[j];
        if (!IV_SMOOTH[j]) continue;
        /* [y''] of a smooth row: its linear form (A0 + vx A1)[j, :] over Fbar */
        double sh;
        dc[q] = acc(0.0, IV_A0[j], fc, NX);
        sh = acc_abs(0.0, IV_A0[j], afc, NX);
        if (row_nonzero(IV_A1[j])) {
            dc[q] += vx * acc(0.0, IV_A1[j], fc, NX);
            sh += avx * acc_abs(0.0, IV_A1[j], afc, NX);
        }
        for (int i = 0; i < NX; i++)
            if (IV_A1[j][i] == 0.0 && IV_A0[j][i] != 0.0) dr[q] += fabs(IV_A0[j][i]) * fr[i];
        for (int i = 0; i < NX; i++)
            if (IV_A1[j][i] != 0.0) {
                dr[q] += fabs(IV_A0[j][i] + vx * IV_A1[j][i]) * fr[i];
                sh += (fabs(IV_A0[j][i]) + avx * fabs(IV_A1[j][i])) * fr[i];
            }
        dr[q] = radius(dr[q], sh, 0.0, 16);
    }
    omega(mode, vx, d, l, l + NX, c, r, 1, oc0, or0);
    omega(mode, vx, d, p->Fb, p->Fb + NX, fc, fr, 0, oc1, or1);
    /* the coefficients' errors and the design residuals' (|x| <= xmax over the step) */
    double sfrm = 0.0;
    for (int q = 0; q < NY; q++) sfrm += frm[q];
    double e = k->err_phi * size_mr(xc, xr, NX) + k->err_w0j * size_mr(c0, r0, NY) + k->err_w1j * size_mr(yc, yr, NY)
               + k->err_w2j * size_mr(dc, dr, NY) + k->err_w3j * sfrm + k->err_gp * size_mr(oc0, or0, NX)
               + k->err_gp * size_mr(oc1, or1, NX) + k->err_gh * ad;
    double xmax = 0.0;
    for (int j = 0; j < NX; j++) {
        double t = fabs(c[j]) + r[j] + h * py_max(fabs(p->Fb[j]), fabs(p->Fb[NX + j]));
        xmax = j == 0 ? t : py_max(xmax, t);
    }
    xmax *= 1.0 + 8.0 * U_RND;
    double rho1 = IV_RESIDUAL[mode][0], rho2 = IV_RESIDUAL[mode][1], rho3 = IV_RESIDUAL[mode][2];
    double eres = rho1 * xmax + rho2 * ad;
    for (int j = 0; j < NX; j++) {
        ax[j] = fabs(xc[j]);
        ao0[j] = fabs(oc0[j]);
        ao1[j] = fabs(oc1[j]);
    }
    for (int q = 0; q < NY; q++) {
        a0[q] = fabs(c0[q]);
        ay[q] = fabs(yc[q]);
        adc[q] = fabs(dc[q]);
    }
    for (int i = 0; i < NX; i++) {
        double nc = acc(0.0, k->phi[i], xc, NX), nr = acc(0.0, k->phi[i], xr, NX), na;
        nc = acc(nc, k->w0j[i], c0, NY);
        nc = acc(nc, k->w1j[i], yc, NY);
        nc = acc(nc, k->w2j_neg[i], dc, NY);
        nc = acc(nc, k->gp[i], oc0, NX);
        nc = acc(nc, k->g1p[i], oc1, NX);
        if (k->gh[i] != 0.0) nc += k->gh[i] * d;
        nr = acc(nr, k->aw0j[i], r0, NY);
        nr = acc(nr, k->aw1j[i], yr, NY);
        nr = acc(nr, k->w2aj[i], dr, NY);
        nr = acc(nr, k->w3aj2[i], frm, NY);
        nr = acc(nr, k->gap[i], or0, NX);
        nr = acc(nr, k->g1ap[i], or1, NX);
        na = acc(0.0, k->phi[i], ax, NX);        /* the shadow of nc */
        na = acc(na, k->aw0j[i], a0, NY);
        na = acc(na, k->aw1j[i], ay, NY);
        na = acc(na, k->w2aj[i], adc, NY);
        na = acc(na, k->gap[i], ao0, NX);
        na = acc(na, k->g1ap[i], ao1, NX);
        na += fabs(k->gh[i] * d);
        double ei = e + k->gsum[i] * eres, R = radius(nr, na, ei, 24);
        /* the box at t: x = xi + E y(t), intersected with B */
        double bc = acc(nc, IV_E[mode][i], yc, NY), br = acc_abs(nr, IV_E[mode][i], yr, NY);
        double Rb = radius(br, acc_abs(na, IV_E[mode][i], ay, NY), ei + rho3 * xmax, 26);
        double xl = dn(bc - Rb), xu = up(bc + Rb);
        if (xl < B[i]) xl = B[i];
        if (xu > B[NX + i]) xu = B[NX + i];
        if (xl > xu) xl = B[i], xu = B[NX + i];
        out[i] = xl;
        out[NX + i] = xu;
        out[NB + i] = dn(nc - R);
        out[NB + NX + i] = up(nc + R);
    }
    for (int q = 0; q < NY; q++) {       /* the measured states: with their measurement */
        int j = MEAS[q];
        if (out[j] < ylo[q]) out[j] = ylo[q];
        if (out[NX + j] > yhi[q]) out[NX + j] = yhi[q];
        if (out[j] > out[NX + j]) out[j] = ylo[q], out[NX + j] = yhi[q];
    }
}

/* ------------------------------------------------------------------ modes, restarts, outputs */
/* Eq. (44): mode i on [edges[i], edges[i + 1]); outside the grid the nearest mode (one warning
 * per excursion) */
static int band(State *s, double vx, const Log *log)
{
    if (IV_EDGES[0] <= vx && vx <= IV_EDGES[N_MODES]) {
        s->outside = 0;
    } else {
        if (!s->outside)
            log_event(log, LOG_WARNING, "vx = %.4g m/s outside the design grid [%.4g, %.4g] m/s: the nearest mode "
                      "is used (the speed mismatch is bounded exactly, the bounds widen)",
                      vx, IV_EDGES[0], IV_EDGES[N_MODES]);
        s->outside = 1;
    }
    int i = -1;                                /* bisect_right(edges, vx) - 1 */
    while (i < N_MODES && IV_EDGES[i + 1] <= vx) i++;
    return i < 0 ? 0 : (i < N_MODES - 1 ? i : N_MODES - 1);
}

/* The runtime's ``_measured_box``: [y - nu, y + nu], each end one ulp outward when nu > 0. */
static void measured_box(double y, double nu, double *lo, double *hi)
{
    if (nu == 0.0) {
        *lo = *hi = y;
        return;
    }
    *lo = nextafter(y - nu, -INFINITY);
    *hi = nextafter(y + nu, INFINITY);
}

/* ------------------------------------------------------------------ the measurement of ay */
/* The runtime's ``_one_minus_cos``: k >= 1 - cos(d) rounded up: d^2/2 (1 - cos d <= d^2/2 for every
 * real d; no cancellation, no libm), at most 1 (cos d >= 0 on the input's declared range |d| <= pi/2;
 * the FMI layers refuse steering beyond it); 0 for d = 0. */
static double one_minus_cos(double d)
{
    if (d == 0.0) return 0.0;
    double k = up(up(d * d) * 0.5);
    return k <= 1.0 ? k : 1.0;      /* (a NaN steering: 1) */
}

/* The runtime's ``_outward_sum``: t1 + t2 rounded outward by 8 u (|t1| + |t2|) + 4 2^-1074 and one ulp. */
static double outward_sum(double t1, double t2, int side)
{
    double err = 8.0 * 0x1p-53 * (fabs(t1) + fabs(t2)) + 4.0 * 0x1p-1074;
    return nextafter(t1 + t2 + side * err, side * INFINITY);
}

/* The runtime's ``_fyf``: the bounds of Fyf = a x3 + b x4 over the box X (eq. 8 inverted), rounded outward */
static void fyf_bounds(const double X[NB], double *lo, double *hi)
{
    double L = IV_LF + IV_LR, a = IV_M * IV_LR / L, b = IV_IZ / L;
    *lo = outward_sum(a * X[2], b * X[3], -1);
    *hi = outward_sum(a * X[NX + 2], b * X[NX + 3], 1);
}

/* The runtime's ``_ay_nu``: the nu of the ay row, ay_error_bound + k |Fyf| / m for Fyf in [fl, fu],
 * k >= 1 - cos(delta), rounded up (ay_error_bound itself when k = 0).
 * DEPARTURE from paper 001's measurement equation (y = C x, eq. 9 and 11: ay = x3 = (Fyf + Fyr)/m;
 * eq. 46): a car steered by delta measures ay = (Fyf cos(delta) + Fyr)/m (CarPlant's), so ay - x3 =
 * -Fyf (1 - cos delta)/m, which the small-angle model leaves out and which jumps with the held steering
 * at every communication point (issue 47: a 1 us step exposed it as an inconsistency); bounded here. */
static double ay_nu(const State *s, double k, double fl, double fu)
{
    double nu = s->nu[1], F, e;
    if (k == 0.0) return nu;
    F = fu > -fl ? fu : -fl;                 /* max |Fyf| (fl <= fu) */
    e = up(up(k * F) / IV_M);
    if (!(e >= 0.0)) e = INFINITY;           /* (NaN bounds: no bound) */
    return up(nu + e);
}

/* The runtime's ``_ay_nu_apriori`` (a restart: no box of x3): |Fyf| <= (a (|ay| + nu) + b max|x4|) /
 * (1 - k lr/L), x4 in [x4l, x4u], rounded up (lr/L: two roundings, the factor 1 + 4u). */
static double ay_nu_apriori(const State *s, double ay, double k, double x4l, double x4u)
{
    if (k == 0.0) return s->nu[1];
    double h = up(fabs(ay) + s->nu[1]), L = IV_LF + IV_LR, fl, fu, F, den;
    const double X[NB] = {0.0, 0.0, -h, x4l, 0.0, 0.0, h, x4u};
    fyf_bounds(X, &fl, &fu);
    F = fu > -fl ? fu : -fl;
    den = dn(1.0 - up(up(k * (IV_LR / L)) * (1.0 + 4.0 * U_RND)));
    F = den > 0.0 ? up(F / den) : INFINITY;
    return ay_nu(s, k, -F, F);
}

/* The initial box: the unmeasured states +-x0_halfwidth (hull with the current bounds if keep), the
 * measured ones y +- nu, ay's nu by ``ay_nu_apriori`` (k >= 1 - cos delta); no xi, no pending
 * correction (the runtime's ``_restart``) */
static void restart(State *s, const double y[NY], int keep, double k)
{
    for (int q = 0; q < NY; q++) {
        int j = UNMEAS[q];
        double lo = -IV_X0_HALFWIDTH[j], hi = IV_X0_HALFWIDTH[j];
        if (keep) {
            lo = py_min(lo, s->box[j]);
            hi = py_max(hi, s->box[NX + j]);
        }
        s->box[j] = lo;
        s->box[NX + j] = hi;
    }
    const double nus[NY] = {s->nu[0], ay_nu_apriori(s, y[1], k, s->box[3], s->box[NX + 3])};
    for (int q = 0; q < NY; q++) measured_box(y[q], nus[q], &s->box[MEAS[q]], &s->box[NX + MEAS[q]]);
    s->xi_mode = -1;
    s->has_pending = 0;
}

/* me_xi := the hull of P x over the box X (eq. 20), P of the active mode (model exchange) */
static void me_rebase(State *s, const double X[NB])
{
    double c[NX], r[NX];
    mid_rad(X, c, r);
    for (int i = 0; i < NX; i++) {
        s->me_xi[i] = -INFINITY;
        s->me_xi[NX + i] = INFINITY;
    }
    rebase(IV_P[s->mode], c, r, s->me_xi);
}

/* |vx| < vx_hold (or vx = 0): the observer is frozen */
static int frozen(double vx, double hold)
{
    return (-hold < vx && vx < hold) || vx == 0.0;
}

/* the runtime's ``initialize``: the initial box; the mode of the initial speed unless frozen */
static void start(Model *m, const double *u, const Log *log)
{
    State *s = &m->s;
    double y[NY], vx = u[IN_vx];
    measurements(u, y);
    s->d_last = u[IN_delta];
    restart(s, y, 0, one_minus_cos(u[IN_delta]));
    if (fabs(vx) >= m->vx_hold && fabs(vx) > 0.0) {
        s->mode = band(s, vx, log);
        s->vx_pub = vx;
    }
    s->started = 1;
    s->consistent = 1;
    me_rebase(s, s->box);
}

/* The runtime's ``_outward_atan``: atan(q) rounded outward by 3 ulps (side -1: below, +1: above). */
static double outward_atan(double q, int side)
{
    double t = atan(q);
    int k;
    for (k = 0; k < 3; k++) t = nextafter(t, side * INFINITY);
    return t;
}

/* The runtime's ``_publish``: vy; beta = atan(vy / vx) (monotone in vy, decreasing when reversing);
 * r; the axle forces Fyf = (m lr x3 + Iz x4)/L, Fyr = (m lf x3 - Iz x4)/L (eq. 8 inverted, eq. 45)
 * by interval arithmetic: the lower bound of Fyr takes the UPPER bound of x4 (eq. 45's misprint).
 * beta and the forces rounded outward by a bound of their evaluation's error (DEPARTURE, as there). */
static void outputs_of(const double X[NB], double vx, int mode, int consistent, double *y, int *yi)
{
    const double *l = X, *u = X + NX;
    double L = IV_LF + IV_LR, b = IV_IZ / L, c = IV_M * IV_LF / L;
    y[OUT_vy_lower] = l[0];
    y[OUT_vy_upper] = u[0];
    y[OUT_beta_lower] = vx > 0.0 ? outward_atan(l[0] / vx, -1) : outward_atan(u[0] / vx, -1);
    y[OUT_beta_upper] = vx > 0.0 ? outward_atan(u[0] / vx, 1) : outward_atan(l[0] / vx, 1);
    y[OUT_yaw_rate_lower] = l[1];
    y[OUT_yaw_rate_upper] = u[1];
    fyf_bounds(X, &y[OUT_Fyf_lower], &y[OUT_Fyf_upper]);
    y[OUT_Fyr_lower] = outward_sum(c * l[2], -b * u[3], -1);
    y[OUT_Fyr_upper] = outward_sum(c * u[2], -b * l[3], 1);
    yi[INT_mode] = mode + 1;
    yi[INT_consistent] = consistent;
}

/* ------------------------------------------------------------------ co-simulation step */
/* Step 1: the published box of the measured states intersected with [y - nu, y + nu] (DEPARTURE:
 * a tightening; both sets contain x), ay's nu by ``ay_nu`` over this box (k >= 1 - cos delta). 0 if
 * it is empty beyond IV_CONSISTENCY_TOL (1 + |y|). */
static int intersect_measurement(State *s, const double y[NY], double k)
{
    int consistent = 1;
    double fl, fu;
    fyf_bounds(s->box, &fl, &fu);
    const double nus[NY] = {s->nu[0], ay_nu(s, k, fl, fu)};
    for (int q = 0; q < NY; q++) {
        int j = MEAS[q];
        double lo = s->box[j], hi = s->box[NX + j], ml, mu;
        measured_box(y[q], nus[q], &ml, &mu);
        if (ml > lo) lo = ml;
        if (mu < hi) hi = mu;
        if (lo > hi) {
            if (lo - hi <= IV_CONSISTENCY_TOL * (1.0 + fabs(y[q]))) {   /* rounding: the gap itself */
                double t = lo;
                lo = hi;
                hi = t;
            } else {
                consistent = 0;
            }
        }
        s->box[j] = lo;
        s->box[NX + j] = hi;
    }
    return consistent;
}

static const char NON_FINITE[] = "bounds became non-finite: restarted from the measurement and x0_halfwidth";

/* Step 2: the correction of the pending step now that y(t) is known (in the measured rows of the box).
 * 0, or -1 (no step map). */
static int correct_pending(Model *m, const Log *log)
{
    State *s = &m->s;
    const Core *k = core_for(m, s->p.mode, s->p.h, log);
    double ylo[NY], yhi[NY], out[2 * NB], sb[NB];
    if (k == NULL) return -1;
    for (int q = 0; q < NY; q++) {
        ylo[q] = s->box[MEAS[q]];
        yhi[q] = s->box[NX + MEAS[q]];
    }
    correct(k, &s->p, ylo, yhi, s->box, out);
    if (s->p.has_sm && sampled_correct(m, &s->p, ylo, yhi, sb) == 0) intersect_box(out, sb);
    if (all_finite(out, 2 * NB)) {
        memcpy(s->box, out, sizeof s->box);
        memcpy(s->xi, out + NB, sizeof s->xi);
        s->xi_mode = s->p.mode;
    } else {
        /* DEPARTURE (floating point), as the runtime: a correction without finite bounds (a step so
         * short that its coefficients' error bounds, ~u/h, overflow) is skipped; the box, the pending
         * step's prediction intersected with y(t), is a guaranteed enclosure; xi dropped */
        s->xi_mode = -1;
    }
    return 0;
}

/* the a priori enclosure T over a (sub)step hs, by the comparison bound if ``enclose`` fails
 * (*fallback = 1). 0, or -1 (no finite comparison bound). */
static int enclosure(double hs, double vx, double d, const double X[NB], double T[NB], int *fallback,
                     const Log *log)
{
    if (enclose(hs, vx, d, X, T) == 0) return 0;
    *fallback = 1;
    if (comparison_enclosure(hs, vx, d, X, T) == 0) return 0;
    log_event(log, LOG_ERROR, "step refused: no finite a priori enclosure (hs = %g s, vx = %g m/s)", hs, vx);
    return -1;
}

/* Steps 4 and 5: the enclosure T over [t, t + h] (from k->nsub substeps for long steps), out =
 * [Fbar; predicted box] of ``predict``, and the box B at t + h. 0, or -1. */
static int prediction(const Core *k, double h, double vx, double d, const double X[NB], double T[NB],
                      double out[2 * NB], double B[NB], int *fallback, const Log *log)
{
    if (k->nsub == 1) {
        if (enclosure(h, vx, d, X, T, fallback, log) != 0) return -1;
        predict(h, vx, d, X, T, out);
        memcpy(B, out + NB, NB * sizeof *B);
        return 0;
    }
    double Xm[NB], Tm[NB], o[2 * NB];
    memcpy(Xm, X, sizeof Xm);
    for (int n = 0; n < k->nsub; n++) {
        if (enclosure(k->hs, vx, d, Xm, Tm, fallback, log) != 0) return -1;
        predict(k->hs, vx, d, Xm, Tm, o);
        memcpy(Xm, o + NB, sizeof Xm);
        for (int i = 0; i < NX; i++) {
            T[i] = n == 0 ? Tm[i] : py_min(T[i], Tm[i]);
            T[NX + i] = n == 0 ? Tm[NX + i] : py_max(T[NX + i], Tm[NX + i]);
        }
    }
    predict(h, vx, d, X, T, out);
    for (int i = 0; i < NX; i++) {
        B[i] = py_max(out[NB + i], Xm[i]);
        B[NX + i] = py_min(out[NB + NX + i], Xm[NX + i]);
    }
    return 0;
}

/* the runtime's ``step`` (see the top of this file); -1 refused (the caller restores the state) */
static int step(Model *m, double h, const double *u, const Log *log)
{
    State *s = &m->s;
    double vx = u[IN_vx], d = u[IN_delta], hold = m->vx_hold, y[NY];
    if (!(h <= IV_MAX_COMM_STEP)) {     /* ``max_communication_step``: the bounds would not contract */
        log_event(log, LOG_ERROR, "communication step %g s refused: longer than %g s, the longest step at which "
                  "this design's bounds contract (the measurements arrive only at the communication points: over a "
                  "longer step the bounds of the trajectory grow faster than one sample narrows them); use a step "
                  "<= %g s", h, IV_MAX_COMM_STEP, IV_MAX_COMM_STEP);
        return -1;
    }
    if (!s->started) start(m, u, log);
    measurements(u, y);
    /* 1 - cos of the steering before and after t (``ay_nu``): y(t) may follow either */
    double kc = one_minus_cos(d), kl = one_minus_cos(s->d_last);
    if (kl > kc) kc = kl;
    s->d_last = d;
    if (frozen(vx, hold)) {
        if (!s->holding)
            log_event(log, LOG_WARNING, "|vx| = %.3g m/s < vx_hold = %g m/s: interval observer frozen, bounds held",
                      fabs(vx), hold);
        s->holding = 1;
        s->has_pending = 0;
        return 0;
    }
    if (s->holding) {
        log_event(log, LOG_WARNING, "vx = %.3g m/s: interval observer resumes; the bounds restart from the "
                  "measurement and x0_halfwidth", vx);
        s->holding = 0;
        restart(s, y, 0, kc);
    }
    /* 1. measurement intersection */
    s->consistent = intersect_measurement(s, y, kc);
    if (!s->consistent) {
        if (!s->inconsistent)
            log_event(log, LOG_WARNING, "measurement (yaw_rate = %.4g rad/s, ay = %.4g m/s2) outside the bounds: "
                      "the model does not hold (stiffness outside the box, saturated tires?); bounds restarted "
                      "from the measurement and x0_halfwidth, consistent = 0", y[0], y[1]);
        s->inconsistent = 1;
        restart(s, y, 1, kc);
    } else {
        s->inconsistent = 0;
    }
    /* 2. the correction of the previous step */
    if (s->has_pending && correct_pending(m, log) != 0) return -1;
    /* 3. the mode of this step */
    int mode = s->mode = band(s, vx, log);
    const Core *k = core_for(m, mode, h, log);
    if (k == NULL) return -1;
    /* 4.-5. the enclosure over [t, t + h] and the prediction at t + h */
    double X[NB], T[NB], out[2 * NB], B[NB];
    int fallback = 0;
    memcpy(X, s->box, sizeof X);
    if (prediction(k, h, vx, d, X, T, out, B, &fallback, log) != 0) return -1;
    if (fallback && !s->fallback_episode)
        log_event(log, LOG_WARNING, "a priori enclosure not found in %d tries (h = %g s, vx = %.4g m/s): "
                  "comparison bound used, wider", IV_ENCLOSURE_TRIES, h, vx);
    s->fallback_episode = fallback;
    if (!all_finite(out, 2 * NB)) {
        log_event(log, LOG_WARNING, NON_FINITE);
        restart(s, y, 0, kc);
    } else {
        Pending *p = &s->p;
        p->mode = mode;
        p->h = h;
        p->vx = vx;
        p->d = d;
        memcpy(p->X, X, sizeof X);
        memcpy(p->Fb, out, sizeof p->Fb);
        for (int i = 0; i < NX; i++) {
            p->xi[i] = s->xi_mode == mode ? s->xi[i] : -INFINITY;
            p->xi[NX + i] = s->xi_mode == mode ? s->xi[NX + i] : INFINITY;
        }
        p->has_sm = 0;
        if (IV_SAMPLED && h >= IV_SAMPLED_MIN_STEP) {      /* the box by the model alone, intersected */
            double Bs[NB];
            p->has_sm = sampled_predict(m, h, vx, d, X, Bs, p) == 0;
            if (p->has_sm) intersect_box(B, Bs);
        }
        s->has_pending = 1;
        memcpy(s->box, B, sizeof B);
    }
    s->vx_pub = vx;
    return 0;
}

/* ------------------------------------------------------------------ model.h */
int model_setup(Model *m, const double *p, const Log *log)
{
    double hold = p[PAR_vx_hold];
    if (!(isfinite(hold) && hold >= 0.0)) {
        log_event(log, LOG_ERROR, "parameter vx_hold must be finite and >= 0 m/s, got %g", hold);
        return -1;
    }
    const double nu[NY] = {p[PAR_yaw_rate_error_bound], p[PAR_ay_error_bound]};
    static const char *const NU_NAMES[NY] = {"yaw_rate_error_bound (rad/s)", "ay_error_bound (m/s2)"};
    for (int q = 0; q < NY; q++)
        if (!(isfinite(nu[q]) && nu[q] >= 0.0)) {
            log_event(log, LOG_ERROR, "parameter %s must be finite and >= 0, got %g", NU_NAMES[q], nu[q]);
            return -1;
        }
    memset(m, 0, sizeof *m);
    m->vx_hold = hold;
    memcpy(m->s.nu, nu, sizeof nu);
    m->s.xi_mode = -1;
    m->s.consistent = 1;
    m->s.vx_pub = py_max(hold, 1e-3);
    return 0;
}

void model_initialize(Model *m, const double *u, const Log *log)
{
    start(m, u, log);
}

int model_do_step(Model *m, double h, const double *u, const Log *log)
{
    State saved = m->s;
    if (step(m, h, u, log) == 0) return 0;
    m->s = saved;
    return -1;
}

void model_outputs(const Model *m, double *y, int *yi)
{
    outputs_of(m->s.box, m->s.vx_pub, m->s.mode, m->s.consistent, y, yi);
}

/* ------------------------------------------------------------------ model exchange: eq. (23) */
#if N_STATES > 0
#if N_STATES != NB || N_EVENT_INDICATORS != 5
#error "lateral_interval_observer.c: the states are [xi_lo; xi_up], five event indicators"
#endif

void model_me_get_states(const Model *m, double *x)
{
    memcpy(x, m->s.me_xi, sizeof m->s.me_xi);
}

void model_me_set_states(Model *m, const double *x)
{
    memcpy(m->s.me_xi, x, sizeof m->s.me_xi);
}

void model_me_nominals(const Model *m, double *nominal)
{
    (void)m;
    for (int i = 0; i < NB; i++) nominal[i] = 1.0;
}

/* the box of x = xi + E y: [xi_lo + E y - |E| nu, xi_up + E y + |E| nu] */
static void me_box(const State *s, const double y[NY], double X[NB])
{
    for (int i = 0; i < NX; i++) {
        double ey = acc(0.0, IV_E[s->mode][i], y, NY), en = acc_abs(0.0, IV_E[s->mode][i], s->nu, NY);
        X[i] = s->me_xi[i] + ey - en;
        X[NX + i] = s->me_xi[NX + i] + ey + en;
    }
}

/* eq. (23): xi_up' = N xi_up + J y + H delta + Omega_up (lower alike; N Metzler keeps them ordered,
 * Lemma 2), Omega by eq. (24) = P oc +- |P| orad from the omega bounds over the box (eq. 25), J y
 * +- |J| nu; 0 while frozen */
void model_me_derivatives(const Model *m, const double *u, double *dx)
{
    const State *s = &m->s;
    const int mode = s->mode;
    double y[NY], X[NB], c[NX], r[NX], oc[NX], orad[NX], d = u[IN_delta];
    if (!s->started || s->holding) {
        memset(dx, 0, NB * sizeof *dx);
        return;
    }
    measurements(u, y);
    me_box(s, y, X);
    mid_rad(X, c, r);
    omega(mode, u[IN_vx], d, X, X + NX, c, r, 1, oc, orad);
    for (int i = 0; i < NX; i++) {
        double base = acc(0.0, IV_J[mode][i], y, NY) + IV_H[mode][i] * d + acc(0.0, IV_P[mode][i], oc, NX);
        double rad = acc_abs(0.0, IV_J[mode][i], s->nu, NY) + acc_abs(0.0, IV_P[mode][i], orad, NX);
        dx[i] = acc(0.0, IV_N[mode][i], s->me_xi, NX) + base - rad;
        dx[NX + i] = acc(0.0, IV_N[mode][i], s->me_xi + NX, NX) + base + rad;
    }
}

/* The indicators of the current discrete state (a zero crossing of one = "switch now"; it is the
 * signed distance of vx to a threshold, positive on the current side; the state switches when it
 * is <= 0, so that an event located exactly on a threshold switches too). Where the co-simulation's
 * rule includes the threshold in the set being left (a band's lower edge, the grid's ends, the
 * running state at |vx| = vx_hold), the threshold is moved ME_HYST beyond it. */
void model_me_event_indicators(const Model *m, const double *u, double *z)
{
    const State *s = &m->s;
    double vx = u[IN_vx], hold = m->vx_hold;
    int j = s->mode;
    z[0] = j > 0 ? vx - (IV_EDGES[j] - ME_HYST) : 1.0;                  /* leave band j downward */
    z[1] = j < N_MODES - 1 ? IV_EDGES[j + 1] - vx : 1.0;                /* leave band j upward */
    z[2] = s->holding ? hold - fabs(vx) : fabs(vx) - (hold - ME_HYST);   /* resume / freeze */
    z[3] = vx - (IV_EDGES[0] - ME_HYST);                                /* leave the design grid */
    z[4] = IV_EDGES[N_MODES] + ME_HYST - vx;
}

/* The discrete state at an event (model_me_event_indicators): start; freeze (the bounds of x held,
 * beta at the freeze speed +-vx_hold); resume (a restart like at initialisation); mode switch (eq.
 * 44, the half-open bands; xi re-based on the new P, eq. 20); the out-of-grid warning. */
int model_me_event_update(Model *m, double t, const double *u, const Log *log)
{
    State *s = &m->s;
    double vx = u[IN_vx], hold = m->vx_hold, y[NY], X[NB];
    int changed = 0;
    (void)t;
    measurements(u, y);
    if (!s->started) {
        start(m, u, log);
        changed = 1;
    }
    if (!s->holding && fabs(vx) <= hold - ME_HYST) {
        log_event(log, LOG_WARNING, "|vx| = %.3g m/s < vx_hold = %g m/s: interval observer frozen, bounds held",
                  fabs(vx), hold);
        me_box(s, y, s->box);
        s->vx_pub = copysign(hold, vx);
        s->holding = 1;
    }
    if (s->holding) {
        if (frozen(vx, hold)) return changed;
        log_event(log, LOG_WARNING, "vx = %.3g m/s: interval observer resumes; the bounds restart from the "
                  "measurement and x0_halfwidth", vx);
        s->holding = 0;
        restart(s, y, 0, one_minus_cos(u[IN_delta]));
        s->mode = band(s, vx, log);
        me_rebase(s, s->box);
        return 1;
    }
    int j = s->mode, mode = band(s, vx, log);
    if (!((j > 0 && vx <= IV_EDGES[j] - ME_HYST) || (j < N_MODES - 1 && vx >= IV_EDGES[j + 1]))) return changed;
    me_box(s, y, X);
    s->mode = mode;
    me_rebase(s, X);
    return 1;
}

/* the outputs of the box xi + E y at the current inputs (the held box while frozen); no measurement
 * intersection in eq. (23), hence no consistency test: consistent = 1 */
void model_me_outputs(const Model *m, const double *u, double *y, int *yi)
{
    const State *s = &m->s;
    double ym[NY], X[NB];
    if (!s->started || s->holding) {
        outputs_of(s->box, s->vx_pub, s->mode, 1, y, yi);
        return;
    }
    measurements(u, ym);
    me_box(s, ym, X);
    outputs_of(X, u[IN_vx], s->mode, 1, y, yi);
}
#endif
