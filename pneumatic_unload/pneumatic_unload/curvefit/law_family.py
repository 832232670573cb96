# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The family of models the final curve fit compares: the heat laws, their hot-start
variants, each with the subsonic index m held at 0.5 or fitted; and the information
criterion that chooses among them.

:class:`Family` fits the laws in turn (:func:`~.law_fit.fit_law`), each starting from the
first law's fit, offers a law with a second parameter only where the record determines it
(:mod:`~.heat_law_offer`), explores strong and weak exchange when every law leaves
structure, and adds the hot-start variants where the wall assumed at T10 leaves structure
or T10 is far from a room's temperature. :func:`offer_m` adds a law's variant with m fitted
(or held) where the record determines m (:mod:`~.subsonic_offer`). :func:`criterion` is
the BIC of every fit. Keys: the law ('natural', 'fixed', 'density', 'natural+turbulent'),
'+wall' for a hot start, '|m' for m fitted.

SI units: s, Pa absolute, K, m^3/(s Pa).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload.config.estimator import (
    AMBIENT_TEMPERATURE,
    WALL_ASSUMED_STD,
    EstimatorSettings,
    probe_uncertainty,
    t10_measured,
    with_wall,
)
from pneumatic_unload.curvefit.curve_fit_result import CurveFit, CurveSpan
from pneumatic_unload.curvefit.heat_law_offer import (
    DENSITY_LAW_MAX_EXPONENT_SD,
    TURBULENT_MAX_LOG_SD,
    density_law_problem,
    next_law_start,
    turbulent_law_problem,
)
from pneumatic_unload.curvefit.law_fit import fit_law, heat_of, start_from
from pneumatic_unload.curvefit.linear_twin import Twin, linear_twin
from pneumatic_unload.curvefit.plateau import COLD_DRIFT_Z, PLATEAU_BEND_Z, PLATEAU_DRIFT_Z
from pneumatic_unload.curvefit.subsonic_offer import M_SUFFIX, split_key, subsonic_index_problem
from pneumatic_unload.model.effects import WALL_TEMPERATURE
from pneumatic_unload.model.inversion import estimator_model
from pneumatic_unload.model.parametric import SUBSONIC_INDEX_START
from pneumatic_unload.selection.evidence import information_criterion

#: Residual inflation above which, with the wall assumed at T10, the hot-start variants
#: (wall temperature fitted) are tried too [-] (they are also tried when T10 is more than
#: sqrt(3) WALL_ASSUMED_STD from a room's AMBIENT_TEMPERATURE).
HOT_START_INFLATION = 1.5

#: Delta-BIC below which another law counts as fitting about as well [-].
LAW_BIC_THRESHOLD = 10.0
#: A hot start is fitted in full where its first-order twin's BIC gain is above this [-]:
#: any gain (a 20 K warm gas's twin predicted 4.1 where its fit gained more than 10);
#: noise alone gains its chi^2 of one degree of freedom less ln n (about -5).
HOT_TWIN_MARGIN = 0.0
#: A twin (m or an offset freed) is fitted in full only where its first-order BIC gain is
#: above this [-] (half the criterion's threshold: the first order may under-state a move).
TWIN_BIC_MARGIN = 5.0
#: The laws with a second heat parameter: the one-parameter law each extends and the
#: starting values of the heat exchange taken from its fit.
SECOND_PARAMETER: dict[str, tuple[str, Callable[[CurveFit], dict[str, float]]]] = {
    "density": ("fixed", lambda f: {"tau_heat": f.tau_heat, "heat_exponent": 0.3}),
    "natural+turbulent": ("natural", lambda f: {"heat_scale": f.heat_scale,
                                                "heat_turbulent": 1.0}),
}
#: Evaluation budget of a fit started from its seed (:attr:`Family.seeds`) [-].
SEEDED_NFEV = 80
#: Evaluation budget of the next laws' fits where the first law leaves the heat exchange
#: undetermined (its multiplier within 2 sigma of none) [-]: the constant-hA law walks a
#: valley as flat (C within 0.03 %), and its full budget of 32 cost 42-108 evaluations.
FLAT_EXCHANGE_NFEV = 12
FloatArray = NDArray[np.float64]
#: One fit of the table: (result, chi^2 [Pa^2], free parameters [-]).
Fit = tuple[CurveFit, float, int]


