/* SPDX-License-Identifier: Apache-2.0
 * Copyright 2026 pneumatic_unload maintainers
 */
/* The compiled core of the pneumatic_unload discharge model (see kernel.py, which builds
 * and loads this file): the ISO 6358 flow function, the wall heat laws, the right-hand
 * side of the tank's mass and energy balance, and a Dormand-Prince 5(4) integrator with
 * its continuous extension. This is the only implementation of these formulae in the
 * package; the Python side packs the parameters (model/ode.py, model/heat.py).
 *
 * SI units: Pa absolute, K, m^3, s, kg/s, W. Parameter slots: keep equal to kernel.py.
 */
#include <math.h>
#include <stddef.h>
#include <stdlib.h>

enum {
    GAMMA, R_GAS, CP, VOLUME, P_ATM, T_WALL, B_RATIO, M_INDEX, C_RHO, LEAK,
    HEAT_MODE, HEAT_A, HEAT_RA, PIPE, PIPE_VOLUME, PIPE_C_RHO,
    T_OPEN, RAMP, T_CLOSE, R_LIN, SQRT_TN,
    LEAK_DOWN, OLEAK_C_RHO, OLEAK_B, OLEAK_DOWN_C_RHO, OLEAK_DOWN_B, HEAT_TURB,
    CHARGE, P_SUPPLY, T_SUPPLY, HEAT_JET, Q_EXPONENT, SERIES_KAPPA, SERIES_B, SERIES_M,
    SERIES_X0, HEAT_G1, HEAT_G2, HEAT_TREF, N_PARAMETERS
};

/* Exponent of the inflow's Reynolds number in a charge's jet-driven convection [-]. */
#define JET_EXPONENT 0.67

/* Subsonic index of the orifice-law leaks [-] (a sharp-edged orifice). */
#define LEAK_M_INDEX 0.5

enum { HEAT_NONE = 0, HEAT_NATURAL = 1, HEAT_FIXED = 2, HEAT_DENSITY = 3, HEAT_TIME = 4 };
enum { OK = 0, TOO_MANY_STEPS = 1, STEP_TOO_SMALL = 2, NOT_FINITE = 3 };

#define MAX_STATES 8

int pu_n_parameters(void) { return N_PARAMETERS; }

/* The step size h [s] rounded down onto a grid of 16 sizes per octave (h = m 2^e with m a
 * multiple of 1/32 in [1/2, 1); frexp and ldexp are exact). The step sequence chosen by
 * the error control then stays the same under last-bit changes of the parameters, so the
 * solution is a smooth function of them except where a proposed size crosses a grid
 * line (rare): a fit's Gauss-Newton polish converges onto its stationary point, which
 * last-bit differences (another BLAS kernel, another summation order) then move only by
 * rounding. A free step size jittered the solution by ~1e-10 relative, which left the
 * fitted C reproducible to ~1e-9 and b to ~1e-7 only. Costs about 3 % more steps. */
static double grid_step(double h)
{
    int e;
    double m = frexp(h, &e);
    return ldexp(floor(m * 32.0) / 32.0, e);
}

/* ISO 6358 flow function phi(r), r = p2/p1 [-]; b critical ratio, m subsonic index,
 * q the exponent of the subsonic branch's ellipse (2 in ISO 6358-1:2013: phi =
 * (1 - x^q)^m, x = (r - b)/(1 - b); another q describes a curve that is not ISO-shaped,
 * e.g. two restrictions in series), linear in (1 - r) above r_linear (0 at r = 1,
 * negative beyond: reverse flow). q = 2 is computed as x * x (the law as it always was,
 * bit for bit). */
static double ellipse_power(double x, double q)
{
    return q == 2.0 ? x * x : pow(x, q);
}

double pu_flow_phi(double r, double b, double m, double q, double r_linear)
{
    if (r <= b) return 1.0;
    if (r > r_linear) {
        double xl = (r_linear - b) / (1.0 - b);
        return pow(1.0 - ellipse_power(xl, q), m) * (1.0 - r) / (1.0 - r_linear);
    }
    double x = (r - b) / (1.0 - b);
    return pow(1.0 - ellipse_power(x, q), m);
}

/* The root of a falling gap f on [lo, hi] (f(lo) > 0 > f(hi); an end where it is not)
 * by the Illinois method, to the last bits (a fit's finite differences see a smooth
 * function of the parameters). a: the gap's arguments. */
typedef double (*gap_fn)(double x, const double *a);

static double falling_root(gap_fn f, const double *a, double lo, double hi)
{
    double flo = f(lo, a), fhi = f(hi, a), x = lo;
    if (!(flo > 0.0)) return lo;
    if (!(fhi < 0.0)) return hi;
    int side = 0;
    for (int i = 0; i < 200 && hi - lo > 1e-15 * hi; i++) {
        x = (lo * fhi - hi * flo) / (fhi - flo);
        if (!(x > lo && x < hi)) x = 0.5 * (lo + hi);
        double fx = f(x, a);
        if (fx > 0.0) { lo = x; flo = fx; if (side == 1) fhi *= 0.5; side = 1; }
        else if (fx < 0.0) { hi = x; fhi = fx; if (side == -1) flo *= 0.5; side = -1; }
        else return x;
    }
    return x;
}

