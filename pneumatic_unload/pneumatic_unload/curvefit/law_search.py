# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The search of a law family: the heat laws fitted with the subsonic index m held, and
with m free where the record asks for it, and the criterion's choice (:func:`choose_laws`;
used by :func:`~pneumatic_unload.curvefit.fitting.fit_curve` and
:func:`~pneumatic_unload.curvefit.joint_family.with_temperature`). SI units."""

from __future__ import annotations

from typing import Any

import numpy as np

from pneumatic_unload.curvefit.law_family import (
    LAW_BIC_THRESHOLD,
    Family,
    Fit,
    best_key,
    criterion,
    offer_m,
    other,
)
from pneumatic_unload.curvefit.subsonic_offer import M_SUFFIX, subsonic_index_problem

#: Where every law fitted with m held misses the record by more than this ratio of its
#: residual's RMS to its white noise's [-] (:attr:`CurveFit.misfit`), the laws are all
#: fitted with m free too (random draws of the ISO law with m 0.70, Newton cooling: every
#: law 2.1-4.5 with m held, C +0.7 % and -7.2 %, b 0.04 for 0.26; two restrictions in
#: series, 2.7: C -13.8 % through a hot start; 1.0 with m free). Structure within the
#: noise stays with the first law's test (HydDown's Nusselt jump: 1.03-1.18, where the
#: density law with m free read C +1.5 %). 1.5 until session 25: the ISO law with m 0.62
#: and b 0.6 under Newton cooling (1 L, 6 bar) had every law 1.35-1.45 with m held, the
#: natural law's hot start with m free chosen at C -6.4 % and residuals not white, while
#: the constant hA law with m free fits it to the noise (C +0.004 %, m 0.615).
MISFIT_SEARCH = 1.3
#: A law refuted with m held is fitted with m free only where its first-order twin with m
#: freed (:meth:`Family.twin`) leaves a chi^2 within this factor of the best fit's [-].
#: The twin underestimates what freeing m gains where m and the heat law trade, the full
#: fit does not: of 246 such fits (foreign draws 0-319 and the 170 temperature draws with
#: T, bench_random_draws), the 11 that beat every fit had twins at 0.85-5.2 times the best
#: chi^2 (foreign draw 308, a constant hA with m 0.43: 5.2, its fit 46 better in BIC than
#: the best); the 76 at 10.3-650 missed by 2000 or more in BIC, or failed, and on
#: bench_engine's 1 M-sample record (a wrong law at 54) cost analyze 0.4 s for nothing.
M_PROBE_TWIN_RATIO = 10.0


def choose_laws(fam: Family, tried: tuple[str, ...]) -> tuple[Family, str]:
    """Fit the laws ``tried`` with m held, and with m free where the record asks for it;
    returns the family and the key the criterion chooses.

    The subsonic index: the first law once more with m free where its first-order twin
    (:meth:`Family.twin`) says it is worth a fit; where the record determines m and the
    criterion prefers it to the same law with m held, the laws are fitted again with m
    free (m and the heat law trade: both families are offered); clearly (by
    LAW_BIC_THRESHOLD: HydDown's 1 L vessel, 3.5 better with m free, then took the density
    law with m = 0.527 and C +1.5 % over the hot start's -0.1 %). The chosen law's other
    variant (m held for one fitted, m free for one held where its twin says it is worth a
    fit) is fitted too, and the criterion decides between the two. A law refuted with m
    held is tried with m free too (:func:`_refuted_with_m_free`); where the chosen law has
    m free, every law is fitted with m free."""
    fam.run(tried, "")  # m held at 0.5
    fits, n = fam.fits, fam.span.n
    first = tried[0]
    if first in fits and fam.worth(fam.twin(first, "m")) and offer_m(fam, first) is None:
        pair = criterion({k: fits[k] for k in (first, first + M_SUFFIX)}, n)
        if pair[first] - pair[first + M_SUFFIX] > LAW_BIC_THRESHOLD:
            fam.run(tried, M_SUFFIX)
    if fits and min(f[0].misfit for f in fits.values()) > MISFIT_SEARCH:
        # every law misses the record by more than its noise: m and the heat law trade,
        # so the first law's gain from m alone does not speak for the others (a flow with
        # m 0.70 and Newton cooling: the natural law took up the shape with b 0.04 and
        # gained nothing from m, while the constant hA law with m fits to the noise)
        fam.run(tried, M_SUFFIX)
    _refuted_with_m_free(fam, tried)
    best = best_key(fits, n)
    if other(best) not in fam.raw and (best.endswith(M_SUFFIX)
                                       or fam.worth(fam.twin(best, "m"))):
        offer_m(fam, best)
        best = best_key(fits, n)
    if best.endswith(M_SUFFIX) and any(
            k + M_SUFFIX not in fits and k + M_SUFFIX not in fam.not_offered
            for k in tried):
        # m chosen: m and the heat law trade, so the other laws are fitted with m free
        # too (a -0.44 kPa zero fitted, m 0.46, constant hA: the natural law's hot start
        # with m free, 9 better than with m held, read m 0.485 +- 0.003 and b 0.258 +-
        # 0.004 for 0.462 and 0.244, while the constant hA's with m free, not fitted, is
        # 14 better still and reads 0.458 and 0.242)
        fam.run(tried, M_SUFFIX)
        best = best_key(fits, n)
    return fam, best


def _refuted_with_m_free(fam: Family, tried: tuple[str, ...]) -> None:
    """A law refuted with m held (misfit over MISFIT_SEARCH) may be the record's with m
    free: m and the heat law trade. Each whose first-order twin with m freed comes within
    reach of the best (:func:`_twin_within_reach`) is fitted with m free from its fit; where one of
    those is better in BIC than every fit so far, the family is fitted with m free and
    each of those fits kept where it is the better of its key (foreign draw 308, a
    constant hA with m 0.43: that law misfit 5.3 with m held while the natural law, m
    held, followed the record to its noise with b 0.161 for 0.167 and m 0.500 +- 0.003;
    the constant hA with m free, never fitted, was 46 better in BIC: m 0.433, b 0.153)."""
    fits, n = fam.fits, fam.span.n
    probes: dict[str, tuple[Fit, Any]] = {}
    for k in tried:
        key = k + M_SUFFIX
        if k not in fits or fits[k][0].misfit <= MISFIT_SEARCH or key in fits \
                or key in fam.not_offered or not _twin_within_reach(fam, k):
            continue
        try:
            got = fam.fit(key, start=fam.start_of(fits[k][0]), max_nfev=120)
        except (ValueError, FloatingPointError, np.linalg.LinAlgError):
            got = None
        raw = fam.raw.pop(key, None)
        if got is not None and subsonic_index_problem(got[0]) is None:
            probes[key] = (got, raw)
    if not probes:
        return
    bic = criterion({**fits, **{k: v[0] for k, v in probes.items()}}, n)
    if min(bic[k] for k in probes) >= min(bic[k] for k in fits):
        return
    fam.run(tried, M_SUFFIX)
    for key, (got, raw) in probes.items():
        if key not in fam.not_offered and (key not in fits or got[1] < fits[key][1]):
            fits[key], fam.raw[key] = got, raw


def _twin_within_reach(fam: Family, key: str) -> bool:
    """Whether the fit ``key`` (m held), with m freed to first order, leaves a chi^2 within
    :data:`M_PROBE_TWIN_RATIO` of the family's best [-] (True where the twin is not
    computable: the full fit decides)."""
    tw = fam.twin(key, "m")
    best = min(f[1] for f in fam.fits.values())
    return tw is None or not best > 0.0 or tw.chi2 - tw.gain <= M_PROBE_TWIN_RATIO * best
