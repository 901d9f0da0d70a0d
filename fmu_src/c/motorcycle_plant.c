/*
 * motorcycle_plant.c - the nonlinear motorcycle of paper 003: Sharp's (1971) lateral model with Magic
 * Formula tyres and relaxation; the native twin of fmu_src/motorcycle_plant.py (same equations,
 * integrator, substeps, clamps, warnings and outputs). C99, libc and libm only.
 *
 * Axes (SAE): x forward, y right, z down. States (SI): roll_angle phi, steer_angle delta, vy,
 * yaw_rate r, roll_rate, steer_rate, Ff, Fr. Inputs: rider_torque tau (N m), vx (m/s, prescribed).
 * (E1) M du/dt = -(C0 + vx C1) u - K_sin [sin phi, sin delta] + B_F [Ff, Fr] + B_tau tau,
 *      u = [vy, r, roll_rate, steer_rate]; phi' = roll_rate, delta' = steer_rate
 *      (paper 003's eqs. (1)-(2) with the derived coefficients);
 * (E2) alpha_f = -(slip_f . u)/vs + cos(eps) delta, alpha_r = -(slip_r . u)/vs, gamma = camber rows
 *      [phi, delta], vs = max(vx, V_SLIP_MIN) (eqs. (7)-(8));
 * (E3) Fs = D sin(C atan(B x - E (B x - atan(B x)))), x = alpha + (C2/C1) gamma, D = mu Fz,
 *      B = C1 / (C D); linear tyres: Fs = C1 x; Gamma = Fs - C1 x (eqs. (5)-(6));
 * (E4) dF/dt = (vr / sigma) (Fs - F), vr = max(vx, V_RELAX_MIN) (eqs. (3)-(4)); sigma = 0:
 *      algebraic tyres F = Fs, the force states then report Fs.
 *
 * Co-simulation: classical RK4, inputs held over the step, n equal substeps, n the least integer with
 * h/n <= H_MAX and lam_est h/n <= LAM_DT (lam_est bounds the spectral radius of the linearisation).
 * Clamps (one warning on entering each): |tau| <= TAU_MAX, 0 <= vx <= VX_MAX, a warning below V_WARN
 * (slip and relaxation use the 1 m/s floors), |phi| > ROLL_WARN: fallen over (the integration goes
 * on). A step whose state turns non-finite, or that would need more than MAX_SUBSTEPS substeps (a
 * step of hours: the Python runtime would loop as long), is refused with the state unchanged.
 *
 * ModelExchange: the 8 states and (E1)-(E4) at the current (continuous, clamped) inputs. With
 * sigma = 0 the force states are not dynamic (derivative 0, the value they had at initialisation)
 * and take no part in the dynamics: the outputs Ff, Fr are the algebraic forces Fs (the number of
 * states of an FMU is fixed at build time, sigma is a parameter). Event indicators (the warnings'
 * thresholds; z3 also marks the kink of the 1 m/s floors):
 *     z0 = TAU_MAX - |tau|, z1 = vx, z2 = VX_MAX - vx, z3 = vx - V_WARN, z4 = ROLL_WARN - |phi|;
 * the warnings are issued in model_me_event_update, a threshold reached counting as crossed (beyond).
 */
#include <math.h>
#include <string.h>

#include "model.h"
#include "model_data.h"

#define NQ 8                   /* states */
#define NU 4                   /* speeds u = [vy, r, roll_rate, steer_rate] */
#define MAX_SUBSTEPS 1e7       /* RK4 substeps of one step at most (1e4 s at H_MAX = 1 ms) */
#define STR(x) #x
#define XSTR(x) STR(x)

enum { X_PHI, X_DELTA, X_VY, X_R, X_P, X_D, X_FF, X_FR };      /* state indices */
enum { WARN_TAU = 1, WARN_VX_NEG = 2, WARN_VX_MAX = 4, WARN_VX_MIN = 8, WARN_FALLEN = 16 };

