/*
 * car_plant.c - CarPlant, the nonlinear two-track lateral/yaw/roll car with Magic Formula tires,
 * the truth model of every car observer: the C twin of fmu_src/car_plant.py (CarPlantModel).
 *
 * The physics (equations E1-E7), the axes and signs, the assumptions, the clamps and the numerics
 * are documented once, in docs/runtime/car_plant.md; the comments here cite it. Every expression is
 * written in the order of operations of the Python runtime, so that (same IEEE doubles, the same
 * libm) both backends give the same numbers.
 * Over ~600 lines: one nonlinear model (four wheels, roll, load transfer, CS and ME) kept whole,
 * in the order of its Python twin.
 *
 * Co-simulation (model_do_step = CarPlantModel.step): the inputs clamped with a warning on
 * entering a clamp, ax = the finite difference of consecutive vx inputs (0 on the first step),
 * Heun's method on n equal substeps (<= H_MAX, more when the fastest-mode estimate asks), the
 * outputs at the CG. Departures from the Python runtime, all for calls it cannot survive or
 * cannot see through FMI:
 *   - a step whose state becomes non-finite is refused as a whole (error logged, return -1, the
 *     model unchanged: states, previous vx, warning flags and outputs), where the Python runtime
 *     keeps the new inputs and refreshes its outputs at the old state (its FMU returns fmi2OK
 *     with the error logged; this one fmi2Error, so the host may restore a state and retry);
 *   - a step that needs more than MAX_SUBSTEPS substeps (a relaxation length sigma of
 *     micrometres, or a communication step of hours) is refused likewise, where the Python
 *     runtime would run for minutes or forever;
 *   - non-finite inputs never reach the model (the FMI layer refuses the step), so the Python
 *     runtime's "non-finite stiffness scale holds the last valid one" has no counterpart here.
 *
 * Model exchange: states x_vy, x_yaw_rate, x_roll_angle, x_roll_rate, x_Fy_fl..x_Fy_rr (the
 * Python runtime's eight) and x_vx_lag; the derivatives are CarPlantModel.derivatives at the
 * current inputs (clamped silently), the outputs those of co-simulation at the current state and
 * inputs. With algebraic tires (sigma <= 0) the four force states have zero derivative and are
 * not used (they keep their start values, 0): the forces are the algebraic E5/E6 loop of
 * co-simulation, and the outputs Fyf, Fyr report them.
 * The longitudinal acceleration ax of the load transfer (E5): FMI 2.0 gives a model-exchange FMU
 * no derivative of its inputs, and co-simulation's finite difference of consecutive step inputs
 * has no counterpart in continuous time, so ax is the derivative of the vx input through a
 * first-order lag, as in Modelica's Blocks.Continuous.Derivative:
 *     x_vx_lag' = (vx - x_vx_lag) / AX_LAG,   ax = (vx - x_vx_lag) / AX_LAG (clamped to +-AX_MAX),
 * with vx clamped as everywhere. x_vx_lag starts at the initial vx, so ax starts at 0 as in
 * co-simulation. For a smooth vx this is dvx/dt delayed by AX_LAG = 5 ms (co-simulation's
 * difference quotient: by half a step, 2.5 ms at the default 5 ms); 5 ms is short against the
 * dynamics the load transfer drives (roll ~ 0.1 s, tire relaxation sigma/vx >= 5 ms) and long
 * enough that a host holding vx over steps of that size sees no ax spikes.
 * The discrete state is the warning flags: each warning condition has an event indicator (of
 * the current flag, with a hysteresis of Z_HYSTERESIS, see indicator()), and
 * model_me_event_update logs the warnings as model_do_step does.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model.h"
#include "model_data.h"
#include "model_util.h"

#define MAX_SUBSTEPS 1e6 /* Heun substeps per call beyond which a step is refused (see above) */
#define AX_LAG 0.005     /* s, time constant of the model-exchange derivative of vx (see above) */
#define Z_HYSTERESIS 1e-9 /* SI units of each event indicator (m/s, rad, 1, m/s^2), see indicator() */
#define N_WHEELS 4       /* fl, fr, rl, rr */
#define N_BODY 4         /* vy, r, phi, phid: the states integrated with algebraic tires */
#define N_X 8            /* the Python runtime's states: body, then the four wheel forces */

/* the Python runtime's warning keys, one bit each (edge-triggered: logged when the condition
 * becomes true, re-armed when it is false again) */
enum {
    W_VX_NEG = 1 << 0,
    W_VX_MAX = 1 << 1,
    W_VX_MIN = 1 << 2,
    W_DELTA = 1 << 3,
    W_BANK = 1 << 4,
    W_SCALE_F = 1 << 5,
    W_SCALE_R = 1 << 6,
    W_AX = 1 << 7,
    W_SPIN = 1 << 8
};

