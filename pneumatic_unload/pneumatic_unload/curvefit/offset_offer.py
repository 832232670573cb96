# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The transducer's zero offset offered to the curve fit (SI units): a record that settles
away from the given p_atm has the offset fitted where the criterion clearly prefers it
(:func:`offer_offset`, :func:`offset_verdict`, :func:`keep_probe`; used by
:func:`~pneumatic_unload.curvefit.fitting.fit_curve`); one not fitted moves b and m by what
its stated uncertainty does along the fit's valley (:func:`unfitted_offset_lines`)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pneumatic_unload.curvefit.law_family import (
    LAW_BIC_THRESHOLD,
    TWIN_BIC_MARGIN,
    Family,
    Fit,
    criterion,
)
from pneumatic_unload.curvefit.subsonic_offer import M_SUFFIX, subsonic_index_problem
from pneumatic_unload.uncertainty.budget import input_uncertainties

#: Largest zero offset fitted, as a fraction of the drop p10 - p_atm [-] (a transducer's
#: zero is off by a few kPa; a record that sits tens of kPa away has not settled).
OFFSET_MAX_FRACTION = 0.05
#: A record whose last 2 % lie this many of their standard errors from the given p_atm, and
#: :data:`OFFSET_GAP_NOISE` of a reading's noise, is probed for a zero offset in full,
#: whatever the chosen fit's first-order twin says [-].
OFFSET_GAP_Z = 5.0
#: ... and this share of a reading's noise [-] (the 1 M-sample record of
#: ``bench/bench_engine.py`` ends 281 Pa above p_atm, 32 standard errors but 0.28 of its
#: noise: probing it in full cost ``analyze`` 0.1 s, 0.42 -> 0.49 of a raw bag iteration).
OFFSET_GAP_NOISE = 0.5
#: Key prefix of the family's best fit with the offset where the offset is not fitted
#: though the record's end is clearly away from p_atm: a reading in the model-form spread.
OFFSET_READING = "with the offset: "
#: The record's last 2 % must lie within this fraction of the drop of the given p_atm plus
#: the fitted offset [-]: the record settles on its final plateau.
SETTLED_FRACTION = 0.01


def offer_offset(fam: Family, best: str, gap: float, clear: bool = False,
                 kept: dict[str, Any] | None = None) -> str | None:
    """Fit the chosen law ``best`` once more with the transducer's zero offset (starting
    from ``gap`` [Pa], the record's last 2 % above the given p_atm; ``clear``: that end
    clearly away from it, probed in full); None when the criterion
    clearly prefers it (by LAW_BIC_THRESHOLD, the offset determined), else why not, in
    words (the probe also frees m: the criterion then asks for the offset's family only
    where the offset is also 3 of its sigmas from 0). ``kept``, where given, receives the
    probe's fit: 'key', 'entry' (its :data:`Fit`) and 'raw' (its FitResult and model), a
    fit of the offset's family (:func:`keep_probe`)."""
    # the first-order twin of the chosen fit (m as it is there) screens; the probe frees m
    # too: a flow law that is not the elliptic one leaves structure an offset alone cannot
    # take up, and an offset hides the subsonic tail's shape (m 0.3 read 3 kPa high: each
    # alone gains little, both together thousands)
    held = fam.fits[best]
    tw = fam.twin(best, "offset")
    if tw is not None and not fam.worth(tw) and not clear:
        # (a record's end clearly away from p_atm is probed in full: a chosen fit with m
        # free may have taken the offset up in b and m, its twin then gaining nothing:
        # -2.0 kPa read as b 0.066 for 0.36 and m 0.61 for 0.5)
        return (f"not fitted: the record settles at the given p_atm (an offset of "
                f"{tw.value:+.0f} +- {tw.std:.0f} Pa would not improve the criterion by "
                f"{TWIN_BIC_MARGIN:g}, to first order)")
    key = best if best.endswith(M_SUFFIX) else best + M_SUFFIX
    probe = Family(fam.span, fam.settings, fam.common, offset=True,
                   plateau_drift_z=fam.plateau_drift_z, t10_logged=fam.t10_logged,
                   plateau_bend_z=fam.plateau_bend_z)
    # started from the chosen fit and, where it has m free, from its law's fit with m held
    # too (whose b and m have not taken the offset up; m freed from 0.5 screens the far
    # ends of b and m): the lower chi^2 of the two
    bases = [held[0]] + [fam.fits[k][0] for k in (best.removesuffix(M_SUFFIX),)
                         if k != best and k in fam.fits]
    got = None
    for base in bases:
        start = fam.start_of(base)
        if math.isfinite(gap):
            start["offset"] = gap
        try:
            one = probe.fit(key, start=start, max_nfev=120)
        except (ValueError, FloatingPointError, np.linalg.LinAlgError):
            continue
        if got is None or one[1] < got[1]:
            got = one
            if kept is not None:
                kept.update(key=key, entry=one, raw=probe.raw[key])
    if got is None:
        return "not fitted: the fit with an offset failed"
    return offset_verdict(fam, held, got, gap)