struct Model {
    double x[NQ];              /* the states (SI) */
    double sigma;              /* m; 0: algebraic tyres */
    int relax, linear;         /* sigma > 0; linear tyres */
    double mf_C, mf_E;         /* Magic Formula shape and curvature factors */
    double D[2], B[2], kg[2];  /* per tyre (front, rear): mu Fz (N), C1 / (C D) (1/rad), C2 / C1 */
    unsigned warned;           /* WARN_* flags: the warnings whose condition holds */
    double y[N_OUTPUTS];
};

/* the right-hand side (E1)-(E4) for held, clamped inputs (the runtime's _make_rhs) */
typedef struct {
    double R[NU][NQ];          /* u' = R [vy, r, roll_rate, steer_rate, sin phi, sin delta, Ff, Fr] + g0 */
    double g0[NU];
    double a[2][NU];           /* slip-angle rows -slip / vs */
    double k;                  /* vr / sigma (1/s); 0 with algebraic tyres */
} Rhs;

/* tyre quantities at a state: the forces acting, Gamma, slip angles (the runtime's aux) */
typedef struct {
    double F[2], Gamma[2], alpha[2];
} Tyres;

size_t model_size(void)
{
    return sizeof(Model);
}

/* ------------------------------------------------------------------ the physics */
static void make_rhs(const Model *m, double tau, double vx, Rhs *f)
{
    double D[NU][NU];
    for (int i = 0; i < NU; i++)
        for (int j = 0; j < NU; j++) D[i][j] = PL_C0[i][j] + vx * PL_C1[i][j];
    for (int i = 0; i < NU; i++) {
        double mt = 0.0;
        for (int j = 0; j < NU; j++) {
            double acc = 0.0;
            for (int k = 0; k < NU; k++) acc += PL_MINV[i][k] * D[k][j];
            f->R[i][j] = -acc;
        }
        for (int j = 0; j < 2; j++) {
            double ks = 0.0, kf = 0.0;
            for (int k = 0; k < NU; k++) {
                ks += PL_MINV[i][k] * PL_K_SIN[k][j];
                kf += PL_MINV[i][k] * PL_B_F[k][j];
            }
            f->R[i][NU + j] = -ks;
            f->R[i][NU + 2 + j] = kf;
        }
        for (int k = 0; k < NU; k++) mt += PL_MINV[i][k] * PL_B_TAU[k];
        f->g0[i] = mt * tau;
    }
    double vs = vx > PL_V_SLIP_MIN ? vx : PL_V_SLIP_MIN;
    double ivs = 1.0 / vs;
    double vr = vx > PL_V_RELAX_MIN ? vx : PL_V_RELAX_MIN;
    f->k = m->relax ? vr / m->sigma : 0.0;
    for (int t = 0; t < 2; t++)
        for (int j = 0; j < NU; j++) f->a[t][j] = -PL_SLIP[t][j] * ivs;
}

/* (E2)-(E3) at state x: the forces acting (Fs with algebraic tyres), Gamma, alpha; Fs */
static void tyres_at(const Model *m, const Rhs *f, const double *x, Tyres *ty, double Fs[2])
{
    for (int t = 0; t < 2; t++) {
        const double *a = f->a[t];
        double al = a[0] * x[X_VY] + a[1] * x[X_R] + a[2] * x[X_P] + a[3] * x[X_D] + PL_HEADING[t] * x[X_DELTA];
        double xe = al + m->kg[t] * (PL_CAMBER[t][0] * x[X_PHI] + PL_CAMBER[t][1] * x[X_DELTA]);
        if (m->linear) {
            Fs[t] = PL_TYRE_C1[t] * xe;
        } else {
            double b = m->B[t] * xe;
            Fs[t] = m->D[t] * sin(m->mf_C * atan(b - m->mf_E * (b - atan(b))));
        }
        ty->F[t] = m->relax ? x[X_FF + t] : Fs[t];
        ty->Gamma[t] = Fs[t] - PL_TYRE_C1[t] * xe;
        ty->alpha[t] = al;
    }
}