/* a = (b1, m1, b2, m2, kappa, r, r_linear): the upstream element at x = p_i/p1 against
 * the downstream one at r/x (continuity, C1 phi1(x) = C2 x phi2(r/x), per C1) and the
 * choked pair's (phi1(x) = kappa x: the downstream element choked). */
static double series_gap(double x, const double *a)
{
    return pu_flow_phi(x, a[0], a[1], 2.0, a[6])
           - a[4] * x * pu_flow_phi(a[5] / x, a[2], a[3], 2.0, a[6]);
}

static double choked_gap(double x, const double *a)
{
    return pu_flow_phi(x, a[0], a[1], 2.0, a[6]) - a[4] * x;
}

/* The intermediate ratio x0 = p_i/p1 [-] of two ISO 6358-1 elements in series when the
 * pair is choked (upstream element b1, m1; the downstream one's conductance kappa times
 * the upstream one's): phi1(x0) = kappa x0 (the downstream element choked), or 1/kappa
 * when the upstream element chokes first (kappa b1 >= 1). */
double pu_series_choked(double b1, double m1, double kappa, double r_linear)
{
    double a[7] = {b1, m1, 0.0, 0.0, kappa, 0.0, r_linear};
    return kappa * b1 >= 1.0 ? 1.0 / kappa : falling_root(choked_gap, a, b1, 1.0);
}

/* Flow function [-] of two ISO 6358-1 elements in series (ISO 6358-3: one mass flow
 * through both, one stagnation temperature, no volume between them), normalised by the
 * pair's choked flow: the upstream element (b1, m1), the downstream one (b2, m2) of
 * conductance kappa C1; phi = phi1(x)/phi1(x0), x = p_i/p1 by continuity at r = p2/p1,
 * x0 the choked pair's (pu_series_choked, passed in: it depends on the parameters
 * alone). Linear in (1 - r) above r_linear from its value there, as the ISO law. */
static double series_phi_at(double r, double b1, double m1, double b2, double m2,
                            double kappa, double r_linear, double x0)
{
    double rr = r > r_linear ? r_linear : r;
    double end = r > r_linear ? (1.0 - r) / (1.0 - r_linear) : 1.0;
    if (kappa * b1 < 1.0 && rr <= b2 * x0) return end;  /* choked */
    double a[7] = {b1, m1, b2, m2, kappa, rr, r_linear};
    return pu_flow_phi(falling_root(series_gap, a, rr, 1.0), b1, m1, 2.0, r_linear)
           / pu_flow_phi(x0, b1, m1, 2.0, r_linear) * end;
}

double pu_series_phi(double r, double b1, double m1, double b2, double m2, double kappa,
                     double r_linear)
{
    return series_phi_at(r, b1, m1, b2, m2, kappa, r_linear,
                         pu_series_choked(b1, m1, kappa, r_linear));
}

/* The component's flow function [-]: the ISO law (b, m, q), or a pair in series where
 * SERIES_KAPPA > 0 (its upstream element b, m; the downstream SERIES_B, SERIES_M; the
 * choked pair's SERIES_X0 from pu_series_choked, packed with the parameters). */
static double component_phi(double r, const double *prm, double r_lin)
{
    if (prm[SERIES_KAPPA] > 0.0)
        return series_phi_at(r, prm[B_RATIO], prm[M_INDEX], prm[SERIES_B], prm[SERIES_M],
                             prm[SERIES_KAPPA], r_lin, prm[SERIES_X0]);
    return pu_flow_phi(r, prm[B_RATIO], prm[M_INDEX], prm[Q_EXPONENT], r_lin);
}

/* pu_series_phi (kappa > 0; the choked pair's ratio solved once) or pu_flow_phi at n
 * ratios r into out [-]. */
void pu_component_phi_array(int n, const double *r, double b, double m, double q,
                            double b2, double m2, double kappa, double r_linear,
                            double *out)
{
    double x0 = kappa > 0.0 ? pu_series_choked(b, m, kappa, r_linear) : 0.0;
    for (int i = 0; i < n; i++)
        out[i] = kappa > 0.0 ? series_phi_at(r[i], b, m, b2, m2, kappa, r_linear, x0)
                             : pu_flow_phi(r[i], b, m, q, r_linear);
}

/* Wall heat flow into the gas Q [W] at p [Pa], gas temperature t_gas [K].
 * natural: Q = coeff Nu(Ra) (Tw - T), Nu = 0.59 Ra^0.25 (Ra < 1e9) or turb 0.10 Ra^(1/3)
 * (turb [-] scales the turbulent branch alone: 1 is the correlation as published; 1.3
 * gives McAdams' 0.13), Nu >= 1, Ra = ra_const |Tw - T|/T (p/T)^2; fixed: Q = coeff (Tw - T); density:
 * Q = coeff (p/T)^n (Tw - T), n = ra_const (an hA that varies as the gas density to a
 * power n; coeff = hA_0 (T_0/p_0)^n [W/K / (Pa/K)^n], hA_0 at the density of p_0, T_0);
 * time: Q = coeff (Tw - T), coeff = hA at the opening (the right-hand side multiplies it by
 * heat_time_factor); none: 0. */
