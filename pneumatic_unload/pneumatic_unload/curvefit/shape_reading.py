# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
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

:func:`read_shape` fits a heat law once more with m free and a shape beyond the ISO law's,
from its fit with m free: the ellipse's exponent q (phi = (1 - x^q)^m, x = (r - b)/(1 - b);
q = 2 is the ISO law), or the component as two ISO elements in series (ISO 6358-3: one mass
flow, the downstream element's b2, m2 and C2/C1 fitted; the kernel's ``pu_series_phi``).
It reduces that flow curve to the ISO law by least squares over a uniform grid of r
(:data:`REDUCTION_GRID`, :func:`iso_reduction`). The reduced (b, m), their covariance
carried through the reduction's Jacobian, and the fit's chi^2 are a reading of the record
that the model-form spread of C, b and m counts by the information criterion, as it counts
the heat laws (:func:`pneumatic_unload.curvefit.fitting.fit_curve`), with the reading's own
variance (a shape the record determines loosely widens the spread). :func:`read_shapes`
reads both shapes for every heat law fitted with m free: a heat law takes up part of a
shape, so the shape read with the chosen law alone can be the wrong one (foreign draw 111,
a pair cooled by a constant hA: the chosen law, natural convection's turbulent branch
free, read b 0.026 +- 0.007 for 0.357 and its own pair reading b 0.037; the pair read
with the density law fits 35 better by the criterion and reads b 0.294 +- 0.052, with
the truth's own law 0.356). Where the best reading that the record determines
(:func:`settles`) is clearly better than every fit (:func:`shape_wins`: by the criterion's
threshold, the rule the heat laws use), its reduced b and m are the ones reported. Either
way the spread is taken about the discharge's own ISO fit: the distance the reduction
moved b and m is their model-form line. Not every pair is resolved: draw 182 of the
foreign draws (a pair cooled by a constant hA) is fitted 3 chi^2 units better by the ISO
law with the natural-convection law's turbulent branch free (b 0.284 for 0.210) than by
the pair with the truth's own heat law started at the truth's values: a record that does
not tell these curves apart. Made for the pressure alone (not where a logged
temperature is fitted).

SI units: s, Pa absolute; b, m, q, b2, m2 and C2/C1 are dimensionless.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.curvefit.curve_fit_result import CurveFit
from pneumatic_unload.curvefit.law_family import LAW_BIC_THRESHOLD, Family, Fit
from pneumatic_unload.curvefit.subsonic_offer import M_SUFFIX
from pneumatic_unload.fit.lsq import minimize
from pneumatic_unload.fit.params import Parameter, Parameters
from pneumatic_unload.model.kernel import component_phi
from pneumatic_unload.model.parametric import ISO_ELLIPSE_EXPONENT, SUBSONIC_INDEX_START
from pneumatic_unload.physics import R_LINEAR, flow_function

FloatArray = NDArray[np.float64]

#: Key prefix of each shape's reading in the model-form pool (the key ends with M_SUFFIX:
#: it carries an m).
SHAPE_READING = {"q": "flow-curve shape: ", "series": "flow-curve pair: "}
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
#: A pair fit's start: its downstream element's b, m and C2/C1 [-] (a second element
#: three times as wide as the first: a curve near the first's alone).
SERIES_START_B, SERIES_START_RATIO = 0.3, 3.0
#: A pair's reading is reported only where it determines the reduced b and m within
#: this 1-sigma [-].
SERIES_MAX_SD = 0.05
#: Evaluation budget of the q-free fit from the m-free one [-].
SHAPE_NFEV = 60
#: Relative step of the reduction's Jacobian (central differences) [-].
JACOBIAN_STEP = 1e-4


#: The parameters of each shape beyond the ISO law's (b, m) [-] (law_fit's ``shape``).
SHAPE_PARAMETERS: dict[str, tuple[str, ...]] = {"q": ("q",), "series": ("b2", "m2", "kappa")}


def shape_curve(values: dict[str, float], shape: str) -> FloatArray:
    """phi [-] over :data:`REDUCTION_GRID` of a fit's (b, m) and its shape's parameters
    (:data:`SHAPE_PARAMETERS`), through the kernel's flow function (the model's own)."""
    if shape == "series":
        return component_phi(REDUCTION_GRID, values["b"], values["m"], R_LINEAR,
                             series=(values["b2"], values["m2"], values["kappa"]))
    return component_phi(REDUCTION_GRID, values["b"], values["m"], R_LINEAR,
                         q=values.get("q", ISO_ELLIPSE_EXPONENT))


def iso_reduction(values: dict[str, float], shape: str) -> tuple[float, float]:
    """The ISO 6358-1 (b, m) nearest the flow curve of ``values`` (:func:`shape_curve`)
    [-]: least squares on phi over :data:`REDUCTION_GRID` through the package's engine
    (the curve's own where it is ISO's)."""
    if shape == "q" and values["q"] == ISO_ELLIPSE_EXPONENT:
        return values["b"], values["m"]
    target = shape_curve(values, shape)
    params = Parameters([
        Parameter("b", min(max(values["b"], 0.0), 0.95), 0.0, 0.99, "-", scale=0.1,
                  doc="critical pressure ratio"),
        Parameter("m", min(max(values["m"], 0.1), 1.0), 0.05, 3.0, "-", scale=0.1,
                  doc="subsonic index")])
    got = minimize(lambda v: (flow_function(REDUCTION_GRID, v["b"], v["m"]) - target)
                   / PHI_RESOLUTION, params, max_nfev=200)
    return float(got.values["b"]), float(got.values["m"])


def reduction_covariance(values: dict[str, float], shape: str,
                         cov: FloatArray) -> FloatArray:
    """The 2x2 covariance of :func:`iso_reduction`'s (b, m) [-] from ``cov``, that of the
    fit's (b, m, then the shape's parameters) [-], through the reduction's Jacobian
    (central differences)."""
    names = ("b", "m", *SHAPE_PARAMETERS[shape])
    jac = np.zeros((2, len(names)))
    for i, name in enumerate(names):
        h = JACOBIAN_STEP * max(abs(values[name]), 0.1)
        up, dn = {**values, name: values[name] + h}, {**values, name: values[name] - h}
        jac[:, i] = (np.array(iso_reduction(up, shape))
                     - np.array(iso_reduction(dn, shape))) / (2 * h)
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


def shape_start(shape: str) -> dict[str, float]:
    """The shape's parameters' start [-], beside the m-free fit's values: q at ISO's 2; a
    pair whose downstream element is :data:`SERIES_START_RATIO` times as wide as the
    fitted one (b 0.3, m 0.5), so that its curve starts near the fitted ISO curve."""
    if shape == "q":
        return {"q": ISO_ELLIPSE_EXPONENT}
    return {"b2": SERIES_START_B, "m2": SUBSONIC_INDEX_START, "kappa": SERIES_START_RATIO}


def read_shape(fam: Family, best: str, shape: str = "q") -> tuple[dict[str, Fit], str]:
    """The flow-curve ``shape``'s reading ('q' or 'series') of the chosen fit ``best`` (see
    the module note): ({key: (CurveFit with the reduced b, m and their 1-sigma, chi^2
    [Pa^2], free parameters)}, in words), or ({}, why not: the record does not determine
    m, the fit failed)."""
    law_key = best if best.endswith(M_SUFFIX) else best + M_SUFFIX
    source = fam.raw.get(law_key, {}).get("fit")
    if source is None or not math.isfinite(source.subsonic_index_std):
        return {}, "not read: no fit with m free to start from"
    kept: dict[str, Any] = {}
    try:
        cf, chi2, k = fam.fit(law_key, start={**fam.start_of(source),
                                              **shape_start(shape)},
                              max_nfev=SHAPE_NFEV, shape=shape, keep=kept)
    except (ValueError, FloatingPointError, np.linalg.LinAlgError) as exc:
        return {}, f"not read: the fit with the {shape} shape failed ({exc})"
    names = ("b", "m", *SHAPE_PARAMETERS[shape])
    values = {n: float(kept["result"].values[n]) for n in names}
    cov = physical_covariance(kept, names)
    if cov is None or not math.isfinite(cf.conductance):
        return {}, f"not read: the fit with the {shape} shape did not determine it"
    b_r, m_r = iso_reduction(values, shape)
    cov_r = reduction_covariance(values, shape, cov)
    sb, sm = (math.sqrt(max(float(cov_r[i, i]), 0.0)) for i in range(2))
    sd = {n: math.sqrt(max(float(cov[i, i]), 0.0)) for i, n in enumerate(names)}
    reading = dataclasses.replace(cf, critical_ratio=b_r, critical_ratio_std=sb,
                                  subsonic_index=m_r, subsonic_index_std=sm,
                                  subsonic_index_fitted=True)
    what = (f"q {values['q']:.2f} +- {sd['q']:.2f}" if shape == "q" else
            f"a pair in series: b2 {values['b2']:.3f} +- {sd['b2']:.3f}, m2 "
            f"{values['m2']:.3f} +- {sd['m2']:.3f}, C2/C1 {values['kappa']:.3g} +- "
            f"{sd['kappa']:.2g}")
    why = (f"{what} (b {values['b']:.3f}, m {values['m']:.3f}): the ISO 6358-1 law nearest "
           f"that curve over r in [0, {R_LINEAR:g}] has b {b_r:.3f} +- {sb:.3f}, m "
           f"{m_r:.3f} +- {sm:.3f}, C {cf.conductance:.4g}")
    return {SHAPE_READING[shape] + law_key: (reading, chi2, k)}, why


def read_shapes(fam: Family, best: str) -> tuple[dict[str, Fit], str]:
    """The shape's readings of the record: the q-free fit and the pair in series
    (:func:`read_shape`) of every heat law fitted with m free (a pair's fit costs about ten
    q-free fits: three more parameters and a flow function solved per evaluation);
    ({key: reading}, the chosen law's readings in words)."""
    first = best if best.endswith(M_SUFFIX) else best + M_SUFFIX
    keys = [first] + [k for k in fam.fits if k.endswith(M_SUFFIX) and k != first]
    out: dict[str, Fit] = {}
    words = []
    for key in keys:
        for shape in SHAPE_PARAMETERS:
            got, why = read_shape(fam, key, shape)
            out.update(got)
            if key == first:
                words.append(why)
    if len(keys) > 1:
        words.append(f"q and the pair read with the {len(keys) - 1} other heat law(s) "
                     "fitted with m free too")
    return out, "; ".join(words)


def settles(key: str, reading: CurveFit) -> bool:
    """The record determines the shape of the reading ``key``: q within
    :data:`ELLIPSE_EXPONENT_MAX_SD`; a pair's reduced b and m within
    :data:`SERIES_MAX_SD` [-]."""
    if key.startswith(SHAPE_READING["q"]):
        return reading.ellipse_exponent_std <= ELLIPSE_EXPONENT_MAX_SD
    return max(reading.critical_ratio_std, reading.subsonic_index_std) <= SERIES_MAX_SD


def shape_wins(shape: dict[str, Fit], bic: dict[str, float]) -> str | None:
    """The key of the best shape reading (by the criterion, ``bic`` [-] of every fit and
    reading) where the record determines its shape (:func:`settles`) and the criterion
    clearly prefers it to each fit and other reading that is not a shape's (by
    :data:`LAW_BIC_THRESHOLD`, the heat laws' rule): its ISO (b, m) are then reported;
    else None. (A gas 3 K warm and a -0.5 kPa zero: the shape's reading 51 better than the
    chosen law, an unclaimed warm gas's 59, with the truth's m where the shape read it
    0.023 low. A pair in series whose best reading, q with the truth's own heat law, left
    q loose at 3.70 +- 0.33: the pair's reading, settled but 19 worse, read b 0.380 for
    0.346.)"""
    key = min(shape, key=lambda k: bic[k], default=None)
    if key is None or not settles(key, shape[key][0]):
        return None
    others = [v for k, v in bic.items() if k not in shape]
    return key if not others or bic[key] < min(others) - LAW_BIC_THRESHOLD else None