/* the event indicators of model exchange, one per warning condition (indicator()) */
enum { Z_VX_NEG, Z_VX_MAX, Z_VX_MIN, Z_DELTA, Z_BANK, Z_SCALE_F, Z_SCALE_R, Z_AX, Z_SPIN, N_Z };

/* the inputs of one step after their clamps (rad, m/s, rad, 1, 1) and ax (m/s^2) */
typedef struct {
    double delta, vx, phir, sf, sr, ax;
} Held;

/* the right-hand side's constants for held inputs (CarPlantModel._make_rhs, outside ``f``) */
typedef struct {
    double vx, t2, sd, cd, vxcd, vxsd, t2cd, t2sd; /* E4 */
    double zf, zd, zr;                         /* E3 */
    double mFzf, mFzr;                         /* E5: mu times the axle's wheel load (N) */
    double mgch, gs;                           /* E1, E2 */
    double k;                                  /* E7: relaxation rate (1/s), 0 with algebraic tires */
    double nBf, nBr, nBCf, nBCr;               /* E6: -B, -B C per axle, times the stiffness inputs */
} Rhs;

/* the wheel forces (N) at a state: F the current ones, Fss their steady-state values (E6) */
typedef struct {
    double F[N_WHEELS], Fss[N_WHEELS];
    double Ff, Fr, S, ay, Mroll; /* axle sums (wheel frame), sum along body y, S/m, roll moment */
} Forces;

/* what the outputs need of the tires */
typedef struct {
    double S, Fyf, Fyr, af, ar;
} TireOut;

struct Model {
    /* parameters and the constants CarPlantModel.__init__ derives from them */
    double mu, sigma;
    int relax, linear;
    double t2, Wf, Wr, kx;               /* m; N, N static wheel loads; N/(m/s^2) per wheel */
    double mkyf, mkyr, mef, mer;         /* mu times the lateral transfer coefficients (E5) */
    double nBf, nBr, nBCf, nBCr;         /* -B, -B C per axle (E6) */
    double lam_alg, lam_osc_s, lam_roll; /* fastest-mode estimate of the substep rule */
    /* state */
    double x[N_X];
    int have_vx_prev;     /* a step was taken: vx_prev holds its vx */
    double vx_prev;       /* m/s */
    Held last;            /* the inputs of the last step (and ax), those of the outputs */
    unsigned flags;       /* W_*: warnings whose condition holds */
    double y[N_OUTPUTS];  /* co-simulation outputs */
    double vx_lag;        /* m/s, model exchange: the lag state of the vx derivative */
    int have_vx_lag;      /* vx_lag was set from an input */
};

size_t model_size(void)
{
    return sizeof(Model);
}

/* ------------------------------------------------------------------ small helpers */
/* Python's min(max(x, lo), hi), NaN and signed zeros included */
static double clamp(double x, double lo, double hi)
{
    x = lo > x ? lo : x;
    return hi < x ? hi : x;
}

/* 1 when the warning `flag` must be logged now: its condition `active` has just become true */
static int enters(Model *m, unsigned flag, int active)
{
    if (!active) {
        m->flags &= ~flag;
        return 0;
    }
    if (m->flags & flag) return 0;
    m->flags |= flag;
    return 1;
}

/* ------------------------------------------------------------------ inputs */
/* the inputs clamped (docs/runtime/car_plant.md, "Numerics and input clamping"; stiffness inputs to
 * [SCALE_IN_MIN, SCALE_IN_MAX]), ax not yet known */
static Held clamp_inputs(const double *u)
{
    Held in;
    in.delta = clamp(u[IN_delta], -CP_DELTA_MAX, CP_DELTA_MAX);
    in.vx = clamp(u[IN_vx], 0.0, CP_VX_MAX);
    in.phir = clamp(u[IN_bank_angle], -CP_BANK_MAX, CP_BANK_MAX);
    in.sf = clamp(u[IN_stiffness_scale_f], CP_SCALE_IN_MIN, CP_SCALE_IN_MAX);
    in.sr = clamp(u[IN_stiffness_scale_r], CP_SCALE_IN_MIN, CP_SCALE_IN_MAX);
    in.ax = 0.0;
    return in;
}

/* the warning of a stiffness input `name` = x outside [SCALE_IN_MIN, SCALE_IN_MAX] */
static void warn_scale(Model *m, unsigned flag, const char *name, double x, const Log *log)
{
    char a[32], b[32], lo[32], hi[32];
    double c = x < CP_SCALE_IN_MIN ? CP_SCALE_IN_MIN : CP_SCALE_IN_MAX;
    if (enters(m, flag, !(CP_SCALE_IN_MIN <= x && x <= CP_SCALE_IN_MAX)))
        log_event(log, LOG_WARNING, "CarPlant: %s = %s clamped to %s (allowed %s ... %s)", name, py_repr(x, a),
                  py_repr(c, b), py_repr(CP_SCALE_IN_MIN, lo), py_repr(CP_SCALE_IN_MAX, hi));
}