double pu_heat_flow(double mode, double coeff, double ra_const, double t_wall, double p,
                    double t_gas, double turb)
{
    if (mode == HEAT_NONE) return 0.0;
    double dt_w = t_wall - t_gas;
    if (mode == HEAT_FIXED || mode == HEAT_TIME) return coeff * dt_w;
    if (mode == HEAT_DENSITY) return coeff * pow(p / t_gas, ra_const) * dt_w;
    double ra = ra_const * fabs(dt_w) / t_gas * (p / t_gas) * (p / t_gas);
    double nu = ra < 1e9 ? 0.59 * pow(ra, 0.25) : turb * 0.10 * cbrt(ra);
    return coeff * (nu > 1.0 ? nu : 1.0) * dt_w;
}

/* The time law's factor on hA at t [s]: exp(g1 u + g2 u^2), u = ln(1 + s/t_ref) with s the
 * time since the opening (0 before it), t_ref the HEAT_TREF slot [s]; 1 for the other laws
 * (whose hA is a function of the state alone). The exponent is capped at 50 (hA e^50 times
 * the opening's: the exchange is then isothermal to the integrator). */
static double heat_time_factor(double t, const double *prm)
{
    if (prm[HEAT_MODE] != HEAT_TIME) return 1.0;
    double s = t - prm[T_OPEN];
    double u = s > 0.0 ? log1p(s / prm[HEAT_TREF]) : 0.0;
    double e = prm[HEAT_G1] * u + prm[HEAT_G2] * u * u;
    return exp(e < 50.0 ? e : 50.0);
}

/* Valve effective-area fraction a(t) [-]: a linear ramp of `ramp` s from t_open, shut
 * from t_close. */
double pu_opening(double t, double t_open, double ramp, double t_close)
{
    if (t < t_open || t >= t_close) return 0.0;
    if (ramp > 0.0 && t < t_open + ramp) return (t - t_open) / ramp;
    return 1.0;
}

/* Mass flow [kg/s] through the valve's branch from a node at p [Pa], T [K] to p_atm: the
 * component (C rho_n, b, m) and the downstream leaks in parallel with it (laminar
 * k_down (p - p_atm); orifice law C_leak rho_n, b_leak), all times the opening a [-]. */
static double valve_branch(double a, double p, double t_node, const double *prm)
{
    if (a <= 0.0) return 0.0;
    double p_atm = prm[P_ATM], r_lin = prm[R_LIN], sq_tn = prm[SQRT_TN];
    /* the component's term in the order of the original formula (bit-identical results
     * without leaks) */
    double g = a * prm[C_RHO] * p * sq_tn / sqrt(t_node)
               * component_phi(p_atm / p, prm, r_lin);
    if (prm[LEAK_DOWN] != 0.0) g += a * prm[LEAK_DOWN] * (p - p_atm);
    if (prm[OLEAK_DOWN_C_RHO] > 0.0)
        g += a * prm[OLEAK_DOWN_C_RHO] * p * sq_tn / sqrt(t_node)
             * pu_flow_phi(p_atm / p, prm[OLEAK_DOWN_B], LEAK_M_INDEX, 2.0, r_lin);
    return g;
}

/* Mass flow [kg/s] into the tank at p [Pa] through the component from the supply
 * (p_s, T_s: the CHARGE slots) upstream of it, times the opening a [-]: the ISO 6358 law
 * with p1 = p_s, T1 = T_s, r = p / p_s (negative beyond r = 1: the linear end's reverse
 * flow, a tank above its supply). */
static double supply_branch(double a, double p, const double *prm)
{
    if (a <= 0.0) return 0.0;
    double p_s = prm[P_SUPPLY];
    return a * prm[C_RHO] * p_s * prm[SQRT_TN] / sqrt(prm[T_SUPPLY])
           * component_phi(p / p_s, prm, prm[R_LIN]);
}

/* dy/dt of y = (p [Pa], T [K][, p_pipe [Pa]]) at t [s].
 * Flows out of the tank: the valve branch (through the pipe when there is one), the
 * upstream laminar leak LEAK (p - p_atm) and the upstream orifice-law leak (C_leak rho_n,
 * b_leak), both active whether the valve is open or not. A charge (CHARGE 1): the
 * component fills the tank from the supply instead, its inflow carrying the supply's
 * enthalpy c_p T_s (the leaks still go from the tank to p_atm; no pipe). */