def keep_probe(fam: Family, kept: dict[str, Any]) -> bool:
    """Put the offset probe's fit (``kept``, from :func:`offer_offset`) into ``fam``, the
    family fitted with the offset, where that family lacks its key or fits it worse, its
    m determined and its hot start (if one) offered there too: a fit made is a reading of
    the record (a flow with m 0.40 and a -1.4 kPa zero: the probe's constant-hA hot start
    with m free fitted to the noise, C +0.6 %, while the family, which fits m only
    for its best law, chose the natural law's, 36 worse in BIC, and no heat law followed
    the logged temperature). Returns whether it was put in."""
    key, entry = kept.get("key"), kept.get("entry")
    if key is None or entry is None or subsonic_index_problem(entry[0]) is not None:
        return False
    base = key.removesuffix(M_SUFFIX)
    if key in fam.not_offered or ("+wall" in base and base not in fam.fits):
        return False
    if key in fam.fits and fam.fits[key][1] <= entry[1]:
        return False
    fam.fits[key], fam.raw[key] = entry, kept["raw"]
    return True


def offset_verdict(fam: Family, held: Fit, got: Fit, gap: float) -> str | None:
    """None where the fit ``got`` with the zero offset is to be kept over ``held``
    (:data:`Fit` entries; ``gap`` [Pa]: the record's end above the given p_atm): the
    offset a small shift of a record that settles, the criterion clearly preferring it (by
    LAW_BIC_THRESHOLD) and the offset 3 of its sigmas from 0; else why not, in words."""
    off, sd = got[0].pressure_offset, got[0].pressure_offset_std
    drop = abs(got[0].p10 - fam.settings.end_pressure)  # type: ignore[operator]
    if not (abs(off) <= OFFSET_MAX_FRACTION * drop
            and abs(gap - off) <= SETTLED_FRACTION * drop):
        # a zero offset is a small shift of a record that settles: one that ends before
        # its final plateau (or a large "offset") is something else
        return (f"not fitted: the record does not settle on a plateau an offset explains "
                f"(its end {gap:+.0f} Pa from the given p_atm, an offset would be "
                f"{off:+.0f} Pa)")
    pair = criterion({"held": held, "offset": got}, fam.span.n)
    gain = pair["held"] - pair["offset"]
    if math.isfinite(sd) and gain > LAW_BIC_THRESHOLD and abs(off) > 3.0 * sd:
        return None
    return (f"not fitted: the record settles at the given p_atm (an offset of {off:+.0f} "
            f"+- {sd:.0f} Pa would improve the criterion by {gain:.1f} <= "
            f"{LAW_BIC_THRESHOLD:g})")


def unfitted_offset_lines(fam: Family, best: str) -> dict[str, float]:
    """The transducer's zero not fitted (p_atm given): b's and m's standard uncertainty [-]
    from its stated uncertainty d [Pa] (``pressure_uncertainty``, default 0.1 % of p10),
    along the chosen fit ``best``'s valley with the offset freed (its first-order twin's
    slopes: |db/dd| d, |dm/dd| d; with m held, m's from the law's fit with m free, NaN
    without it). An offset hides in the
    subsonic tail's shape where the record ends before its final plateau, b and m taking it
    up: the first-order line at the transition (b^2 d / p_atm) missed that (a +0.7 kPa zero
    read m 0.591 +- 0.009 for 0.50). d is the stated input's, as C's line of the offset
    (the record's own reading of the offset leans on the fit it is missing from). Returns
    {'input_std', 'b', 'm'}; {} without the twin."""
    tw = fam.twin(best, "offset")
    if tw is None:
        return {}
    d = input_uncertainties(fam.settings, fam.fits[best][0].p10)["pressure"]
    slope_m = tw.slope_m
    if not best.endswith(M_SUFFIX) and best + M_SUFFIX in fam.fits:
        # m held: its line is the move of the law's m-free fit (m at 0.500 +- 0.001 with a
        # -240 Pa zero, held, for 0.529: the held value's own line covered 0.004)
        free_m = fam.twin(best + M_SUFFIX, "offset")
        slope_m = free_m.slope_m if free_m is not None else math.nan
    # (math.nan itself where a slope is not known: results are compared as dicts, and a
    # NaN equals only itself)
    return {"input_std": d, "b": abs(tw.slope_b) * d if math.isfinite(tw.slope_b) else math.nan,
            "m": abs(slope_m) * d if math.isfinite(slope_m) else math.nan}