/* the warnings of the input clamps (CarPlantModel._clamp_inputs, _clamp_scales), in their order */
static void warn_inputs(Model *m, const double *u, const Log *log)
{
    char a[32], b[32];
    double vx = u[IN_vx], delta = u[IN_delta], phir = u[IN_bank_angle];
    double vxc = clamp(vx, 0.0, CP_VX_MAX);
    if (enters(m, W_VX_NEG, vx < 0.0))
        log_event(log, LOG_WARNING, "CarPlant: vx = %s m/s < 0 clamped to 0 (forward driving only)", py_repr(vx, a));
    if (enters(m, W_VX_MAX, vx > CP_VX_MAX))
        log_event(log, LOG_WARNING, "CarPlant: vx = %s m/s clamped to %s m/s", py_repr(vx, a), py_repr(CP_VX_MAX, b));
    if (enters(m, W_VX_MIN, vxc < CP_V_SLIP_MIN))
        log_event(log, LOG_WARNING, "CarPlant: vx = %s m/s below %s m/s: slip angles and relaxation regularised "
                  "(model meant for vx >= 5 m/s)", py_repr(vxc, a), py_repr(CP_V_SLIP_MIN, b));
    if (enters(m, W_DELTA, fabs(delta) > CP_DELTA_MAX))
        log_event(log, LOG_WARNING, "CarPlant: |delta| = %s rad clamped to %s rad", py_repr(fabs(delta), a),
                  py_repr(CP_DELTA_MAX, b));
    if (enters(m, W_BANK, fabs(phir) > CP_BANK_MAX))
        log_event(log, LOG_WARNING, "CarPlant: |bank_angle| = %s rad clamped to %s rad", py_repr(fabs(phir), a),
                  py_repr(CP_BANK_MAX, b));
    warn_scale(m, W_SCALE_F, "stiffness_scale_f", u[IN_stiffness_scale_f], log);
    warn_scale(m, W_SCALE_R, "stiffness_scale_r", u[IN_stiffness_scale_r], log);
}

/* the longitudinal acceleration (m/s^2) clamped to +-AX_MAX, with its warning; `source` says
 * where the unclamped value `ax` came from */
static double limit_ax(Model *m, double ax, const char *source, const Log *log)
{
    char a[32];
    if (enters(m, W_AX, ax > CP_AX_MAX || ax < -CP_AX_MAX))
        log_event(log, LOG_WARNING, "CarPlant: longitudinal acceleration %.4g m/s^2 (%s) clamped to +-%s", ax, source,
                  py_repr(CP_AX_MAX, a));
    return clamp(ax, -CP_AX_MAX, CP_AX_MAX);
}

/* ------------------------------------------------------------------ the physics */
/* the constants of the right-hand side for the held inputs `in` (CarPlantModel._make_rhs) */
static Rhs make_rhs(const Model *m, const Held *in)
{
    Rhs c;
    /* time-varying cornering stiffness: the inputs multiply B (exact no-op at 1.0) */
    c.nBf = m->nBf * in->sf;
    c.nBr = m->nBr * in->sr;
    c.nBCf = m->nBCf * in->sf;
    c.nBCr = m->nBCr * in->sr;
    c.vx = in->vx;
    c.t2 = m->t2;
    c.sd = sin(in->delta);
    c.cd = cos(in->delta);
    /* E4: u_fl,fr = vx cd + vf sd -+ r (t/2) cd, v_fl,fr = vf cd - vx sd +- r (t/2) sd */
    c.vxcd = in->vx * c.cd;
    c.vxsd = in->vx * c.sd;
    c.t2cd = m->t2 * c.cd;
    c.t2sd = m->t2 * c.sd;
    /* E3: r' = (lf cd (Fy_fl + Fy_fr) + (t/2) sd (Fy_fl - Fy_fr) - lr (Fy_rl + Fy_rr)) / Iz */
    c.zf = CP_VEHICLE.lf * c.cd / CP_VEHICLE.Iz;
    c.zd = c.t2sd / CP_VEHICLE.Iz;
    c.zr = CP_VEHICLE.lr / CP_VEHICLE.Iz;
    /* E5: static loads on the bank and the longitudinal transfer, clamped so no axle goes below 0 */
    double cphr = cos(in->phir);
    double Fzf = m->Wf * cphr;
    double Fzr = m->Wr * cphr;
    double dx = m->kx * in->ax;
    if (dx > Fzf)
        dx = Fzf;
    else if (dx < -Fzr)
        dx = -Fzr;
    Fzf -= dx;
    Fzr += dx;
    c.mFzf = m->mu * Fzf; /* the lateral clamps act on mu dFz (mu > 0) */
    c.mFzr = m->mu * Fzr;
    c.mgch = CP_VEHICLE.m * CP_G * cphr * CP_VEHICLE.hr; /* E1: roll moment of the vertical reaction */
    c.gs = CP_G * sin(in->phir);                         /* E2: bank gravity component */
    double vrel = in->vx > CP_V_RELAX_MIN ? in->vx : CP_V_RELAX_MIN;
    c.k = m->relax ? vrel / m->sigma : 0.0; /* E7 */
    return c;
}