void pu_rhs(double t, const double *y, const double *prm, double *dy)
{
    double p1 = y[0], t1 = y[1];
    double a = pu_opening(t, prm[T_OPEN], prm[RAMP], prm[T_CLOSE]);
    double p_atm = prm[P_ATM], t_wall = prm[T_WALL], sq_tn = prm[SQRT_TN];
    double r_lin = prm[R_LIN];
    double g1 = 0.0;
    if (prm[CHARGE] > 0.0) {
        double g_in = supply_branch(a, p1, prm);
        double g_leak = prm[LEAK] * (p1 - p_atm);
        if (prm[OLEAK_C_RHO] > 0.0)
            g_leak += prm[OLEAK_C_RHO] * p1 * sq_tn / sqrt(t1)
                      * pu_flow_phi(p_atm / p1, prm[OLEAK_B], LEAK_M_INDEX, 2.0, r_lin);
        double q = pu_heat_flow(prm[HEAT_MODE], prm[HEAT_A], prm[HEAT_RA], t_wall, p1, t1,
                                prm[HEAT_TURB]) * heat_time_factor(t, prm);
        /* forced convection by the incoming jet: hA = HEAT_JET |g_in|^0.67 [W/K] */
        if (prm[HEAT_JET] > 0.0 && g_in != 0.0)
            q += prm[HEAT_JET] * pow(fabs(g_in), JET_EXPONENT) * (t_wall - t1);
        double vol = prm[VOLUME];
        /* the inflow brings c_p T_s per kg (a reverse flow, g_in < 0, leaves at T) */
        double h_in = g_in >= 0.0 ? prm[T_SUPPLY] : t1;
        double dp = (prm[GAMMA] - 1.0) / vol
                    * (q + prm[CP] * (g_in * h_in - g_leak * t1));
        dy[0] = dp;
        dy[1] = t1 / p1 * dp - prm[R_GAS] * t1 * t1 / (p1 * vol) * (g_in - g_leak);
        return;
    }
    if (prm[PIPE] > 0.0) {
        double p2 = y[2];
        g1 = prm[PIPE_C_RHO] * p1 * sq_tn / sqrt(t1) * pu_flow_phi(p2 / p1, 0.5, 0.5, 2.0, r_lin);
        double g2 = valve_branch(a, p2, t_wall, prm);
        dy[2] = prm[R_GAS] * t_wall / prm[PIPE_VOLUME] * (g1 - g2);
    } else {
        g1 = valve_branch(a, p1, t1, prm);
    }
    double g_out = g1 + prm[LEAK] * (p1 - p_atm);
    if (prm[OLEAK_C_RHO] > 0.0)
        g_out += prm[OLEAK_C_RHO] * p1 * sq_tn / sqrt(t1)
                 * pu_flow_phi(p_atm / p1, prm[OLEAK_B], LEAK_M_INDEX, 2.0, r_lin);
    double q = pu_heat_flow(prm[HEAT_MODE], prm[HEAT_A], prm[HEAT_RA], t_wall, p1, t1,
                            prm[HEAT_TURB]) * heat_time_factor(t, prm);
    /* The gas leaving (or, for g < 0, entering) is taken at the tank gas temperature.
     * Reverse flow through the component happens in these models only as the numerical
     * overshoot of a discharge that ends on g = 0 (the valve closes before p_atm, heat
     * transfer keeps the flow outwards); a switch to the surroundings' temperature for
     * g < 0 put a kink exactly there, on which the stiff pipe model chattered (300 000
     * steps instead of 3 000). */
    double t_up = t1;
    double vol = prm[VOLUME];
    double dp1 = (prm[GAMMA] - 1.0) / vol * (q - g_out * prm[CP] * t_up);
    dy[0] = dp1;
    dy[1] = t1 / p1 * dp1 + prm[R_GAS] * t1 * t1 / (p1 * vol) * g_out;
}

static double error_norm(int n, const double *err, const double *y, const double *yn,
                         double rtol, const double *atol)
{
    double s = 0.0;
    for (int i = 0; i < n; i++) {
        double ay = fabs(y[i]), an = fabs(yn[i]);
        double sc = atol[i] + rtol * (ay > an ? ay : an);
        s += (err[i] / sc) * (err[i] / sc);
    }
    return sqrt(s / n);
}

/* LU decomposition with partial pivoting of the n x n matrix a (row major), in place. */
static int lu_factor(int n, double *a, int *piv)
{
    for (int k = 0; k < n; k++) {
        int p = k;
        for (int i = k + 1; i < n; i++)
            if (fabs(a[i * n + k]) > fabs(a[p * n + k])) p = i;
        piv[k] = p;
        if (a[p * n + k] == 0.0 || !isfinite(a[p * n + k])) return 1;
        if (p != k)
            for (int j = 0; j < n; j++) {
                double tmp = a[k * n + j];
                a[k * n + j] = a[p * n + j];
                a[p * n + j] = tmp;
            }
        for (int i = k + 1; i < n; i++) {
            double f = a[i * n + k] / a[k * n + k];
            a[i * n + k] = f;
            for (int j = k + 1; j < n; j++) a[i * n + j] -= f * a[k * n + j];
        }
    }
    return 0;
}

static void lu_solve(int n, const double *a, const int *piv, double *b)
{
    for (int k = 0; k < n; k++) {
        double tmp = b[piv[k]];
        b[piv[k]] = b[k];
        b[k] = tmp;
        for (int i = k + 1; i < n; i++) b[i] -= a[i * n + k] * b[k];
    }
    for (int k = n - 1; k >= 0; k--) {
        for (int j = k + 1; j < n; j++) b[k] -= a[k * n + j] * b[j];
        b[k] /= a[k * n + k];
    }
}

/* Returned by rosenbrock() (never by pu_dopri5) when its steps stay shorter than the
 * explicit method's stability-limited step: the explicit method is the cheaper one there. */
#define EXPLICIT_CHEAPER (-1)
/* Accepted Rosenbrock steps over which its mean step is compared with the explicit one. */
#define ROS_WINDOW 50
/* Accepted explicit steps after which the stiff method is tried again (a trial costs about
 * 2 ROS_WINDOW steps, so at most a tenth more steps where the explicit method wins). */