/* dx/dt (E1)-(E4) */
static void rhs(const Model *m, const Rhs *f, const double *x, double *dx)
{
    Tyres ty;
    double Fs[2];
    tyres_at(m, f, x, &ty, Fs);
    double v[NQ] = {x[X_VY], x[X_R], x[X_P], x[X_D], sin(x[X_PHI]), sin(x[X_DELTA]), ty.F[0], ty.F[1]};
    dx[X_PHI] = x[X_P];
    dx[X_DELTA] = x[X_D];
    for (int i = 0; i < NU; i++) {
        double acc = f->R[i][0] * v[0];
        for (int j = 1; j < NQ; j++) acc += f->R[i][j] * v[j];
        dx[X_VY + i] = acc + f->g0[i];
    }
    dx[X_FF] = m->relax ? f->k * (Fs[0] - x[X_FF]) : 0.0;
    dx[X_FR] = m->relax ? f->k * (Fs[1] - x[X_FR]) : 0.0;
}

/* upper estimate (1/s) of the spectral radius of the linearisation at speed vx (clamped) */
static double lam_est(const Model *m, double vx)
{
    if (m->relax) {
        double vr = vx >= PL_V_RELAX_MIN ? vx : PL_V_RELAX_MIN;
        return vr / m->sigma + sqrt(PL_KT / m->sigma) + PL_LAM_MECH;
    }
    return PL_KT / (vx >= PL_V_SLIP_MIN ? vx : PL_V_SLIP_MIN) + PL_LAM_MECH;
}

/* ------------------------------------------------------------------ inputs and warnings */
static void clamp_inputs(const double *u, double *tau, double *vx)
{
    double t = u[IN_rider_torque], v = u[IN_vx];
    *tau = t < -PL_TAU_MAX ? -PL_TAU_MAX : t > PL_TAU_MAX ? PL_TAU_MAX : t;
    *vx = v < 0.0 ? 0.0 : v > PL_VX_MAX ? PL_VX_MAX : v;
}

/* value > limit; at a ModelExchange event (me) while warning `flag` is off: value >= limit (the
 * indicator that fired may be exactly 0 at the root CVode reports: the crossing counts there, else
 * it would be lost) */
static int beyond(const Model *m, unsigned flag, int me, double value, double limit)
{
    return me && !(m->warned & flag) ? value >= limit : value > limit;
}

/* 1 when the condition of warning `flag` starts to hold (warn once), keeping track of it */
static int enters(Model *m, unsigned flag, int active)
{
    if (!active) {
        m->warned &= ~flag;
        return 0;
    }
    if (m->warned & flag) return 0;
    m->warned |= flag;
    return 1;
}

static void warn_inputs(Model *m, const double *u, int me, const Log *log)
{
    double tau, vx, t = u[IN_rider_torque], v = u[IN_vx];
    clamp_inputs(u, &tau, &vx);
    if (enters(m, WARN_TAU, beyond(m, WARN_TAU, me, fabs(t), PL_TAU_MAX)))
        log_event(log, LOG_WARNING, "MotorcyclePlant: |rider_torque| = %g N m clamped to %g N m", fabs(t), PL_TAU_MAX);
    if (enters(m, WARN_VX_NEG, beyond(m, WARN_VX_NEG, me, -v, 0.0)))
        log_event(log, LOG_WARNING, "MotorcyclePlant: vx = %g m/s < 0 clamped to 0 (forward only)", v);
    if (enters(m, WARN_VX_MAX, beyond(m, WARN_VX_MAX, me, v, PL_VX_MAX)))
        log_event(log, LOG_WARNING, "MotorcyclePlant: vx = %g m/s clamped to %g m/s", v, PL_VX_MAX);
    if (enters(m, WARN_VX_MIN, beyond(m, WARN_VX_MIN, me, -vx, -PL_V_WARN)))
        log_event(log, LOG_WARNING, "MotorcyclePlant: vx = %g m/s below %g m/s: slip angles and relaxation use a "
                  "%g m/s floor (model meant for vx >= 5 m/s)", vx, PL_V_WARN, PL_V_SLIP_MIN);
}