/* E4: q = tan(-alpha) = v / max(u, V_SLIP_MIN) per wheel (fl, fr, rl, rr), from the wheel-frame
 * velocity (u along the wheel, v across it) at the body state s = [vy, r, ...]; for
 * u >= V_SLIP_MIN exactly alpha = delta_w - atan2(vy + r xw, vx - r yw) */
static void slip_tangents(const Rhs *c, const double *s, double *q)
{
    const double vmin = CP_V_SLIP_MIN;
    double vy = s[0], r = s[1];
    double rt = r * c->t2;
    double ul = c->vx - rt;            /* body-x velocity of the left wheels (yw = +t/2) */
    double ur = c->vx + rt;            /* right wheels (yw = -t/2) */
    double vf = vy + r * CP_VEHICLE.lf; /* body-y velocity of the front wheels */
    double vr = vy - r * CP_VEHICLE.lr; /* rear wheels */
    double uf = c->vxcd + vf * c->sd;
    double wf = vf * c->cd - c->vxsd;
    double rc = r * c->t2cd;
    double rs = r * c->t2sd;
    double u1 = uf - rc;
    double u2 = uf + rc;
    q[0] = (wf + rs) / (u1 > vmin ? u1 : vmin);
    q[1] = (wf - rs) / (u2 > vmin ? u2 : vmin);
    q[2] = vr / (ul > vmin ? ul : vmin);
    q[3] = vr / (ur > vmin ? ur : vmin);
}

/* E6 with x = B alpha: Fy_ss / (mu Fz) = sin(C atan(x - E (x - atan x))) */
static double magic_formula(double x)
{
    return sin(CP_VEHICLE.mf_C * atan(x - CP_VEHICLE.mf_E * (x - atan(x))));
}

/* E6: g = Fy_ss / (mu Fz) per wheel from the slip tangents q (alpha = -atan q); linear_tires: the
 * Magic Formula's slope at zero slip, B C alpha */
static void tire_curves(const Model *m, const Rhs *c, const double *q, double *g)
{
    if (m->linear) {
        g[0] = c->nBCf * atan(q[0]);
        g[1] = c->nBCf * atan(q[1]);
        g[2] = c->nBCr * atan(q[2]);
        g[3] = c->nBCr * atan(q[3]);
    } else {
        g[0] = magic_formula(c->nBf * atan(q[0]));
        g[1] = magic_formula(c->nBf * atan(q[1]));
        g[2] = magic_formula(c->nBr * atan(q[2]));
        g[3] = magic_formula(c->nBr * atan(q[3]));
    }
}

/* E5: an axle's lateral transfer d = mu dFz clamped to mu Fz_axle (every Fz >= 0) */
static double limit_transfer(double d, double mFz)
{
    if (d > mFz) return mFz;
    if (d < -mFz) return -mFz;
    return d;
}

/* E5 x E6: steady-state wheel forces (N) for the unclamped axle transfers df, dr (mu dFz): left
 * wheels -dFz, right +dFz */
static void steady_forces(const Rhs *c, const double *g, double df, double dr, double *Fss)
{
    df = limit_transfer(df, c->mFzf);
    dr = limit_transfer(dr, c->mFzr);
    Fss[0] = (c->mFzf - df) * g[0];
    Fss[1] = (c->mFzf + df) * g[1];
    Fss[2] = (c->mFzr - dr) * g[2];
    Fss[3] = (c->mFzr + dr) * g[3];
}

/* the wheel forces at the state s (E5, E6; "Modelling assumptions", load transfer): with
 * relaxation the forces are the states and ay_eff = S/m comes from them; with algebraic tires
 * the loop is solved by one fixed-point iteration (pass 1 with ay_eff = 0, pass 2 with
 * ay_eff = S_pass1 / m) and the forces are the steady-state ones */
static void wheel_forces(const Model *m, const Rhs *c, const double *s, const double *g, Forces *f)
{
    f->Mroll = CP_VEHICLE.Kr * s[2] + CP_VEHICLE.br * s[3];
    if (m->relax) {
        for (int i = 0; i < N_WHEELS; i++) f->F[i] = s[N_BODY + i];
        f->Ff = f->F[0] + f->F[1];
        f->Fr = f->F[2] + f->F[3];
        f->S = f->Ff * c->cd + f->Fr;
    } else {
        steady_forces(c, g, m->mef * f->Mroll, m->mer * f->Mroll, f->Fss);
        f->S = (f->Fss[0] + f->Fss[1]) * c->cd + f->Fss[2] + f->Fss[3];
    }
    f->ay = f->S / CP_VEHICLE.m;
    steady_forces(c, g, m->mkyf * f->ay + m->mef * f->Mroll, m->mkyr * f->ay + m->mer * f->Mroll, f->Fss);
    if (!m->relax) {
        for (int i = 0; i < N_WHEELS; i++) f->F[i] = f->Fss[i];
        f->Ff = f->Fss[0] + f->Fss[1];
        f->Fr = f->Fss[2] + f->Fss[3];
        f->S = f->Ff * c->cd + f->Fr;
        f->ay = f->S / CP_VEHICLE.m;
    }
}