#define ROS_RETRY (20 * ROS_WINDOW)

/* Stiff continuation: the Rosenbrock 2(3) W-method of Shampine & Reichelt (1997, the
 * formula of MATLAB's ode23s) from (*t_io, y) to t1, with a finite-difference Jacobian and
 * time derivative at every step and its own continuous extension for the outputs from
 * index *j_io. Same arguments and return codes as pu_dopri5, and EXPLICIT_CHEAPER when
 * the mean accepted step over a window of ROS_WINDOW steps (after the first, the start-up
 * from the explicit step) is below h_explicit (the
 * stability-limited step of the explicit method when it switched): a second-order method
 * at a tight tolerance can need far shorter steps than a moderately stiff problem allows
 * the explicit one (a pipe 1e-3 of the tank: 290 000 steps against 6 000). Then t, y,
 * *j_io, *steps_io hold where it stopped and *h_mean its mean step. */
static int rosenbrock(int n, double *y, double *t_io, double t1, double h,
                      double h_explicit, int n_out, const double *t_out, int *j_io,
                      const double *prm, double rtol, const double *atol, double hmax,
                      long *steps_io, long max_steps, double *out, int *n_done,
                      double *h_mean)
{
    double t = *t_io;
    int j = *j_io;
    long steps = *steps_io;
    long accepted = 0;
    double t_window = t;
    const double d = 1.0 / (2.0 + sqrt(2.0)), e32 = 6.0 + sqrt(2.0);
    double f0[MAX_STATES], f1[MAX_STATES], f2[MAX_STATES], ft[MAX_STATES];
    double k1[MAX_STATES], k2[MAX_STATES], k3[MAX_STATES], yt[MAX_STATES];
    double yn[MAX_STATES], err[MAX_STATES], dfdt[MAX_STATES];
    double jac[MAX_STATES * MAX_STATES], w[MAX_STATES * MAX_STATES];
    int piv[MAX_STATES], i, c;
    double span = t1 - t;
    pu_rhs(t, y, prm, f0);
    while (t < t1) {
        if (steps >= max_steps) return TOO_MANY_STEPS;
        int last = (t + h >= t1) || (t1 - (t + h) < 1e-12 * span);
        if (last) h = t1 - t;
        if (h <= 1e-14 * fmax(fabs(t), span)) return STEP_TOO_SMALL;
        /* Jacobian and df/dt by forward differences */
        for (c = 0; c < n; c++) {
            double del = 1e-7 * fmax(fabs(y[c]), atol[c] / rtol);
            for (i = 0; i < n; i++) yt[i] = y[i];
            yt[c] += del;
            pu_rhs(t, yt, prm, ft);
            for (i = 0; i < n; i++) jac[i * n + c] = (ft[i] - f0[i]) / del;
        }
        double dt = 1e-7 * fmax(fabs(t), span);
        if (t + dt > t1) dt = -dt;  /* stay inside the smooth segment */
        pu_rhs(t + dt, y, prm, ft);
        for (i = 0; i < n; i++) dfdt[i] = (ft[i] - f0[i]) / dt;
        for (;;) {
            for (i = 0; i < n; i++)
                for (c = 0; c < n; c++)
                    w[i * n + c] = (i == c ? 1.0 : 0.0) - h * d * jac[i * n + c];
            if (lu_factor(n, w, piv)) {
                h *= 0.25;
                if (h <= 1e-14 * fmax(fabs(t), span)) return STEP_TOO_SMALL;
                last = 0;
                continue;
            }
            for (i = 0; i < n; i++) k1[i] = f0[i] + h * d * dfdt[i];
            lu_solve(n, w, piv, k1);
            for (i = 0; i < n; i++) yt[i] = y[i] + 0.5 * h * k1[i];
            pu_rhs(t + 0.5 * h, yt, prm, f1);
            for (i = 0; i < n; i++) k2[i] = f1[i] - k1[i];
            lu_solve(n, w, piv, k2);
            for (i = 0; i < n; i++) {
                k2[i] += k1[i];
                yn[i] = y[i] + h * k2[i];
            }
            double t_new = last ? t1 : t + h;
            pu_rhs(t_new, yn, prm, f2);
            for (i = 0; i < n; i++)
                k3[i] = f2[i] - e32 * (k2[i] - f1[i]) - 2.0 * (k1[i] - f0[i]) + h * d * dfdt[i];
            lu_solve(n, w, piv, k3);
            for (i = 0; i < n; i++) err[i] = h / 6.0 * (k1[i] - 2.0 * k2[i] + k3[i]);
            steps++;
            double e = error_norm(n, err, y, yn, rtol, atol);
            if (!isfinite(e) || e > 1.0) {
                h = grid_step(h * (isfinite(e) ? fmax(0.1, 0.8 * pow(e, -1.0 / 3.0)) : 0.1));
                last = (t + h >= t1);
                if (last) h = t1 - t;
                if (h <= 1e-14 * fmax(fabs(t), span)) return isfinite(e) ? STEP_TOO_SMALL
                                                                          : NOT_FINITE;
                if (steps >= max_steps) return TOO_MANY_STEPS;
                continue;
            }
            /* accepted: outputs in (t, t_new] from the method's interpolant */
            while (j < n_out && t_out[j] <= t_new) {
                double s = (t_out[j] - t) / h;
                double a1 = s * (1.0 - s) / (1.0 - 2.0 * d), a2 = s * (s - 2.0 * d) / (1.0 - 2.0 * d);
                for (i = 0; i < n; i++) out[j * n + i] = y[i] + h * (a1 * k1[i] + a2 * k2[i]);
                j++;
            }
            *n_done = j;
            t = t_new;
            for (i = 0; i < n; i++) {
                y[i] = yn[i];
                f0[i] = f2[i];
            }
            double fac = e == 0.0 ? 5.0 : fmin(5.0, 0.8 * pow(e, -1.0 / 3.0));
            h = grid_step(fmin(h * fac, hmax));
            if (++accepted % ROS_WINDOW == 0) {  /* the first window: its start-up */
                double mean = (t - t_window) / ROS_WINDOW;
                t_window = t;
                if (accepted > ROS_WINDOW && mean < h_explicit && t < t1) {
                    *t_io = t;
                    *j_io = j;
                    *steps_io = steps;
                    *h_mean = mean;
                    return EXPLICIT_CHEAPER;
                }
            }
            break;
        }
    }
    return OK;
}