@dataclass
class Family:
    """The fits of one curve fit, made in turn.

    Attributes
    ----------
    span : CurveSpan
        Where the samples lie.
    settings : EstimatorSettings
        Tank, gas and heat model.
    common : dict
        Arguments of every :func:`~.law_fit.fit_law` call (trace, starting values, hold, fit_heat).
    profile_heat : bool
        Profile the heat scale where its likelihood is not quadratic (the laws' first fits).
    offset : bool
        Every fit with the transducer's zero offset fitted.
    fits : dict
        Key -> :data:`Fit` offered to the criterion.
    raw : dict
        Key -> the fit's FitResult ('result'), model, covariance scale, CurveFit ('fit')
        and :data:`Fit` ('entry', offered or not).
    not_offered : dict
        Key -> why a fit made is not offered (the record does not carry its parameter).
    unclaimed : dict
        The best-fitting hot start not claimed (T10 not measured, a gas within a room's
        spread, its plateau straight): key -> :data:`Fit`, a reading of the record the
        model-form spread counts where it fits as well as the laws offered.
    seeds : dict
        Key -> starting values [SI] of that key's fit, replacing the one the family would
        take (e.g. the same law's fit to the pressure alone, for the joint fit with the
        logged temperature).
    plateau_drift_z : float
        The plateau's slope before the opening in its standard errors
        (:func:`~pneumatic_unload.curvefit.plateau.plateau_drift`; beyond
        :data:`~pneumatic_unload.curvefit.plateau.PLATEAU_DRIFT_Z` either way the hot starts
        are fitted too, and its sign says which: a cold gas makes it rise, a warm one
        fall) [-].
    plateau_bend_z : float
        The plateau's bend toward a level before the opening in its standard errors
        (:func:`~pneumatic_unload.curvefit.plateau.plateau_bend`) [-]: a gas cooling (or
        warming) to the wall's temperature approaches it exponentially; a leak's decay is
        straight over a plateau.
    t10_logged : bool
        The record carries the gas temperature (T10 measured, whatever its value).
    """

    span: CurveSpan
    settings: EstimatorSettings
    common: dict[str, Any]
    profile_heat: bool = True
    offset: bool = False
    fits: dict[str, Fit] = field(default_factory=dict)
    raw: dict[str, dict[str, Any]] = field(default_factory=dict)
    not_offered: dict[str, str] = field(default_factory=dict)
    unclaimed: dict[str, Fit] = field(default_factory=dict)
    seeds: dict[str, dict[str, float]] = field(default_factory=dict)
    plateau_drift_z: float = 0.0
    t10_logged: bool = False
    plateau_bend_z: float = 0.0

    @property
    def plateau_drifts(self) -> bool:
        """The plateau drifts by :data:`~pneumatic_unload.curvefit.plateau.PLATEAU_DRIFT_Z`
        or more, either way."""
        return abs(self.plateau_drift_z) >= PLATEAU_DRIFT_Z

    @property
    def t10_assumed(self) -> bool:
        """T10 was not measured (at its default, a room's :data:`AMBIENT_TEMPERATURE`, the
        wall not given, no logged temperature): a hot start is then fitted as a gas warmer
        or cooler than a wall at the room's temperature, T10 fitted (a tank stands in the
        room, a charge warms the gas; the pressure hardly tells which of the two is at the
        room's temperature: C goes as 1/sqrt(T) along that valley), not as a wall away from
        a room's T10 (C +4.6 % to +5.7 % on 20-30 K hot starts:
        bench/bench_temperature_records.py)."""
        return not t10_measured(self.settings, self.t10_logged)

    @property
    def natural(self) -> bool:
        """The natural heat model is on (else adiabatic)."""
        return self.settings.heat_model == "natural"

    def fit(self, key: str, *, start: dict[str, float] | None, max_nfev: int,
            profile_heat: bool = False, explore: bool = False, shape: str = "iso",
            keep: dict[str, Any] | None = None) -> Fit:
        """The fit of a table key (kept in ``raw``, not offered); ``shape`` not 'iso': the
        flow curve's (law_fit's), a reading (:mod:`~.shape_reading`) kept in ``keep`` alone."""
        law, wall, fit_m = split_key(key)
        kept: dict[str, Any] = {} if keep is None else keep
        if shape == "iso":  # (another shape's fit is a reading, kept in ``keep`` alone)
            self.raw[key] = kept
            if key in self.seeds:  # a start near this key's minimum: a few iterations
                start, max_nfev = self.seeds[key], max(max_nfev, SEEDED_NFEV)
        settings, warm = self.settings, wall and self.t10_assumed
        if warm:  # a hot start read as a gas warm from its charge in a tank at the room's
            settings = with_wall(settings, AMBIENT_TEMPERATURE)
        out = fit_law(self.span, settings, profile_heat=profile_heat, law=law,
                      start=start, max_nfev=max_nfev, fit_wall=wall and not warm,
                      fit_m=fit_m, fit_offset=self.offset, fit_t10=warm, shape=shape,
                      explore=explore, keep=kept, **self.common)
        kept["fit"], kept["entry"] = out[0], out
        return out

    def start_of(self, fit: CurveFit) -> dict[str, float]:
        """Starting values [SI] of another fit from ``fit``: its C, opening, p10, b, p_atm,
        m and heat exchange."""
        return start_from(fit, self.span.t_ref, **heat_of(fit))

    def twin(self, key: str, name: str) -> Twin | None:
        """The first-order twin of the fit ``key`` with ``name`` ('m' or 'offset') freed
        (:func:`~pneumatic_unload.curvefit.linear_twin.linear_twin`; None without it)."""
        kept = self.raw.get(key)
        if not kept or "model" not in kept:
            return None
        law, wall, fit_m = split_key(key)
        model = estimator_model(self.settings, kept["model"].start, heat_law=law,
                                fit_wall=wall, fit_m=fit_m or name == "m",
                                fit_offset=self.offset or name == "offset",
                                thermometer=kept["model"].thermometer,
                                fit_t10=kept["model"].fit_initial_temperature)
        start = SUBSONIC_INDEX_START if name == "m" else 0.0
        return linear_twin(self.common["trace"], kept, model, name, start)

    def _plateau_shows(self, cold: bool) -> bool:
        """Whether the plateau's drift allows a gas colder (``cold``) or warmer than the
        wall: a cold one warms on it, rising by
        :data:`~pneumatic_unload.curvefit.plateau.COLD_DRIFT_Z`; a warm one cools, and must
        not rise by :data:`~pneumatic_unload.curvefit.plateau.PLATEAU_DRIFT_Z`."""
        z = self.plateau_drift_z
        return z >= COLD_DRIFT_Z if cold else z < PLATEAU_DRIFT_Z

    def hot_twin(self, key: str) -> Twin | None:
        """The first-order twin of the fit ``key`` as its hot start: T10 freed and the wall
        held at the room's temperature where T10 was not measured (a gas warm from its
        charge), else the wall's temperature freed (at T10, where the fit holds it, the
        twin is the fit itself); None without it."""
        kept = self.raw.get(key)
        if not kept or "model" not in kept:
            return None
        law, _wall, fit_m = split_key(key)
        warm = self.t10_assumed
        settings = with_wall(self.settings, AMBIENT_TEMPERATURE) \
            if warm else self.settings
        model = estimator_model(settings, kept["model"].start, heat_law=law, fit_m=fit_m,
                                fit_offset=self.offset, fit_t10=warm, fit_wall=not warm,
                                thermometer=kept["model"].thermometer,
                                thermometer_offset=kept["model"].thermometer_offset)
        name = "t10" if warm else "t_wall"
        start = self.settings.initial_temperature if warm else self.settings.wall
        return linear_twin(self.common["trace"], kept, model, name, start)

    def _no_hot_start(self, key: str, family: list[str]) -> str | None:
        """Why the hot start of ``key``'s law is not fitted, or None: its first-order twin
        (:meth:`hot_twin`) must predict a BIC gain above :data:`HOT_TWIN_MARGIN` and bring
        the law within :data:`LAW_BIC_THRESHOLD` of the family's best (a plateau's drift of
        noise alone is no hot start, nor does a law the record rejects fit by it)."""
        tw = self.hot_twin(key)
        if tw is None:
            return None
        what = "a warm gas (T10 not measured)" if self.t10_assumed else \
            "a wall away from T10"
        gain = self.twin_bic_gain(tw)
        if gain <= HOT_TWIN_MARGIN:
            return (f"{what} would gain {gain:.1f} in BIC, to first order: the record "
                    "shows no hot start")
        fits = {k: self.fits[k] for k in family}
        bic = criterion(fits, self.span.n)
        unit = criterion_unit(fits)
        _cf, chi2, k = fits[key]
        reach = (chi2 - tw.gain) / unit + (k + 1) * math.log(max(self.span.n, 2))
        if reach - min(bic.values()) > LAW_BIC_THRESHOLD:
            return (f"{what} would leave the {split_key(key)[0]} law "
                    f"{reach - min(bic.values()):.0f} in BIC behind the best, to first order")
        return None

    def worth(self, tw: Twin | None) -> bool:
        """A twin worth fitting in full: not computable, or its predicted BIC gain above
        :data:`TWIN_BIC_MARGIN`, in the residual variance the twin would leave (not
        inflated: where the held fit leaves structure the twin may take it up)."""
        return tw is None or self.twin_bic_gain(tw) > TWIN_BIC_MARGIN

    def twin_bic_gain(self, tw: Twin) -> float:
        """A twin's predicted BIC gain [-]: its chi^2 drop in the residual variance it
        would leave, less the parameter's ln n."""
        unit = max((tw.chi2 - tw.gain) / max(tw.dof, 1), 1e-300)
        return tw.gain / unit - math.log(max(self.span.n, 2))

    def run(self, laws: tuple[str, ...], sfx: str) -> None:
        """Fit ``laws`` with m held (``sfx`` '') or fitted ('|m'), the laws already in the
        table skipped; then the exploration and the hot starts of this family."""
        start: dict[str, float] | None = None
        first = self.fits.get(laws[0] + sfx)
        if first is not None and first[0].inflation < 2.0 \
                and math.isfinite(first[0].conductance):
            start = next_law_start(first[0], self.settings, self.span.t_ref)
        flat = first is not None and _exchange_undetermined(first[0])
        for law in laws:
            key = law + sfx
            if key in self.fits or key in self.not_offered:
                continue
            law_start, nfev = start, (200 if not self.fits else
                                      FLAT_EXCHANGE_NFEV if flat else 32)
            if law in SECOND_PARAMETER:
                # offered where the one-parameter law it extends shows what it needs,
                # started from that law's fit
                base_law, heat = SECOND_PARAMETER[law]
                base = self.fits.get(base_law + sfx, (None,))[0]
                why = density_law_problem(base) if law == "density" else \
                    turbulent_law_problem(base, self.settings, self.span.t_last)
                if why is not None or base is None:
                    self.not_offered[key] = why or f"no {base_law} fit to start from"
                    continue
                law_start = start_from(base, self.span.t_ref, **heat(base))
                nfev = 80
            got = self.fit(key, start=law_start, max_nfev=nfev,
                           profile_heat=self.profile_heat)
            why = _second_parameter_problem(law, got[0])
            if why is not None:
                self.not_offered[key] = why
                continue
            self.fits[key] = got
            flat = flat or (law == laws[0] and _exchange_undetermined(got[0]))
            if start is None and got[0].inflation < 2.0 and math.isfinite(got[0].conductance):
                # the next law starts from this fit when it is close (white residuals);
                # otherwise from the neutral values, with a second start screened
                start = next_law_start(got[0], self.settings, self.span.t_ref)
        self._explore(sfx)
        self._hot_starts(sfx)

    def _explore(self, sfx: str) -> None:
        """Structured residuals under every law of the family: a basin may have been missed
        (e.g. a nearly isothermal discharge fitted from the weak-exchange side); explore
        strong and weak heat exchange from the neutral values and keep what fits better."""
        family = [k for k in self.fits if k.endswith(M_SUFFIX) == bool(sfx)]
        if not family or min(self.fits[k][0].inflation for k in family) <= 2.0:
            return
        for key in family:
            start = {"m": self.fits[key][0].subsonic_index} if sfx else None
            kept_before = self.raw.get(key)
            again = self.fit(key, start=start, max_nfev=200, profile_heat=self.profile_heat,
                             explore=True)
            if again[1] < self.fits[key][1]:
                self.fits[key] = again
            elif kept_before is not None:
                self.raw[key] = kept_before

    def _hot_starts(self, sfx: str) -> None:
        """The hot-start variants (the wall fitted from each one-parameter law's fit) where
        the wall assumed at T10 leaves structure under every law, or T10 is far from a
        room's temperature (a gas warmed or cooled by the charge); offered where the wall
        is clearly away from T10 or the variant turns the structure into white residuals
        (with m held, or else with m free)."""
        s = self.settings
        family = [k for k in self.fits if k.endswith(M_SUFFIX) == bool(sfx)]
        if not (self.natural and self.common["fit_heat"] and s.wall_temperature is None
                and family):
            return
        if s.charge and not self.t10_logged:
            # a charge's pressure barely carries T10 (the inflow's enthalpy sets the rise):
            # fitted from it, T10 traded against C and b (an adiabatic rig's 1 kHz charge:
            # T10 440 K, C +7.7 % at z 7); a warm tank's charge is read with its log
            for law in ("natural", "fixed"):
                if law + sfx in self.fits:
                    self.not_offered[f"{law}+wall{sfx}"] = (
                        "a charge's T10 is not fitted from its pressure (the inflow's "
                        "enthalpy sets the rise): give the gas temperature's log")
            return
        least = min(self.fits[k][0].inflation for k in family)
        far = abs(s.initial_temperature - AMBIENT_TEMPERATURE) > \
            math.sqrt(3.0) * WALL_ASSUMED_STD
        if not (least > HOT_START_INFLATION or far or self.plateau_drifts
                or self.t10_assumed):
            return
        warm: dict[str, tuple[Fit, float]] = {}
        for law in [k for k in ("natural", "fixed") if k + sfx in self.fits]:
            base = self.fits[law + sfx][0]
            if not math.isfinite(base.conductance):
                continue
            key = f"{law}+wall{sfx}"
            # offered on a plateau's drift alone: screened by its first-order twin
            why = self._no_hot_start(law + sfx, family) \
                if least <= HOT_START_INFLATION and not far else None
            if why:
                self.not_offered[key] = why
                continue
            hot = self.fit(key, start=self.start_of(base), max_nfev=120)
            if sfx and hot[0].critical_ratio_on_bound:
                # a warm gas claimed only with m free and b on its bound: the three trade
                # (a 5 K warm gas not measured: b 0.010 for 0.3, m 0.428 +- 0.007 for 0.5)
                self.not_offered[key] = ("with m free, the hot start put b on the bound "
                                         "of its range: T10, b and m trade, the record "
                                         "does not tell them apart")
                continue
            # a hot start is a claim about the rig: a wall clearly away from T10 (3 of the
            # temperature's uncertainties, at least 3 K) makes it, or one nearer that turns
            # the structure every law with the wall at T10 leaves into white residuals; else
            # it absorbs other model error (HydDown: a wall 2.4 K off moved C by +0.25 %)
            t10 = hot[0].gas_temperature.get("t10", s.initial_temperature)
            gap = abs(hot[0].wall_temperature - t10)
            edge = t10 if self.t10_assumed else hot[0].wall_temperature
            if min(abs(edge - WALL_TEMPERATURE.lo), abs(edge - WALL_TEMPERATURE.hi)) < 1.0:
                # a wall on the bound of any room's is no minimum: it absorbs other model
                # error (two restrictions in series: a wall at 150 K, C -4.3 %)
                self.not_offered[key] = (f"the wall or T10 went to the bound of its range "
                                         f"({edge:.0f} K): no hot start")
            elif self.t10_assumed:
                # T10 not measured: a gas warm from its charge is claimed where it lies
                # beyond a room's spread (3 x WALL_ASSUMED_STD); white residuals alone are
                # no evidence of it: a plateau that decays through a leak turned white
                # with a gas 3 K warm and C +6.6 % (z 15; test_adequacy)
                hottest = (s.gas.gamma - 1.0) * AMBIENT_TEMPERATURE
                if gap > hottest:
                    # filling even an evacuated tank heats its gas to gamma T_supply at
                    # most: a larger gap absorbs other model error (two restrictions in
                    # series: T10 545 K, C -29 %)
                    self.not_offered[key] = (f"T10 not measured: a gas {gap:.0f} K from the "
                                             f"room's is beyond what a charge can make "
                                             f"({hottest:.0f} K, gamma T_room)")
                elif not self._plateau_shows(cold := t10 < hot[0].wall_temperature):
                    # a charge warms its gas; a cold one (a tank vented, then shut) warms
                    # on its plateau, which must show it rising, and a warm one must not
                    # rise: else the gas absorbs other model error (two restrictions in
                    # series: T10 286 K, C +3.1 %; a gauge's zero with m 0.3 on a plateau
                    # rising 2.0 sigma by chance: 280 K, +4.8 %)
                    self.not_offered[key] = (
                        f"T10 not measured: a gas {gap:.1f} K {'colder' if cold else 'warmer'}"
                        f" than the room's, its plateau {'not ' if cold else ''}rising "
                        f"({self.plateau_drift_z:+.1f} sigma)")
                else:
                    warm[key] = (hot, gap)  # the claim is judged on the family's best
            elif gap > 3.0 * max(probe_uncertainty(s), 1.0) or \
                    least > HOT_START_INFLATION >= hot[0].inflation:
                self.fits[key] = hot
            elif not sfx and least > HOT_START_INFLATION:
                # or one that does so with m free (a constant hA 2 K from T10, m 0.67, a
                # +2.8 kPa zero: C -1.0 %, b 0.08 for 0.31 through the natural law's)
                free = self.fit(key + M_SUFFIX, start=self.start_of(hot[0]), max_nfev=120)
                if subsonic_index_problem(free[0]) is None and \
                        free[0].inflation <= HOT_START_INFLATION:
                    self.fits[key + M_SUFFIX] = free
        if warm:
            self._warm_gas(warm)

    def _warm_gas(self, warm: dict[str, tuple[Fit, float]]) -> None:
        """Offer the hot starts ``warm`` (key -> fit and its gas's gap from the room's [K];
        T10 not measured) where the one that fits best (its BIC among them) puts the gas
        beyond a room's spread (3 x :data:`WALL_ASSUMED_STD`), or nearer where the plateau
        bends toward a level as a gas reaching the wall's temperature does
        (:data:`~pneumatic_unload.curvefit.plateau.PLATEAU_BEND_Z`; a leak's decay is
        straight over a plateau); else none, the best kept as :attr:`unclaimed`. Each law
        judged by its own gap read a warm gas through the law that needs the largest one
        (a 6 K warm gas, 3.2 K at the opening: C -2.7 % at z -3.6)."""
        fits = {k: f for k, (f, _gap) in warm.items()}
        bic = criterion(fits, self.span.n)
        best = min(bic, key=lambda k: bic[k])
        gap = warm[best][1]
        if gap > 3.0 * WALL_ASSUMED_STD or self.plateau_bend_z >= PLATEAU_BEND_Z:
            self.fits.update(fits)
            return
        self.unclaimed = {best: fits[best]}  # a reading of the record all the same
        for key in warm:
            self.not_offered[key] = (f"T10 not measured: a gas {gap:.1f} K from the room's "
                                     f"(the best-fitting hot start, {split_key(best)[0]}) is "
                                     f"within its spread (3 x {WALL_ASSUMED_STD:g} K), its "
                                     f"plateau bending {self.plateau_bend_z:+.1f} sigma")