static void warn_fallen(Model *m, int me, const Log *log)
{
    double phi = m->x[X_PHI];
    if (enters(m, WARN_FALLEN, beyond(m, WARN_FALLEN, me, fabs(phi), PL_ROLL_WARN)))
        log_event(log, LOG_WARNING, "MotorcyclePlant: |roll_angle| = %.3g rad > %g rad: the motorcycle has fallen "
                  "over; results are outside the model's validity", fabs(phi), PL_ROLL_WARN);
}

/* ------------------------------------------------------------------ outputs */
static void outputs_of(const Model *m, const Rhs *f, const double *x, double *y)
{
    Tyres ty;
    double Fs[2];
    tyres_at(m, f, x, &ty, Fs);
    y[OUT_roll_angle] = x[X_PHI];
    y[OUT_steer_angle] = x[X_DELTA];
    y[OUT_vy] = x[X_VY];
    y[OUT_yaw_rate] = x[X_R];
    y[OUT_roll_rate] = x[X_P];
    y[OUT_steer_rate] = x[X_D];
    y[OUT_Ff] = ty.F[0];
    y[OUT_Fr] = ty.F[1];
    y[OUT_Gamma_f] = ty.Gamma[0];
    y[OUT_Gamma_r] = ty.Gamma[1];
    y[OUT_alpha_f] = ty.alpha[0];
    y[OUT_alpha_r] = ty.alpha[1];
}

/* the co-simulation outputs at the current state and inputs (the runtime's _update_outputs) */
static void update_outputs(Model *m, const Rhs *f, const Log *log)
{
    outputs_of(m, f, m->x, m->y);
    if (!m->relax) {                       /* algebraic tyres: report the current forces as states */
        m->x[X_FF] = m->y[OUT_Ff];
        m->x[X_FR] = m->y[OUT_Fr];
    }
    warn_fallen(m, 0, log);
}

/* ------------------------------------------------------------------ the model */
/* a parameter the runtime refuses: an error naming it */
static int refuse(const Log *log, const char *name, double value, const char *rule)
{
    log_event(log, LOG_ERROR, "MotorcyclePlant: parameter '%s' must be %s, got %g", name, rule, value);
    return -1;
}

int model_setup(Model *m, const double *p, const Log *log)
{
    double mu = p[PAR_mu], sigma = p[PAR_sigma], lin = p[PAR_linear_tires], C = p[PAR_mf_C], E = p[PAR_mf_E];
    if (!(mu > 0.0)) return refuse(log, "mu", mu, "> 0");
    if (!(sigma == 0.0 || sigma >= PL_SIGMA_MIN))
        return refuse(log, "sigma", sigma, "0 (algebraic tyres) or >= " XSTR(PL_SIGMA_MIN) " m");
    if (!(lin == 0.0 || lin == 1.0)) return refuse(log, "linear_tires", lin, "0 or 1");
    if (!(0.0 < C && C < 2.0)) return refuse(log, "mf_C", C, "in (0, 2)");
    if (!(-5.0 <= E && E <= 1.0)) return refuse(log, "mf_E", E, "in [-5, 1]");
    memset(m, 0, sizeof *m);
    m->sigma = sigma;
    m->relax = sigma > 0.0;
    m->linear = lin == 1.0;
    m->mf_C = C;
    m->mf_E = E;
    for (int t = 0; t < 2; t++) {
        m->D[t] = mu * PL_TYRE_FZ[t];
        m->B[t] = PL_TYRE_C1[t] / (C * m->D[t]);
        m->kg[t] = PL_TYRE_C2[t] / PL_TYRE_C1[t];
    }
    Rhs f;
    make_rhs(m, 0.0, 0.0, &f);
    update_outputs(m, &f, log);
    return 0;
}

void model_initialize(Model *m, const double *u, const Log *log)
{
    double tau, vx;
    Rhs f;
    warn_inputs(m, u, 0, log);
    clamp_inputs(u, &tau, &vx);
    make_rhs(m, tau, vx, &f);
    update_outputs(m, &f, log);
}