/* d = ds/dt at s = [vy, r, phi, phid, Fy_fl, Fy_fr, Fy_rl, Fy_rr] (SI): E1 then E2, E3, E7; with
 * algebraic tires s[4..7] are ignored and d[4..7] = 0 */
static void rhs(const Model *m, const Rhs *c, const double *s, double *d)
{
    double q[N_WHEELS], g[N_WHEELS];
    Forces f;
    slip_tangents(c, s, q);
    tire_curves(m, c, q, g);
    wheel_forces(m, c, s, g, &f);
    double sphi = sin(s[2]);
    double cphi = cos(s[2]);
    double phidd = (CP_VEHICLE.hr * f.S * cphi + c->mgch * sphi - f.Mroll) / CP_VEHICLE.Ix;
    d[0] = f.ay - c->gs - c->vx * s[1] + CP_VEHICLE.hr * (phidd * cphi - s[3] * s[3] * sphi);
    d[1] = c->zf * f.Ff + c->zd * (f.F[0] - f.F[1]) - c->zr * f.Fr;
    d[2] = s[3];
    d[3] = phidd;
    for (int i = 0; i < N_WHEELS; i++) d[N_BODY + i] = c->k * (f.Fss[i] - f.F[i]);
}

/* what the outputs need of the tires at the state s (f(..., aux=1) of the Python runtime); with
 * algebraic tires the wheel forces go to F */
static TireOut tire_outputs(const Model *m, const Rhs *c, const double *s, double *F)
{
    double q[N_WHEELS];
    TireOut t;
    slip_tangents(c, s, q);
    t.af = -0.5 * (atan(q[0]) + atan(q[1]));
    t.ar = -0.5 * (atan(q[2]) + atan(q[3]));
    if (m->relax) { /* the forces are states: no Magic Formula needed */
        t.Fyf = (s[4] + s[5]) * c->cd;
        t.S = t.Fyf + s[6] + s[7];
        t.Fyr = s[6] + s[7];
    } else {
        double g[N_WHEELS];
        Forces f;
        tire_curves(m, c, q, g);
        wheel_forces(m, c, s, g, &f);
        for (int i = 0; i < N_WHEELS; i++) F[i] = f.F[i];
        t.S = f.S;
        t.Fyf = f.Ff * c->cd;
        t.Fyr = f.Fr;
    }
    return t;
}

/* the outputs at the CG (docs/runtime/car_plant.md, "Outputs at the centre of gravity") at the state s and
 * the (clamped) speed vx */
static void write_outputs(const double *s, const TireOut *t, double vx, double *y)
{
    double vs = vx > CP_V_SLIP_MIN ? vx : CP_V_SLIP_MIN;
    double vy_cg = s[0] - CP_VEHICLE.hr * s[3] * cos(s[2]);
    y[OUT_beta] = atan(s[0] / vs);
    y[OUT_vy] = s[0];
    y[OUT_yaw_rate] = s[1];
    y[OUT_ay] = t->S / CP_VEHICLE.m;
    y[OUT_roll_angle] = s[2];
    y[OUT_roll_rate] = s[3];
    y[OUT_Fyf] = t->Fyf;
    y[OUT_Fyr] = t->Fyr;
    y[OUT_alpha_f] = t->af;
    y[OUT_alpha_r] = t->ar;
    y[OUT_vy_cg] = vy_cg;
    y[OUT_beta_cg] = atan(vy_cg / vs);
}

/* the spin-out warning ("Validity limit: spin-out") for the mean rear slip angle ar (rad) */
static void warn_spin(Model *m, double ar, const Log *log)
{
    char a[32];
    if (enters(m, W_SPIN, ar > CP_ALPHA_SPIN || ar < -CP_ALPHA_SPIN))
        log_event(log, LOG_WARNING, "CarPlant: |alpha_r| = %.3g rad > %s rad: the car has spun out; with prescribed "
                  "vx the model is not valid beyond this (the body keeps sliding sideways)", fabs(ar),
                  py_repr(CP_ALPHA_SPIN, a));
}

/* the co-simulation outputs at the current state and the last step's inputs
 * (CarPlantModel._update_outputs); with algebraic tires the current forces become the force states */
static void update_outputs(Model *m, const Rhs *c, const Log *log)
{
    TireOut t = tire_outputs(m, c, m->x, m->x + N_BODY);
    write_outputs(m->x, &t, m->last.vx, m->y);
    warn_spin(m, t.ar, log);
}