def _exchange_undetermined(fit: CurveFit) -> bool:
    """The natural law's fit leaves the heat exchange undetermined: its multiplier within
    2 of its standard deviations of none (:data:`FLAT_EXCHANGE_NFEV`)."""
    return fit.heat_law == "natural" and math.isfinite(fit.heat_scale_std) \
        and fit.heat_scale <= 2.0 * fit.heat_scale_std


def _second_parameter_problem(law: str, fit: CurveFit) -> str | None:
    """Why a law with a second heat parameter is not offered: the record does not
    determine it (None: offer it, and for the one-parameter laws)."""
    if law == "density":
        sd = fit.heat_exponent_std
        if not (math.isfinite(sd) and sd <= DENSITY_LAW_MAX_EXPONENT_SD):
            return (f"the record does not determine the exponent n "
                    f"(1-sigma {sd:.2g} > {DENSITY_LAW_MAX_EXPONENT_SD:g})")
    if law == "natural+turbulent":
        sd = fit.heat_turbulent_std / fit.heat_turbulent if fit.heat_turbulent > 0 \
            else math.nan
        if not (math.isfinite(sd) and sd <= TURBULENT_MAX_LOG_SD):
            return (f"the record does not determine the turbulent branch "
                    f"(relative 1-sigma {sd:.2g} > {TURBULENT_MAX_LOG_SD:g})")
    return None


