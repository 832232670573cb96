/* SPDX-License-Identifier: Apache-2.0
 * Copyright 2026 pneumatic_unload maintainers
 */
/* The p* crossing fit of the streaming estimator and its block intake, compiled (issue #10:
 * the crossing estimate published within a millisecond of the sample that completes it).
 *
 * The one implementation of the crossing regression: regression.py's crossing_fit and the
 * estimator's crossing window (unloading.complete_crossing) call these functions through
 * ctypes; every path (per sample, block, batch, live) runs the same arithmetic, so their
 * results stay bit-identical. The block intake (pu_block_steps, pu_append, pu_first_below:
 * a live block's checks, prefix sums and level trigger in three calls instead of some thirty
 * numpy calls, each of which pays for cold caches after the idle wait between blocks) does
 * the additions of the per-sample path in its order, one at a time (no FMA contraction: the
 * kernel is built with -std=c99, whose default is -ffp-contract=off).
 *
 * Units: times in s, pressures in Pa (or the input's signal units: the fit is linear in p).
 */
#include <math.h>

/* 3x3 linear system by Cramer's rule (regression.solve3): 0 when singular. */
static int solve3(const double m[3][3], const double r[3], double x[3])
{
    double a = m[0][0], b = m[0][1], c = m[0][2];
    double d = m[1][0], e = m[1][1], f = m[1][2];
    double g = m[2][0], h = m[2][1], k = m[2][2];
    double c1 = e * k - f * h, c2 = f * g - d * k, c3 = d * h - e * g;
    double det = a * c1 + b * c2 + c * c3;
    if (det == 0.0 || !isfinite(det))
        return 0;
    x[0] = (r[0] * c1 + b * (f * r[2] - r[1] * k) + c * (r[1] * h - e * r[2])) / det;
    x[1] = (a * (r[1] * k - f * r[2]) + r[0] * c2 + c * (d * r[2] - r[1] * g)) / det;
    x[2] = (a * (e * r[2] - r[1] * h) + b * (r[1] * g - d * r[2]) + r[0] * c3) / det;
    return 1;
}

static void no_crossing(double *out)
{
    out[0] = NAN;
    out[1] = INFINITY;
    out[2] = 0.0;
}

/* Sub-sample instant at which a local quadratic regression of p(t) crosses `level`.
 * n samples t [s], p [Pa]; out: crossing time [s], its standard deviation [s], the slope
 * at the crossing [Pa/s]; (NaN, inf, 0) when the fit is flat or degenerate. The quadratic
 * is fitted in the centred, scaled time u = (t - tm)/w and the centred pressure (well
 * conditioned normal equations); its standard deviation by the delta method. */
void pu_crossing_fit(long n, const double *t, const double *p, double level, double *out)
{
    if (n <= 0) {
        no_crossing(out);
        return;
    }
    double st = 0.0, sp = 0.0;
    for (long i = 0; i < n; i++) {
        st += t[i];
        sp += p[i];
    }
    double tm = st / (double)n, p_ref = sp / (double)n;
    double t_first = t[0], t_last = t[n - 1], w;
    if (t_last >= t_first) {
        double lo = tm - t_first, hi = t_last - tm;
        w = hi > lo ? hi : lo;
    } else { /* unsorted stamps: the largest distance from the centre */
        w = 0.0;
        for (long i = 0; i < n; i++) {
            double d = fabs(t[i] - tm);
            if (d > w || isnan(d))
                w = d;
        }
    }
    double atm = fabs(tm);
    if (!(w > 1e-12 * (atm > 1.0 ? atm : 1.0) && isfinite(w) && isfinite(p_ref))) {
        no_crossing(out); /* a window of no duration: no slope, no crossing */
        return;
    }
    double s1 = 0.0, s2 = 0.0, s3 = 0.0, s4 = 0.0, b0 = 0.0, b1 = 0.0, b2 = 0.0;
    for (long i = 0; i < n; i++) {
        double u = (t[i] - tm) / w, u2 = u * u, q = p[i] - p_ref;
        s1 += u;
        s2 += u2;
        s3 += u2 * u;
        s4 += u2 * u2;
        b0 += q;
        b1 += u * q;
        b2 += u2 * q;
    }
    const double m[3][3] = {{(double)n, s1, s2}, {s1, s2, s3}, {s2, s3, s4}};
    const double b[3] = {b0, b1, b2};
    double sol[3];
    if (!solve3(m, b, sol)) { /* fewer than three distinct instants */
        no_crossing(out);
        return;
    }
    double rr = 0.0;
    for (long i = 0; i < n; i++) {
        double u = (t[i] - tm) / w;
        double r = (p[i] - p_ref) - (sol[0] + sol[1] * u + sol[2] * u * u);
        rr += r * r;
    }
    double s2res = rr / (double)(n > 4 ? n - 3 : 1);
    double x_first = t_first - tm, x_last = t_last - tm, span = x_last - x_first;
    double c0 = sol[0] + p_ref, c1 = sol[1] / w, c2 = sol[2] / (w * w), xr;
    if (c1 == 0.0 && c2 == 0.0) { /* flat (stuck or degenerate samples) */
        no_crossing(out);
        return;
    }
    if (fabs(c2) < 1e-30 || fabs(c2 * span * span) < 1e-12 * fabs(c1 * span)) {
        xr = c1 != 0.0 ? (level - c0) / c1 : NAN;
    } else {
        double disc = c1 * c1 - 4.0 * c2 * (c0 - level);
        if (disc < 0.0) {
            xr = c1 != 0.0 ? (level - c0) / c1 : NAN;
        } else { /* the root nearest the window centre */
            double sq = sqrt(disc);
            double r1 = (-c1 + sq) / (2.0 * c2), r2 = (-c1 - sq) / (2.0 * c2);
            xr = fabs(r1) < fabs(r2) ? r1 : r2;
        }
    }
    double slope = c1 + 2.0 * c2 * xr;
    double ur = xr / w;
    const double g[3] = {1.0, ur, ur * ur};
    double mg[3], var_f = INFINITY;
    if (solve3(m, g, mg))
        var_f = s2res * (g[0] * mg[0] + g[1] * mg[1] + g[2] * mg[2]);
    double v = 0.0 > var_f ? 0.0 : var_f; /* NaN stays NaN */
    out[0] = tm + xr;
    out[1] = slope != 0.0 ? sqrt(v) / fabs(slope) : INFINITY;
    out[2] = slope;
}

