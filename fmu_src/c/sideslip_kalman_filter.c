/*
 * sideslip_kalman_filter.c - paper 002's baseline peer, the linear bicycle-model Kalman filter of the
 * MBDS dataset's authors (Leanza, Reina, Blanco-Claraco, Sensors 2021); the native twin of
 * fmu_src/sideslip_kalman_filter.py (same clamps, warnings, start and discretisation, the same
 * arithmetic in the same order, so that the outputs equal the Python FMU's bit for bit).
 * C99, libc and libm only.
 *
 * States x = [vy (m/s), r (rad/s)], covariance P; inputs delta (rad), vx (m/s), yaw_rate (rad/s),
 * ay (m/s^2). Model at the speed v (linear tires; model_data.h: KF_A, KF_B):
 *     x' = A(v) x + B delta,  A = [[a00/v, a01/v - v], [a10/v, a11/v]],  B = [b0, b1],
 *     y = [ay, r] = C(v) x + D delta,  C = [[a00/v, a01/v], [0, 1]],  D = [b0, 0]
 * (ay = vy' + v r: A's first row + [0, v]).
 *
 * One co-simulation step over h (inputs held, v = vx clamped to [KF_VX_MIN, KF_VX_MAX]):
 *   1. update with y = [ay, yaw_rate]: S = C P C' + R, K = P C' S^-1, x += K (y - C x - D delta),
 *      P = (I - K C) P, symmetrised;
 *   2. predict over h, delta held, exact zero-order hold (Van Loan; la_zoh_map, the runtime's
 *      3x3 expm by scaling and squaring with a Taylor series): [[Phi, Gam], [0, 1]] =
 *      expm(h [[A, B], [0, 0]]), x = Phi x + Gam delta, P = Phi P Phi' + Q h.
 * The model depends on the measured speed at every step, so the map is computed per step (no
 * table). Outputs: x_{k+1|k} and beta_hat = atan(vy_hat / v) with the step's v.
 *
 * Clamps and warnings (as the runtime):
 *   - the start (model_initialize, or else the first step): x = [0, yaw_rate], P = P0;
 *   - vx outside [vx_min, vx_max] (the model has 1/vx; reversing is not modelled): the model at
 *     the nearest bound, one warning per excursion;
 *   - a step whose discretised model or result is not finite (an absurd h): refused with a
 *     warning, the state held.
 * The layer refuses a non-finite input or h <= 0 before any call.
 *
 * Co-simulation only (N_STATES = 0, no ModelExchange): this is a DISCRETE-time filter. Every
 * step applies one measurement update with the covariance R of ONE sample, then predicts over
 * h with the process noise Q h. Its gain depends on h: as h -> 0 the updates per second grow
 * like 1/h with R fixed, i.e. the measurement noise density R h -> 0, and the estimate tends to
 * the measurements themselves, not to a continuous-time filter. A ModelExchange form (the
 * Kalman-Bucy filter with a measurement noise density R h_s for a chosen sample time h_s, and
 * its Riccati ODE) would be another estimator, equal to this one at no step size; the runtime
 * mirrored here is the sampled filter the design certifies (sideslip_kalman_filter.design).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model.h"
#include "model_data.h"
#include "model_util.h"
#include "linalg.h"

#if N_STATES != 0
#error "the Kalman filter is co-simulation only (the emitter gives no states)"
#endif

struct Model {
    double x[2];                   /* [vy (m/s), r (rad/s)]: the prediction x_{k+1|k} */
    double P[2][2];                /* its covariance (m^2/s^2, m rad/s^2, rad^2/s^2) */
    int started;                   /* model_initialize (or the first step) has set x, P */
    int outside;                   /* vx outside [vx_min, vx_max] (warned) */
    double y[N_OUTPUTS];           /* outputs */
};

/* the linear bicycle model at the speed v (m/s): A (1/s), B, C rows [ay, r], D */
typedef struct {
    double A[2][2], B[2], C[2][2], D[2];
} Bicycle;

size_t model_size(void)
{
    return sizeof(Model);
}

/* vx clamped to [vx_min, vx_max], one warning per excursion (the runtime's _speed) */
static double speed(Model *m, double vx, const Log *log)
{
    if (KF_VX_MIN <= vx && vx <= KF_VX_MAX) {
        m->outside = 0;
        return vx;
    }
    if (!m->outside)
        log_event(log, LOG_WARNING, "vx = %.4g m/s outside [%g, %g] m/s: the model is evaluated at the nearest bound",
                  vx, KF_VX_MIN, KF_VX_MAX);
    m->outside = 1;
    return vx < KF_VX_MIN ? KF_VX_MIN : KF_VX_MAX;
}

/* the runtime's model(v) */
static Bicycle bicycle_at(double v)
{
    const double a00 = KF_A[0], a01 = KF_A[1], a10 = KF_A[2], a11 = KF_A[3];
    Bicycle s = {{{a00 / v, a01 / v - v}, {a10 / v, a11 / v}}, {KF_B[0], KF_B[1]},
                 {{a00 / v, a01 / v}, {0.0, 1.0}}, {KF_B[0], 0.0}};
    return s;
}

/* the outputs: the prediction x_{k+1|k} and the filtered xf = x_{k|k} of the step's start (the
 * runtime's _publish; xf = x at the start), both at the speed v of the step's start */
static void publish(Model *m, double v, const double xf[2])
{
    m->y[OUT_beta_hat] = atan(m->x[0] / v);
    m->y[OUT_vy_hat] = m->x[0];
    m->y[OUT_yaw_rate_hat] = m->x[1];
    m->y[OUT_beta_filtered] = atan(xf[0] / v);
    m->y[OUT_vy_filtered] = xf[0];
    m->y[OUT_yaw_rate_filtered] = xf[1];
}