/* Dormand-Prince 5(4) from (t0, y0) to t1 (> t0), the states at t_out[0..n_out) written
 * row by row into out (n_out x n). Returns the status; *n_done receives the rows written.
 * When the problem turns stiff (Hairer's test: h |lambda| > 3.25 on 15 accepted steps) the
 * segment is continued by the Rosenbrock method above, and handed back to this one where
 * the Rosenbrock steps turn out shorter than the explicit ones (EXPLICIT_CHEAPER); it
 * switches again when its own steps fall below half of those, or after ROS_RETRY steps
 * (the dynamics change along a discharge: the stiff method wins near its end). */
int pu_dopri5(int n, const double *y0, double t0, double t1, int n_out, const double *t_out,
              const double *prm, double rtol, const double *atol, double hmax,
              long max_steps, double *out, int *n_done)
{
    double k1[MAX_STATES], k2[MAX_STATES], k3[MAX_STATES], k4[MAX_STATES];
    double k5[MAX_STATES], k6[MAX_STATES], k7[MAX_STATES];
    double y[MAX_STATES], yt[MAX_STATES], yn[MAX_STATES], err[MAX_STATES];
    int j = 0, i;
    *n_done = 0;
    if (n < 1 || n > MAX_STATES) return NOT_FINITE;
    for (i = 0; i < n; i++) y[i] = y0[i];
    double t = t0;
    while (j < n_out && t_out[j] <= t0) {
        for (i = 0; i < n; i++) out[j * n + i] = y[i];
        j++;
    }
    *n_done = j;
    double span = t1 - t0;
    if (!(span > 0.0)) return OK;
    if (hmax <= 0.0) hmax = span;
    pu_rhs(t, y, prm, k1);
    /* initial step (Hairer, Norsett & Wanner, Solving ODE I, II.4) */
    double d0 = 0.0, d1 = 0.0, d2 = 0.0;
    for (i = 0; i < n; i++) {
        double sc = atol[i] + rtol * fabs(y[i]);
        d0 += (y[i] / sc) * (y[i] / sc);
        d1 += (k1[i] / sc) * (k1[i] / sc);
    }
    d0 = sqrt(d0 / n);
    d1 = sqrt(d1 / n);
    double h0 = (d0 < 1e-5 || d1 < 1e-5) ? 1e-6 * span : 0.01 * d0 / d1;
    if (h0 > span) h0 = span;
    for (i = 0; i < n; i++) yt[i] = y[i] + h0 * k1[i];
    pu_rhs(t + h0, yt, prm, k2);
    for (i = 0; i < n; i++) {
        double sc = atol[i] + rtol * fabs(y[i]);
        d2 += ((k2[i] - k1[i]) / sc) * ((k2[i] - k1[i]) / sc);
    }
    d2 = sqrt(d2 / n) / h0;
    double dmax = d1 > d2 ? d1 : d2;
    double h1 = dmax <= 1e-15 ? fmax(1e-6 * span, h0 * 1e-3) : pow(0.01 / dmax, 0.2);
    double h = fmin(fmin(100.0 * h0, h1), hmax);
    if (!(h > 0.0) || !isfinite(h)) return NOT_FINITE;
    h = grid_step(h);
    long steps = 0;
    int rejected = 0, n_stiff = 0, non_stiff = 0;
    double h_stiff = INFINITY;  /* mean step of the stiff method where it gave up [s] */
    long explicit_steps = 0;    /* accepted explicit steps since then */
    while (t < t1) {
        if (steps >= max_steps) return TOO_MANY_STEPS;
        int last = (t + h >= t1) || (t1 - (t + h) < 1e-12 * span);
        if (last) h = t1 - t;
        if (h <= 1e-14 * fmax(fabs(t), span)) return STEP_TOO_SMALL;
        for (i = 0; i < n; i++) yt[i] = y[i] + h * 0.2 * k1[i];
        pu_rhs(t + 0.2 * h, yt, prm, k2);
        for (i = 0; i < n; i++) yt[i] = y[i] + h * (3.0 / 40.0 * k1[i] + 9.0 / 40.0 * k2[i]);
        pu_rhs(t + 0.3 * h, yt, prm, k3);
        for (i = 0; i < n; i++)
            yt[i] = y[i] + h * (44.0 / 45.0 * k1[i] - 56.0 / 15.0 * k2[i] + 32.0 / 9.0 * k3[i]);
        pu_rhs(t + 0.8 * h, yt, prm, k4);
        for (i = 0; i < n; i++)
            yt[i] = y[i] + h * (19372.0 / 6561.0 * k1[i] - 25360.0 / 2187.0 * k2[i]
                                + 64448.0 / 6561.0 * k3[i] - 212.0 / 729.0 * k4[i]);
        pu_rhs(t + 8.0 / 9.0 * h, yt, prm, k5);
        for (i = 0; i < n; i++)
            yt[i] = y[i] + h * (9017.0 / 3168.0 * k1[i] - 355.0 / 33.0 * k2[i]
                                + 46732.0 / 5247.0 * k3[i] + 49.0 / 176.0 * k4[i]
                                - 5103.0 / 18656.0 * k5[i]);
        double t_new = last ? t1 : t + h;
        pu_rhs(t_new, yt, prm, k6);
        for (i = 0; i < n; i++)
            yn[i] = y[i] + h * (35.0 / 384.0 * k1[i] + 500.0 / 1113.0 * k3[i]
                                + 125.0 / 192.0 * k4[i] - 2187.0 / 6784.0 * k5[i]
                                + 11.0 / 84.0 * k6[i]);
        pu_rhs(t_new, yn, prm, k7);
        for (i = 0; i < n; i++)
            err[i] = h * (-71.0 / 57600.0 * k1[i] + 71.0 / 16695.0 * k3[i]
                          - 71.0 / 1920.0 * k4[i] + 17253.0 / 339200.0 * k5[i]
                          - 22.0 / 525.0 * k6[i] + 1.0 / 40.0 * k7[i]);
        steps++;
        double e = error_norm(n, err, y, yn, rtol, atol);
        if (!isfinite(e)) {
            if (h <= 1e-12 * span) return NOT_FINITE;
            h = grid_step(h * 0.1);
            rejected = 1;
            continue;
        }
        if (e > 1.0) {
            h = grid_step(h * fmax(0.2, 0.9 * pow(e, -0.2)));
            rejected = 1;
            continue;
        }
        /* accepted: the continuous extension for the outputs in (t, t_new]; its
         * coefficients once per step (the same expressions as per output: bit-identical) */
        if (j < n_out && t_out[j] <= t_new) {
            double r2[MAX_STATES], r3[MAX_STATES], r4[MAX_STATES], r5[MAX_STATES];
            for (i = 0; i < n; i++) {
                r2[i] = yn[i] - y[i];
                r3[i] = h * k1[i] - r2[i];
                r4[i] = r2[i] - h * k7[i] - r3[i];
                r5[i] = h * (-12715105075.0 / 11282082432.0 * k1[i]
                             + 87487479700.0 / 32700410799.0 * k3[i]
                             - 10690763975.0 / 1880347072.0 * k4[i]
                             + 701980252875.0 / 199316789632.0 * k5[i]
                             - 1453857185.0 / 822651844.0 * k6[i]
                             + 69997945.0 / 29380423.0 * k7[i]);
            }
            while (j < n_out && t_out[j] <= t_new) {
                double th = (t_out[j] - t) / h, th1 = 1.0 - th;
                for (i = 0; i < n; i++)
                    out[j * n + i] = y[i] + th * (r2[i] + th1 * (r3[i] + th * (r4[i]
                                                                 + th1 * r5[i])));
                j++;
            }
        }
        *n_done = j;
        explicit_steps++;
        /* stiffness test (Hairer & Wanner, dopri5): h |lambda| from the last two stages */
        double stnum = 0.0, stden = 0.0;
        for (i = 0; i < n; i++) {
            stnum += (k7[i] - k6[i]) * (k7[i] - k6[i]);
            stden += (yn[i] - yt[i]) * (yn[i] - yt[i]);
        }
        if (stden > 0.0 && h * sqrt(stnum / stden) > 3.25) {
            non_stiff = 0;
            /* switch when stiff, unless the stiff method was tried and its steps were
             * not much longer than the explicit ones are now */
            if (++n_stiff >= 15 && t_new < t1
                && (h < 0.5 * h_stiff || explicit_steps >= ROS_RETRY)) {
                for (i = 0; i < n; i++) y[i] = yn[i];
                t = t_new;
                int status = rosenbrock(n, y, &t, t1, h, h, n_out, t_out, &j, prm, rtol,
                                        atol, hmax, &steps, max_steps, out, n_done,
                                        &h_stiff);
                if (status != EXPLICIT_CHEAPER) return status;
                n_stiff = non_stiff = rejected = 0;
                explicit_steps = 0;
                pu_rhs(t, y, prm, k1);
                continue;  /* on with the explicit method from where it stopped */
            }
        } else if (++non_stiff >= 6) {
            n_stiff = 0;
        }
        t = t_new;
        for (i = 0; i < n; i++) {
            y[i] = yn[i];
            k1[i] = k7[i];
        }
        double fac = e == 0.0 ? 10.0 : fmin(10.0, fmax(0.2, 0.9 * pow(e, -0.2)));
        if (rejected) {
            fac = fmin(fac, 1.0);
            rejected = 0;
        }
        h = grid_step(fmin(h * fac, hmax));
    }
    return OK;
}