/* n equal RK4 substeps over h (module comment); 0 if more than MAX_SUBSTEPS */
static double substeps(const Model *m, double h, double vx)
{
    double n = fmax(fmax(ceil(h / PL_H_MAX - 1e-9), ceil(h * lam_est(m, vx) / PL_LAM_DT - 1e-9)), 1.0);
    return n <= MAX_SUBSTEPS ? n : 0.0;
}

int model_do_step(Model *m, double h, const double *u, const Log *log)
{
    double tau, vx, s[NQ], w[NQ], k1[NQ], k2[NQ], k3[NQ], k4[NQ];
    Rhs f;
    clamp_inputs(u, &tau, &vx);
    double n = substeps(m, h, vx);
    if (n == 0.0) {
        log_event(log, LOG_ERROR, "MotorcyclePlant: step h = %g s needs more than %g RK4 substeps; refused", h,
                  MAX_SUBSTEPS);
        return -1;
    }
    warn_inputs(m, u, 0, log);
    double dt = h / n, h2 = 0.5 * dt, h6 = dt / 6.0;
    make_rhs(m, tau, vx, &f);
    memcpy(s, m->x, sizeof s);
    for (long q = 0; q < (long)n; q++) {
        rhs(m, &f, s, k1);
        for (int i = 0; i < NQ; i++) w[i] = s[i] + h2 * k1[i];
        rhs(m, &f, w, k2);
        for (int i = 0; i < NQ; i++) w[i] = s[i] + h2 * k2[i];
        rhs(m, &f, w, k3);
        for (int i = 0; i < NQ; i++) w[i] = s[i] + dt * k3[i];
        rhs(m, &f, w, k4);
        for (int i = 0; i < NQ; i++) s[i] = s[i] + h6 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]);
    }
    for (int i = 0; i < NQ; i++)
        if (!isfinite(s[i])) {
            log_event(log, LOG_ERROR, "MotorcyclePlant: state became non-finite; step undone");
            return -1;
        }
    memcpy(m->x, s, sizeof s);
    update_outputs(m, &f, log);
    return 0;
}

void model_outputs(const Model *m, double *y, int *yi)
{
    (void)yi;
    memcpy(y, m->y, sizeof m->y);
}

/* ------------------------------------------------------------------ model exchange */
void model_me_get_states(const Model *m, double *x)
{
    memcpy(x, m->x, sizeof m->x);
}

void model_me_set_states(Model *m, const double *x)
{
    memcpy(m->x, x, sizeof m->x);
}

/* angles and rates 1, forces the tyres' peak mu Fz */
void model_me_nominals(const Model *m, double *nominal)
{
    for (int i = 0; i < NQ; i++) nominal[i] = 1.0;
    nominal[X_FF] = m->D[0];
    nominal[X_FR] = m->D[1];
}

void model_me_derivatives(const Model *m, const double *u, double *dx)
{
    double tau, vx;
    Rhs f;
    clamp_inputs(u, &tau, &vx);
    make_rhs(m, tau, vx, &f);
    rhs(m, &f, m->x, dx);
}

void model_me_event_indicators(const Model *m, const double *u, double *z)
{
    z[0] = PL_TAU_MAX - fabs(u[IN_rider_torque]);
    z[1] = u[IN_vx];
    z[2] = PL_VX_MAX - u[IN_vx];
    z[3] = u[IN_vx] - PL_V_WARN;
    z[4] = PL_ROLL_WARN - fabs(m->x[X_PHI]);
}

/* the warnings of the inputs and the fall; the continuous state is never changed */
int model_me_event_update(Model *m, double t, const double *u, const Log *log)
{
    (void)t;
    warn_inputs(m, u, 1, log);
    warn_fallen(m, 1, log);
    return 0;
}

void model_me_outputs(const Model *m, const double *u, double *y, int *yi)
{
    double tau, vx;
    Rhs f;
    (void)yi;
    clamp_inputs(u, &tau, &vx);
    make_rhs(m, tau, vx, &f);
    outputs_of(m, &f, m->x, y);
}