/* ------------------------------------------------------------------ set-up */
static int positive(double x, const char *name, const Log *log)
{
    char a[32];
    if (x > 0) return 1;
    log_event(log, LOG_ERROR, "CarPlant: parameter '%s' must be > 0, got %s", name, py_repr(x, a));
    return 0;
}

/* CarPlantModel.__init__'s checks of the FMU parameters (the layer has checked their ranges) */
static int parameters_ok(const double *p, const Log *log)
{
    char a[32];
    if (!positive(p[PAR_mu], "mu", log) || !positive(p[PAR_scale_f], "scale_f", log) ||
        !positive(p[PAR_scale_r], "scale_r", log))
        return 0;
    if (p[PAR_linear_tires] == 0.0 || p[PAR_linear_tires] == 1.0) return 1;
    log_event(log, LOG_ERROR, "CarPlant: parameter 'linear_tires' must be 0 (Magic Formula) or 1 (linear tires), "
              "got %s", py_repr(p[PAR_linear_tires], a));
    return 0;
}

/* the constants CarPlantModel.__init__ derives from the vehicle and the parameters p */
static void derive_constants(Model *m, const double *p)
{
    const double mass = CP_VEHICLE.m, lf = CP_VEHICLE.lf, lr = CP_VEHICLE.lr, C = CP_VEHICLE.mf_C;
    const double L = lf + lr, t = CP_VEHICLE.track, hr = CP_VEHICLE.hr, Ix = CP_VEHICLE.Ix;
    const double mu = p[PAR_mu];
    m->mu = mu;
    m->sigma = p[PAR_sigma];
    m->relax = m->sigma > 0.0;
    m->linear = p[PAR_linear_tires] == 1.0;
    m->t2 = 0.5 * t;
    /* flat-road static wheel loads (N) and the per-axle Magic Formula B (E6) */
    m->Wf = mass * CP_G * lr / (2.0 * L);
    m->Wr = mass * CP_G * lf / (2.0 * L);
    const double Cf_eff = p[PAR_scale_f] * CP_VEHICLE.Cf; /* N/rad, per axle */
    const double Cr_eff = p[PAR_scale_r] * CP_VEHICLE.Cr;
    const double Bf = 0.5 * Cf_eff / (mu * m->Wf * C);
    const double Br = 0.5 * Cr_eff / (mu * m->Wr * C);
    m->nBf = -Bf;
    m->nBr = -Br;
    m->nBCf = -Bf * C;
    m->nBCr = -Br * C;
    /* load transfer coefficients (E5): N per m/s^2 per wheel; times mu, N per m/s^2 and 1/m */
    m->kx = mass * (CP_VEHICLE.h_rc + hr) / (2.0 * L);
    m->mkyf = mu * (mass * lr / L * CP_VEHICLE.h_rc / t);
    m->mkyr = mu * (mass * lf / L * CP_VEHICLE.h_rc / t);
    m->mef = mu * (CP_VEHICLE.roll_share_f / t);
    m->mer = mu * ((1.0 - CP_VEHICLE.roll_share_f) / t);
    /* fastest-mode estimate per unit 1/speed (algebraic tires) and roll, for the substeps; x2:
     * lateral load transfer can double a wheel's load */
    const double Ca0 = 2.0 * (Cf_eff + Cr_eff);
    const double Ca2 = 2.0 * (Cf_eff * lf * lf + Cr_eff * lr * lr);
    m->lam_alg = Ca0 * (1.0 / mass + hr * hr / Ix) + Ca2 / CP_VEHICLE.Iz; /* 1/s per 1/(m/s) */
    m->lam_roll = CP_VEHICLE.br / Ix + sqrt(CP_VEHICLE.Kr / Ix);
    m->lam_osc_s = m->relax ? sqrt(m->lam_alg) / sqrt(m->sigma) : 0.0; /* relaxation oscillation */
}

int model_setup(Model *m, const double *p, const Log *log)
{
    if (!parameters_ok(p, log)) return -1;
    derive_constants(m, p);
    /* the start: at rest, no step taken, the outputs of zero inputs */
    for (int i = 0; i < N_X; i++) m->x[i] = 0.0;
    m->have_vx_prev = 0;
    m->vx_prev = 0.0;
    m->last = (Held){0.0, 0.0, 0.0, 1.0, 1.0, 0.0};
    m->flags = 0;
    m->have_vx_lag = 0;
    m->vx_lag = 0.0;
    Rhs c = make_rhs(m, &m->last);
    update_outputs(m, &c, log);
    return 0;
}

/* CarPlantModel has no ``initialize``: the plant starts at rest with the outputs of model_setup
 * and sees its inputs from the first step on (ax = 0 there). Model exchange: the lag state of the
 * vx derivative starts at the initial vx, so that ax starts at 0 too. */
