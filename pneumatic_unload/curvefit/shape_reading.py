"""The flow curve's shape beyond the ISO 6358-1 law: a reading of the record, and the
ISO (b, m) nearest it.

A component's flow curve need not be ISO-shaped. Two restrictions in series (as ISO
6358-3:2014 computes a system) depart from the nearest ISO 6358-1 curve by a median 0.15 %
of the flow (rms over 74 foreign pairs, bench/bench_random_draws.py); that is within the
record's noise over most of a discharge, but the ISO b and m of such a curve depend on how
its points are weighted. A discharge weights the pressure ratios by the time it spends at
them, and a heat law takes up part of the rest (a pair whose ISO b over a uniform grid of r
is 0.210 read 0.347 with the truth's own heat law and m free). ISO 6358-1's test and ISO
6358-3 fit the law to the flow curve over its pressure ratios instead.

:func:`read_shape` fits the chosen heat law once more with m and the ellipse's exponent q
free (phi = (1 - x^q)^m, x = (r - b)/(1 - b); q = 2 is the ISO law), from the fit with m
free, and reduces that flow curve to the ISO law by least squares over a uniform grid of
r (:data:`REDUCTION_GRID`, :func:`iso_reduction`). The reduced (b, m), their covariance
carried through the reduction's Jacobian, and the fit's chi^2 are a reading of the record
that the model-form spread of C, b and m counts by the information criterion, as it counts
the heat laws (:func:`pneumatic_unload.curvefit.fitting.fit_curve`). Where the q-free fit
is clearly better than every other fit and reading (:func:`shape_wins`: by the criterion's
threshold, the rule the heat laws use), its reduced b and m are the ones reported. Either
way the spread is taken about the discharge's own ISO fit: the distance the reduction
moved b and m is their model-form line (q is one shape among many; a pair in series whose
curve leaves choking gradually is not followed by it: draw 182 of the foreign draws reads
q 2.04 +- 0.10 and b 0.282 for 0.210, a record that does not tell these curves apart).
Made for the pressure alone (not where a logged temperature is fitted).

SI units: s, Pa absolute; b, m and q are dimensionless.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.curvefit.law_family import LAW_BIC_THRESHOLD, Family, Fit
from pneumatic_unload.curvefit.subsonic_offer import M_SUFFIX
from pneumatic_unload.fit.lsq import minimize
from pneumatic_unload.fit.params import Parameter, Parameters
from pneumatic_unload.model.parametric import ISO_ELLIPSE_EXPONENT
from pneumatic_unload.physics import R_LINEAR, flow_function

FloatArray = NDArray[np.float64]

#: Key prefix of the shape's reading in the model-form pool (its key ends with M_SUFFIX:
#: it carries an m).
SHAPE_READING = "flow-curve shape: "
#: The pressure ratios over which a flow curve is reduced to the ISO 6358-1 law: uniform
#: from 0 to the linear end r_l [-] (as ISO 6358-3 fits a system's computed curve; the
#: linear end is the law's own, not a shape).
REDUCTION_GRID = np.linspace(0.0, R_LINEAR, 1000)
#: The flow function's resolution the reduction's residuals are scaled by [-] (the
#: engine stops at a thousandth of a residual variance: b and m to ~1e-9).
PHI_RESOLUTION = 1e-7
#: The shape's reading is reported (:func:`shape_wins`) only where the record determines q
#: within this 1-sigma [-] (the pairs in series it settles read q within 0.01-0.05; a
#: 5 Hz record with 30 kPa of noise and a leak read q 1.57 +- 2.29 and took the leak up as
#: b 0 and m 0.87 +- 0.82, clearly better by the criterion all the same).
ELLIPSE_EXPONENT_MAX_SD = 0.3
#: Evaluation budget of the q-free fit from the m-free one [-].
SHAPE_NFEV = 60
#: Relative step of the reduction's Jacobian (central differences) [-].
JACOBIAN_STEP = 1e-4


def iso_reduction(b: float, m: float, q: float) -> tuple[float, float]:
    """The ISO 6358-1 (b, m) nearest the flow curve of (b, m, q) [-]: least squares on phi
    over :data:`REDUCTION_GRID` through the package's engine (the curve itself where
    q = 2)."""
    if q == ISO_ELLIPSE_EXPONENT:
        return b, m
    target = flow_function(REDUCTION_GRID, b, m, ellipse_exponent=q)
    params = Parameters([
        Parameter("b", min(max(b, 0.0), 0.95), 0.0, 0.99, "-", scale=0.1,
                  doc="critical pressure ratio"),
        Parameter("m", min(max(m, 0.1), 1.0), 0.05, 3.0, "-", scale=0.1,
                  doc="subsonic index")])
    got = minimize(lambda v: (flow_function(REDUCTION_GRID, v["b"], v["m"]) - target)
                   / PHI_RESOLUTION, params, max_nfev=200)
    return float(got.values["b"]), float(got.values["m"])


def reduction_covariance(b: float, m: float, q: float, cov: FloatArray) -> FloatArray:
    """The 2x2 covariance of :func:`iso_reduction`'s (b, m) [-] from ``cov``, that of the
    fit's (b, m, q) [-], through the reduction's Jacobian (central differences)."""
    x0 = np.array([b, m, q])
    jac = np.zeros((2, 3))
    for i in range(3):
        h = JACOBIAN_STEP * max(abs(x0[i]), 0.1)
        up, dn = x0.copy(), x0.copy()
        up[i] += h
        dn[i] -= h
        jac[:, i] = (np.array(iso_reduction(*up)) - np.array(iso_reduction(*dn))) / (2 * h)
    return jac @ cov @ jac.T


def physical_covariance(kept: dict[str, Any], names: tuple[str, ...]) -> FloatArray | None:
    """The covariance of the fitted values ``names`` [their units] from a fit's kept
    FitResult ('result') and covariance scale ('s2'); None where not finite."""
    res = kept["result"]
    free = list(res.params.free)
    if any(n not in free for n in names):
        return None
    cov = np.asarray(res.covariance(kept["s2"]), dtype=float)
    idx = [free.index(n) for n in names]
    d = np.array([res.params.value_std(n, res.values[n], 1.0) for n in names])
    out = cov[np.ix_(idx, idx)] * np.outer(d, d)
    return out if np.all(np.isfinite(out)) else None


def read_shape(fam: Family, best: str) -> tuple[dict[str, Fit], str]:
    """The flow-curve shape's reading of the chosen fit ``best`` (see the module note):
    ({key: (CurveFit with the reduced b, m and their 1-sigma, chi^2 [Pa^2], free
    parameters)}, in words), or ({}, why not: the record does not determine m, the fit
    failed)."""
    law_key = best if best.endswith(M_SUFFIX) else best + M_SUFFIX
    source = fam.raw.get(law_key, {}).get("fit")
    if source is None or not math.isfinite(source.subsonic_index_std):
        return {}, "not read: no fit with m free to start from"
    kept: dict[str, Any] = {}
    try:
        cf, chi2, k = fam.fit(law_key, start={**fam.start_of(source), "q": ISO_ELLIPSE_EXPONENT},
                              max_nfev=SHAPE_NFEV, fit_q=True, keep=kept)
    except (ValueError, FloatingPointError, np.linalg.LinAlgError) as exc:
        return {}, f"not read: the fit with q free failed ({exc})"
    v = kept["result"].values
    b, m, q = float(v["b"]), float(v["m"]), float(v["q"])
    cov = physical_covariance(kept, ("b", "m", "q"))
    if cov is None or not math.isfinite(cf.conductance):
        return {}, "not read: the fit with q free did not determine b, m and q"
    b_r, m_r = iso_reduction(b, m, q)
    cov_r = reduction_covariance(b, m, q, cov)
    sb, sm = (math.sqrt(max(float(cov_r[i, i]), 0.0)) for i in range(2))
    reading = dataclasses.replace(cf, critical_ratio=b_r, critical_ratio_std=sb,
                                  subsonic_index=m_r, subsonic_index_std=sm,
                                  subsonic_index_fitted=True)
    why = (f"q {q:.2f} +- {cf.ellipse_exponent_std:.2f} (b {b:.3f}, m {m:.3f}): the ISO "
           f"6358-1 law nearest that curve over r in [0, {R_LINEAR:g}] has b {b_r:.3f} "
           f"+- {sb:.3f}, m {m_r:.3f} +- {sm:.3f}, C {cf.conductance:.4g}")
    return {SHAPE_READING + law_key: (reading, chi2, k)}, why


def shape_wins(shape: dict[str, Fit], bic: dict[str, float]) -> str | None:
    """The key of the shape's reading where the record determines q (within
    :data:`ELLIPSE_EXPONENT_MAX_SD`) and the criterion (``bic`` [-] of every fit and
    reading) clearly prefers it to each of the others (by :data:`LAW_BIC_THRESHOLD`, the
    heat laws' rule): its ISO (b, m) are then reported; else None. (A gas 3 K warm and a
    -0.5 kPa zero: the shape's reading 51 better than the chosen law, an unclaimed warm
    gas's 59, with the truth's m where the shape read it 0.023 low.)"""
    key = next(iter(shape), None)
    if key is None or not shape[key][0].ellipse_exponent_std <= ELLIPSE_EXPONENT_MAX_SD:
        return None
    others = [v for k, v in bic.items() if k != key]
    return key if not others or bic[key] < min(others) - LAW_BIC_THRESHOLD else None