/* The discharge from (t_out[0], y0) over the smooth segments between bounds[0..n_bounds)
 * (bounds[0] = t_out[0], bounds[n_bounds-1] = t_out[n_out-1], the valve events between),
 * the states at t_out written row by row into out (n_out x n). In each segment: the state
 * stays where it is when the valve is still shut and the gas at rest (dy = 0 at the
 * start); otherwise pu_dopri5 to the segment's end, its step limited to hmax_ramp inside
 * the opening ramp [t_open, t_open + ramp) (0: no limit). *n_done receives the rows
 * written; on a failure *fail_segment the segment and y_fail its starting state.
 * Returns the status of pu_dopri5. */
int pu_integrate(int n, const double *y0, int n_bounds, const double *bounds, int n_out,
                 const double *t_out, const double *prm, double rtol, const double *atol,
                 double t_open, double ramp, long max_steps, double *out, int *n_done,
                 int *fail_segment, double *y_fail)
{
    double y[MAX_STATES], dy[MAX_STATES];
    int i, k = 0, s;
    *n_done = 0;
    *fail_segment = -1;
    if (n < 1 || n > MAX_STATES || n_out < 1 || n_bounds < 2) return NOT_FINITE;
    for (i = 0; i < n; i++) y[i] = y0[i];
    for (s = 0; s < n_bounds - 1; s++) {
        double a = bounds[s], b = bounds[s + 1];
        int last = s == n_bounds - 2;
        int j = k;  /* end of the rows of this segment: first t_out >= b (all when last) */
        if (last) j = n_out;
        else while (j < n_out && t_out[j] < b) j++;
        int rows = j - k + (last ? 0 : 1);  /* plus the state at b */
        pu_rhs(a, y, prm, dy);
        int rest = 0;
        if (b <= t_open) {
            rest = 1;
            for (i = 0; i < n; i++) if (dy[i] != 0.0) rest = 0;
        }
        if (rest || !(b > a)) {
            for (int r = k; r < j; r++)
                for (i = 0; i < n; i++) out[r * n + i] = y[i];
            k = j;
            *n_done = k;
            continue;
        }
        /* the segment's grid: its rows of t_out, then b (the state carried on) */
        double tg_stack[256], og_stack[256 * MAX_STATES];
        double *tg = tg_stack, *og = og_stack;
        double *heap = NULL;
        if (rows > 256) {
            heap = (double *)malloc(sizeof(double) * (size_t)rows * (size_t)(n + 1));
            if (!heap) return NOT_FINITE;
            tg = heap;
            og = heap + rows;
        }
        for (int r = 0; r < j - k; r++) tg[r] = t_out[k + r];
        if (!last) tg[rows - 1] = b;
        double hmax = (ramp > 0.0 && t_open <= a && a < t_open + ramp) ? ramp / 4.0 : 0.0;
        int done = 0;
        int status = pu_dopri5(n, y, a, b, rows, tg, prm, rtol, atol, hmax, max_steps, og,
                               &done);
        int keep = done < j - k ? done : j - k;
        for (int r = 0; r < keep; r++)
            for (i = 0; i < n; i++) out[(k + r) * n + i] = og[r * n + i];
        if (status != OK) {
            *n_done = k + keep;
            *fail_segment = s;
            for (i = 0; i < n; i++) y_fail[i] = y[i];
            free(heap);
            return status;
        }
        if (rows > 0)
            for (i = 0; i < n; i++) y[i] = og[(rows - 1) * n + i];
        free(heap);
        k = j;
        *n_done = k;
    }
    return OK;
}

/* Exact first-order lag y' = (u - y)/tau of the piecewise-linear interpolant of u on any
 * increasing grid t[0..n-1] [s] (tau > 0 [s]), from the previous sample (t_prev, u_prev,
 * y_prev); steady != 0 starts in steady state at the first sample (y = u there). A
 * zero-length step keeps y. Written into y[0..n-1] (unit of u). */
void pu_lag(int n, const double *t, const double *u, double tau, double t_prev,
            double u_prev, double y_prev, int steady, double *y)
{
    double yp = y_prev, up = u_prev, tp = t_prev;
    for (int i = 0; i < n; i++) {
        double h = t[i] - tp;
        if (h <= 0.0) {
            if (i == 0 && steady) yp = u[i];
        } else {
            double a = exp(-h / tau);
            double k = tau / h * (1.0 - a);
            yp = a * yp + (1.0 - k) * u[i] + (k - a) * up;
        }
        y[i] = yp;
        up = u[i];
        tp = t[i];
    }
}

/* The hash of this source, compiled in by setup.py (PU_SOURCE_SHA): the Python side
   loads the library built with the package only when it was built from this text. */
#ifdef PU_SOURCE_SHA
const char *pu_source_sha(void) { return PU_SOURCE_SHA; }
#endif