/* First index in [0, n) whose stamp is >= x (numpy's searchsorted, side 'left'). */
static long search_left(const double *t, long n, double x)
{
    long a = 0, b = n;
    while (a < b) {
        long mid = a + (b - a) / 2;
        if (t[mid] < x)
            a = mid + 1;
        else
            b = mid;
    }
    return a;
}

/* The estimator's crossing window, closed at index n - 1 (the first sample below
 * p* - half). Its first window starts after the last sample above `upper` (p* + half) in
 * [i0, n) (at i0 when there is none); when that leaves fewer than 5 samples, at `fallback`
 * (a slice start: negative counts back from n). The fit on that window, then again on a
 * window symmetric in time about its estimate (the ends of the first were chosen by noisy
 * sample values), and whether a stamp step of the first window exceeds `gap_limit` [s].
 * tv, pv: the buffer's stamps [s] and samples from index 0 (at least n of them).
 * out: crossing time [s], its standard deviation [s], slope [Pa/s], gap (0 or 1), the
 * first window's start [-]. */
void pu_crossing_window(const double *tv, const double *pv, long i0, long n, double upper,
                        long fallback, double level, double gap_limit, double *out)
{
    long lo = i0;
    for (long k = n - 1; k >= i0; k--)
        if (pv[k] > upper) {
            lo = k;
            break;
        }
    if (n - lo < 5) {
        lo = fallback > n - 5 ? fallback : n - 5;
        if (lo < 0)
            lo = lo + n > 0 ? lo + n : 0;
    }
    pu_crossing_fit(n - lo, tv + lo, pv + lo, level, out);
    double h = tv[n - 1] - out[0];
    if (h > 0.0) {
        long k0 = search_left(tv, n, out[0] - h);
        if (n - k0 >= 5)
            pu_crossing_fit(n - k0, tv + k0, pv + k0, level, out);
    }
    double gap = 0.0;
    for (long k = lo + 1; k < n; k++)
        if (tv[k] - tv[k - 1] > gap_limit) {
            gap = 1.0;
            break;
        }
    out[3] = gap;
    out[4] = (double)lo;
}

/* The checks of a block of n samples (stamps t [s], values p) taken after the stamp
 * last_t [s]: out[0] the shortest stamp step t[k] - t[k-1] (t[-1] = last_t) and out[1] the
 * longest (both NaN when a step is NaN, as numpy's min and max), out[2] 1 when every value
 * is finite (else 0), out[3] the larger of |t[0]| and |t[n-1]| [s]. n >= 1. */
void pu_block_steps(const double *t, const double *p, long n, double last_t, double *out)
{
    double lo = INFINITY, hi = -INFINITY, prev = last_t;
    int nan = 0, finite = 1;
    for (long k = 0; k < n; k++) {
        double d = t[k] - prev;
        prev = t[k];
        if (isnan(d)) {
            nan = 1;
        } else {
            if (d < lo)
                lo = d;
            if (d > hi)
                hi = d;
        }
        if (!isfinite(p[k]))
            finite = 0;
    }
    double a = fabs(t[0]), b = fabs(t[n - 1]);
    out[0] = nan ? NAN : lo;
    out[1] = nan ? NAN : hi;
    out[2] = finite ? 1.0 : 0.0;
    out[3] = a > b || isnan(a) ? a : b;
}

/* A block of n samples appended to the estimator's buffer (buffer.SampleBuffer.extend):
 * the stamps t [s] and values p copied to t_out and p_out; the prefix sums of the values
 * and of their squared first differences continued from cs_out[0] and cq_out[0] (the last
 * sums held) into cs_out[1..n] and cq_out[1..n], the first difference taken from prev (the
 * last value held, or p[0]); each sum one addition at a time in sample order, as the
 * per-sample append and numpy's cumsum make them. */
void pu_append(const double *t, const double *p, long n, double prev, double *t_out,
               double *p_out, double *cs_out, double *cq_out)
{
    double s = cs_out[0], q = cq_out[0];
    for (long k = 0; k < n; k++) {
        double v = p[k], d = v - prev;
        double dd = d * d;
        prev = v;
        q = q + dd;
        s = s + v;
        t_out[k] = t[k];
        p_out[k] = v;
        cs_out[k + 1] = s;
        cq_out[k + 1] = q;
    }
}

/* First index in [i, hi) whose value p[k] is below level, or hi (decisions.first_below:
 * a NaN is never below). */
long pu_first_below(const double *p, long i, long hi, double level)
{
    for (long k = i; k < hi; k++)
        if (p[k] < level)
            return k;
    return hi;
}

/* The hash of this source, compiled in by setup.py (PU_SOURCE_SHA): the Python side
   loads the library built with the package only when it was built from this text. */
#ifdef PU_SOURCE_SHA
const char *pu_source_sha(void) { return PU_SOURCE_SHA; }
#endif