void model_initialize(Model *m, const double *u, const Log *log)
{
    (void)log;
    m->vx_lag = clamp(u[IN_vx], 0.0, CP_VX_MAX);
    m->have_vx_lag = 1;
}

/* ------------------------------------------------------------------ co-simulation */
/* CarPlantModel.step's substep count: h / n <= H_MAX and (fastest-mode estimate) h / n <= 1; the
 * tire-stiffness part grows linearly (algebraic) or as the square root (relaxation oscillation)
 * with the stiffness inputs; scales < 1 keep the nominal estimate */
static double substeps(const Model *m, double h, const Held *in)
{
    double smax = in->sf > in->sr ? in->sf : in->sr;
    double lam;
    if (m->relax) {
        double vrel = in->vx > CP_V_RELAX_MIN ? in->vx : CP_V_RELAX_MIN;
        double osc = smax > 1.0 ? m->lam_osc_s * sqrt(smax) : m->lam_osc_s;
        lam = vrel / m->sigma + osc + m->lam_roll;
    } else {
        double vs = in->vx > CP_V_SLIP_MIN ? in->vx : CP_V_SLIP_MIN;
        double alg = smax > 1.0 ? m->lam_alg * smax : m->lam_alg;
        lam = alg / vs + m->lam_roll;
    }
    double n = ceil(h / CP_H_MAX - 1e-9);
    double n_lam = ceil(h * lam - 1e-9);
    if (n_lam > n) n = n_lam;
    return n > 1.0 ? n : 1.0;
}

/* Heun's method (explicit trapezoidal rule): n substeps of dt from s; with algebraic tires only
 * the body states are integrated */
static void heun(const Model *m, const Rhs *c, int n, double dt, double *s)
{
    const int nx = m->relax ? N_X : N_BODY;
    const double hd = 0.5 * dt;
    double a[N_X], b[N_X], p[N_X];
    for (int i = N_BODY; i < N_X; i++) p[i] = s[i];
    for (int k = 0; k < n; k++) {
        rhs(m, c, s, a);
        for (int i = 0; i < nx; i++) p[i] = s[i] + dt * a[i];
        rhs(m, c, p, b);
        for (int i = 0; i < nx; i++) s[i] += hd * (a[i] + b[i]);
    }
}

/* CarPlantModel.step on m (which the caller discards on failure): 0, or -1 with an error logged */
static int advance(Model *m, double h, const double *u, const Log *log)
{
    char a[32];
    Held in = clamp_inputs(u);
    warn_inputs(m, u, log);
    in.ax = limit_ax(m, m->have_vx_prev ? (in.vx - m->vx_prev) / h : 0.0, "from vx inputs", log); /* E5 */
    m->have_vx_prev = 1;
    m->vx_prev = in.vx;
    m->last = in;
    double n = substeps(m, h, &in);
    if (!(n <= MAX_SUBSTEPS)) {
        log_event(log, LOG_ERROR, "CarPlant: a step of %s s would need %.3g Heun substeps (more than %.0f: relaxation "
                  "length sigma = %g m, stiffness inputs %g, %g); step refused", py_repr(h, a), n, MAX_SUBSTEPS,
                  m->sigma, in.sf, in.sr);
        return -1;
    }
    Rhs c = make_rhs(m, &in);
    double s[N_X];
    for (int i = 0; i < N_X; i++) s[i] = m->x[i];
    heun(m, &c, (int)n, h / n, s);
    for (int i = 0; i < N_X; i++)
        if (!isfinite(s[i])) {
            log_event(log, LOG_ERROR, "CarPlant: state became non-finite; step undone");
            return -1;
        }
    for (int i = 0; i < N_X; i++) m->x[i] = s[i];
    update_outputs(m, &c, log);
    return 0;
}

int model_do_step(Model *m, double h, const double *u, const Log *log)
{
    Model next = *m;
    if (advance(&next, h, u, log) != 0) return -1;
    *m = next;
    return 0;
}

void model_outputs(const Model *m, double *y, int *yi)
{
    (void)yi;
    for (int i = 0; i < N_OUTPUTS; i++) y[i] = m->y[i];
}

/* ------------------------------------------------------------------ model exchange */
#if N_STATES > 0
/* the state order of model_data.h: the Python runtime's eight, then the lag state of vx */
enum { X_VX_LAG = N_X };
/* the emitter (latobs/cbackend/car_plant.py) declares N_Z event indicators and N_X + 1 states */
typedef char check_event_indicators[N_EVENT_INDICATORS == N_Z ? 1 : -1];
typedef char check_states[N_STATES == N_X + 1 ? 1 : -1];

/* the held inputs of model exchange: clamped silently; ax the unclamped lagged derivative of vx */
static Held me_inputs(const Model *m, const double *u, double *ax_raw)
{
    Held in = clamp_inputs(u);
    *ax_raw = (in.vx - m->vx_lag) / AX_LAG;
    in.ax = clamp(*ax_raw, -CP_AX_MAX, CP_AX_MAX);
    return in;
}