/* x = [0, yaw_rate], P = P0; the outputs at vx */
static void start(Model *m, const double *u, const Log *log)
{
    m->x[0] = 0.0;
    m->x[1] = u[IN_yaw_rate];
    memcpy(m->P, KF_P0, sizeof m->P);
    m->started = 1;
    publish(m, speed(m, u[IN_vx], log), m->x);
}

int model_setup(Model *m, const double *p, const Log *log)
{
    (void)p, (void)log;            /* no parameters: the covariances are the certified design */
    memset(m, 0, sizeof *m);
    return 0;
}

void model_initialize(Model *m, const double *u, const Log *log)
{
    start(m, u, log);
}

/* 1. measurement update of (x, P) with y = [ay, yaw_rate] (P symmetric: P C' = (C P)') */
static void update(const Bicycle *s, const double *u, double x[2], double P[2][2])
{
    const double y[2] = {u[IN_ay], u[IN_yaw_rate]}, delta = u[IN_delta];
    double CP[2][2], S[2][2], Si[2][2], K[2][2], e[2], N[2][2];
    for (int i = 0; i < 2; i++)
        for (int j = 0; j < 2; j++) CP[i][j] = s->C[i][0] * P[0][j] + s->C[i][1] * P[1][j];
    for (int i = 0; i < 2; i++)
        for (int j = 0; j < 2; j++) S[i][j] = CP[i][0] * s->C[j][0] + CP[i][1] * s->C[j][1] + KF_R[i][j];
    const double det = S[0][0] * S[1][1] - S[0][1] * S[1][0];
    Si[0][0] = S[1][1] / det, Si[0][1] = -S[0][1] / det, Si[1][0] = -S[1][0] / det, Si[1][1] = S[0][0] / det;
    for (int i = 0; i < 2; i++)                /* K = (C P)' S^-1 */
        for (int j = 0; j < 2; j++) K[i][j] = CP[0][i] * Si[0][j] + CP[1][i] * Si[1][j];
    for (int i = 0; i < 2; i++) e[i] = y[i] - (s->C[i][0] * x[0] + s->C[i][1] * x[1]) - s->D[i] * delta;
    for (int i = 0; i < 2; i++) x[i] += K[i][0] * e[0] + K[i][1] * e[1];
    for (int i = 0; i < 2; i++) {              /* N = (I - K C) P */
        double q[2];
        for (int j = 0; j < 2; j++) {
            double kc = K[i][0] * s->C[0][j] + K[i][1] * s->C[1][j];
            q[j] = i == j ? 1.0 - kc : -kc;
        }
        for (int j = 0; j < 2; j++) N[i][j] = q[0] * P[0][j] + q[1] * P[1][j];
    }
    P[0][0] = N[0][0], P[1][1] = N[1][1];
    P[0][1] = P[1][0] = 0.5 * (N[0][1] + N[1][0]);
}

/* 2. prediction over h with delta held: x = Phi x + Gam delta, P = Phi P Phi' + Q h.
 * 0, or -1 if the discretised model is not finite (x, P untouched). */
static int predict(const Bicycle *s, double h, double delta, double x[2], double P[2][2])
{
    double E[2 * 3], F[2][2], G[2], M[2][2], Pn[2][2];
    if (la_zoh_map(2, 1, &s->A[0][0], s->B, h, E) != 0) return -1;
    for (int i = 0; i < 2; i++) F[i][0] = E[3 * i], F[i][1] = E[3 * i + 1], G[i] = E[3 * i + 2];
    const double x0 = x[0], x1 = x[1];
    for (int i = 0; i < 2; i++) x[i] = F[i][0] * x0 + F[i][1] * x1 + G[i] * delta;
    for (int i = 0; i < 2; i++)
        for (int j = 0; j < 2; j++) M[i][j] = F[i][0] * P[0][j] + F[i][1] * P[1][j];
    for (int i = 0; i < 2; i++)
        for (int j = 0; j < 2; j++) Pn[i][j] = M[i][0] * F[j][0] + M[i][1] * F[j][1] + KF_Q[i][j] * h;
    P[0][0] = Pn[0][0], P[1][1] = Pn[1][1];
    P[0][1] = P[1][0] = 0.5 * (Pn[0][1] + Pn[1][0]);
    return 0;
}

int model_do_step(Model *m, double h, const double *u, const Log *log)
{
    double x[2], P[2][2], xf[2];
    if (!m->started) start(m, u, log);
    const double v = speed(m, u[IN_vx], log);
    const Bicycle s = bicycle_at(v);
    memcpy(x, m->x, sizeof x);
    memcpy(P, m->P, sizeof P);
    update(&s, u, x, P);
    memcpy(xf, x, sizeof xf);                  /* x_{k|k} */
    if (predict(&s, h, u[IN_delta], x, P) != 0) {
        char text[32];
        log_event(log, LOG_WARNING, "the model discretised over h = %s s is not finite: step refused, state held",
                  py_repr(h, text));
        return 0;
    }
    if (!(isfinite(x[0]) && isfinite(x[1]) && isfinite(P[0][0]) && isfinite(P[0][1]) && isfinite(P[1][1]))) {
        log_event(log, LOG_WARNING, "the filter's state became non-finite: step refused, state held");
        return 0;
    }
    memcpy(m->x, x, sizeof x);
    memcpy(m->P, P, sizeof P);
    publish(m, v, xf);
    return 0;
}

void model_outputs(const Model *m, double *y, int *yi)
{
    (void)yi;
    memcpy(y, m->y, sizeof m->y);
}