def other(key: str) -> str:
    """The table key of the same law with m held instead of fitted, or fitted instead of
    held."""
    return key.removesuffix(M_SUFFIX) if key.endswith(M_SUFFIX) else key + M_SUFFIX


def offer_m(fam: Family, key: str) -> str | None:
    """Fit the law of ``key`` with m fitted if held there, held if fitted, from that fit;
    offer it to the criterion unless m is fitted and the record does not determine it
    (:func:`~pneumatic_unload.curvefit.subsonic_offer.subsonic_index_problem`: the reason goes to
    ``not_offered`` and is returned; None when offered)."""
    twin = other(key)
    base = fam.fits[key][0]
    try:
        got: Fit | None = fam.fit(twin, start=fam.start_of(base), max_nfev=120)
    except (ValueError, FloatingPointError, np.linalg.LinAlgError):
        got = None
    why = "the fit failed" if got is None else \
        subsonic_index_problem(got[0]) if twin.endswith(M_SUFFIX) else None
    if got is not None and why is None:
        fam.fits[twin] = got
    else:
        fam.not_offered[twin] = why or ""
    return why


def criterion(fits: dict[str, Fit], n: int) -> dict[str, float]:
    """BIC [-] of every fit: chi^2 normalised by the lowest-chi^2 fit's residual variance
    (inflated when structured: correlated residuals carry less information), n samples."""
    unit = criterion_unit(fits)
    return {k: information_criterion(f[1] / unit, f[2], max(n, 2)) for k, f in fits.items()}


def criterion_unit(fits: dict[str, Fit]) -> float:
    """The criterion's residual variance [Pa^2]: the lowest-chi^2 fit's, inflated (a
    ValueError saying so where no law was fitted)."""
    if not fits:
        raise ValueError("no heat law could be fitted to the record")
    ref = fits[min(fits, key=lambda k: fits[k][1])][0]
    return max(ref.rms**2 * ref.inflation, 1e-300)


def best_key(fits: dict[str, Fit], n: int) -> str:
    """The key of the lowest BIC (:func:`criterion`)."""
    bic = criterion(fits, n)
    return min(bic, key=lambda k: bic[k])