void model_me_get_states(const Model *m, double *x)
{
    for (int i = 0; i < N_X; i++) x[i] = m->x[i];
    x[X_VX_LAG] = m->vx_lag;
}

void model_me_set_states(Model *m, const double *x)
{
    for (int i = 0; i < N_X; i++) m->x[i] = x[i];
    m->vx_lag = x[X_VX_LAG];
}

/* vy 1 m/s, r 1 rad/s, phi 0.1 rad, phid 1 rad/s, the wheel forces mu times their static load,
 * vx_lag 10 m/s */
void model_me_nominals(const Model *m, double *nominal)
{
    nominal[0] = 1.0;
    nominal[1] = 1.0;
    nominal[2] = 0.1;
    nominal[3] = 1.0;
    nominal[4] = nominal[5] = m->mu * m->Wf;
    nominal[6] = nominal[7] = m->mu * m->Wr;
    nominal[X_VX_LAG] = 10.0;
}

void model_me_derivatives(const Model *m, const double *u, double *dx)
{
    double ax_raw;
    Held in = me_inputs(m, u, &ax_raw);
    Rhs c = make_rhs(m, &in);
    rhs(m, &c, m->x, dx);
    dx[X_VX_LAG] = ax_raw;
}

/* an indicator of the current discrete state: d is > 0 while the warning's condition is false,
 * < 0 while it holds (its flag is then set); the zero crossing lies Z_HYSTERESIS beyond the
 * condition's boundary, so the condition has changed when the host reaches the event (a root
 * located exactly on the boundary, e.g. an input sample equal to the limit, would leave it
 * unchanged and the indicator at 0, where a root finder no longer sees it leave) */
static double indicator(const Model *m, unsigned flag, double d)
{
    return (m->flags & flag ? -d : d) + Z_HYSTERESIS;
}

/* one per warning condition (enum Z_*) */
void model_me_event_indicators(const Model *m, const double *u, double *z)
{
    double ax_raw, q[N_WHEELS];
    Held in = me_inputs(m, u, &ax_raw);
    Rhs c = make_rhs(m, &in);
    slip_tangents(&c, m->x, q);
    double ar = -0.5 * (atan(q[2]) + atan(q[3]));
    double sf = u[IN_stiffness_scale_f], sr = u[IN_stiffness_scale_r];
    z[Z_VX_NEG] = indicator(m, W_VX_NEG, u[IN_vx]);
    z[Z_VX_MAX] = indicator(m, W_VX_MAX, CP_VX_MAX - u[IN_vx]);
    z[Z_VX_MIN] = indicator(m, W_VX_MIN, u[IN_vx] - CP_V_SLIP_MIN);
    z[Z_DELTA] = indicator(m, W_DELTA, CP_DELTA_MAX - fabs(u[IN_delta]));
    z[Z_BANK] = indicator(m, W_BANK, CP_BANK_MAX - fabs(u[IN_bank_angle]));
    z[Z_SCALE_F] = indicator(m, W_SCALE_F, fmin(sf - CP_SCALE_IN_MIN, CP_SCALE_IN_MAX - sf));
    z[Z_SCALE_R] = indicator(m, W_SCALE_R, fmin(sr - CP_SCALE_IN_MIN, CP_SCALE_IN_MAX - sr));
    z[Z_AX] = indicator(m, W_AX, CP_AX_MAX - fabs(ax_raw));
    z[Z_SPIN] = indicator(m, W_SPIN, CP_ALPHA_SPIN - fabs(ar));
}

/* the warnings of the current inputs and state (the discrete state: their flags); the first
 * event after a start without finite initial inputs sets the lag state to vx */
int model_me_event_update(Model *m, double t, const double *u, const Log *log)
{
    double ax_raw, q[N_WHEELS];
    int changed = !m->have_vx_lag;
    (void)t;
    if (changed) {
        m->vx_lag = clamp(u[IN_vx], 0.0, CP_VX_MAX);
        m->have_vx_lag = 1;
    }
    Held in = me_inputs(m, u, &ax_raw);
    warn_inputs(m, u, log);
    limit_ax(m, ax_raw, "lagged derivative of the vx input", log);
    Rhs c = make_rhs(m, &in);
    slip_tangents(&c, m->x, q);
    warn_spin(m, -0.5 * (atan(q[2]) + atan(q[3])), log);
    return changed;
}

void model_me_outputs(const Model *m, const double *u, double *y, int *yi)
{
    double ax_raw, F[N_WHEELS];
    (void)yi;
    Held in = me_inputs(m, u, &ax_raw);
    Rhs c = make_rhs(m, &in);
    TireOut t = tire_outputs(m, &c, m->x, F);
    write_outputs(m->x, &t, in.vx, y);
}
#endif
