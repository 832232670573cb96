# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The result of the final curve fit (:func:`pneumatic_unload.curvefit.fitting.fit_curve`): the
fitted values of the chosen heat law, their standard deviations, the laws compared, and the
fitted model's configuration; and where the fitted samples lie (:class:`CurveSpan`).

SI units: s, Pa absolute, K, m^3, m^3/(s Pa).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from pneumatic_unload.config import RigConfig
from pneumatic_unload.config.estimator import EstimatorSettings
from pneumatic_unload.model.inversion import rig_from_settings


class CurveSpan(NamedTuple):
    """Where the fitted samples lie: first and last instant [s, absolute], duration [s],
    samples [-] and sample period (median of the first 100 000 intervals) [s]."""

    t_ref: float
    t_last: float
    duration: float
    n: int
    dt: float


@dataclass(frozen=True)
class CurveFit:
    """Result of :func:`fit_curve` (SI units; std NaN when not identifiable).

    Attributes
    ----------
    conductance, conductance_std : float
        C and its 1-sigma [m^3/(s Pa)].
    critical_ratio, critical_ratio_std : float
        b and its 1-sigma [-] (NaN when the subsonic tail does not identify it).
    critical_ratio_on_bound : bool
        The fit put b on the bound of its range (b = 0 is a component's, so b stays
        reported; a hot start is not claimed with m free where it puts b there).
    t_start : float
        Valve opening instant [s].
    p10, p_atm : float
        Initial and atmospheric pressure [Pa absolute].
    heat_scale, heat_scale_std : float
        Multiplier on the natural-convection correlation [-] (1 and NaN when not fitted).
    rms : float
        Residual root mean square [Pa].
    n : int
        Samples fitted [-].
    success : bool
        Optimiser convergence.
    inflation : float
        Variance inflation applied for serially correlated residuals [-]
        (:func:`residual_inflation`).
    heat_law : str
        Heat-transfer law the data chose ('natural', 'fixed', 'density', each possibly
        with '+wall'; 'none' when adiabatic).
    tau_heat, tau_heat_std : float
        Thermal time constant m0 c_v/(hA) of the 'fixed' law (of hA_0, at the initial
        density, for 'density') and its 1-sigma [s] (NaN otherwise).
    heat_exponent, heat_exponent_std : float
        Exponent n of the 'density' law, hA ~ rho^n, and its 1-sigma [-] (NaN otherwise).
    heat_turbulent, heat_turbulent_std : float
        Multiplier on the natural law's turbulent branch and its 1-sigma [-] (1 and NaN
        unless 'natural+turbulent').
    model_form_std : float
        Model-form 1-sigma of C from the laws that fit about as well (delta-BIC < 10) but
        give another C [m^3/(s Pa)] (included in ``conductance_std``).
    laws : dict
        Per law offered: C [m^3/(s Pa)], chi2 and BIC [-].
    whiteness_p : float
        Ljung-Box p-value of the chosen law's residuals (binned, in time order) [-]: small
        means structure the model does not describe.
    not_offered : dict
        Laws fitted but not offered to the choice, with the reason (the record does not
        carry their extra parameter).
    wall_temperature, wall_temperature_std : float
        The wall temperature fitted by a hot-start variant ('natural+wall', 'fixed+wall':
        the gas starts at T10, the wall is elsewhere) and its 1-sigma [K]; NaN when the wall
        was not fitted.
    wall_uncertainty, wall_source : float, str
        With the wall assumed = T10 (not given, not fitted): its standard uncertainty [K]
        (:func:`~pneumatic_unload.config.estimator.wall_uncertainty`, the hot starts' walls
        as evidence) and where it comes from; NaN and '' otherwise.
    wall_std : float
        C's standard uncertainty from that assumed wall [m^3/(s Pa)]: the chosen law
        refitted with the wall moved by +-wall_uncertainty (not in ``conductance_std``);
        NaN otherwise.
    wall_std_b : float
        b's standard uncertainty from the wall [-]: assumed (as ``wall_std``) or given (its
        ``temperature_uncertainty``), the chosen law refitted with the wall moved to first
        order; NaN when no heat law was fitted, the wall was fitted, or b is not determined.
    wall_std_m : float
        m's standard uncertainty from the wall [-], as ``wall_std_b``'s; NaN also with m
        held.
    model_form_std_b : float
        b's model-form 1-sigma [-]: the spread of the b of the laws that fit about as
        well, weighted as C's (not in ``critical_ratio_std``).
    conductance_reproducibility, critical_ratio_reproducibility : float
        The fit's numerical reproducibility of C and b [-, relative]: how far they move
        when the chosen law's search restarts from its minimum displaced by about 1e5
        machine epsilons (:func:`~pneumatic_unload.fit.lsq.restart_spread`): what
        last-bit differences (another CPU's BLAS kernel or summation order) may change;
        1e-12 or less for a well-conditioned record, more in a flat valley (a faded heat
        exchange). NaN when not measured; b's is 0 when b was held.
    subsonic_index, subsonic_index_std : float
        The ISO 6358-1:2013 subsonic index m and its 1-sigma [-]: fitted when the record's
        subsonic tail determines it and the data choose it (the information criterion of
        the heat laws), else held at 0.5 (std NaN).
    subsonic_index_fitted : bool
        m was fitted (True) or held (False).
    ellipse_exponent, ellipse_exponent_std : float
        The exponent q of the subsonic branch's ellipse, phi = (1 - x^q)^m, and its 1-sigma
        [-]: 2 and NaN in the ISO 6358-1 law (always, but in the flow-curve shape's
        reading, :mod:`pneumatic_unload.curvefit.shape_reading`).
    shape_source : str
        The flow-curve shape's reading in words: the law fitted with q free and the ISO
        6358-1 (b, m) nearest its flow curve ('' where it was not made).
    subsonic_std, subsonic_std_b : float
        With m held: C's [m^3/(s Pa)] and b's [-] standard uncertainty from holding it (the
        budgets' 'subsonic index' line, :mod:`pneumatic_unload.curvefit.subsonic_offer`); 0 when m
        was fitted (its uncertainty is in the fit's covariance).
    subsonic_source : str
        Why m was fitted or held, in words.
    critical_ratio_source : str
        Why b is not reported (NaN), with the fit's value and 1-sigma [-], in words; ''
        when it is.
    misfit : float
        The pressure residual's RMS over its white noise's [-]
        (:func:`~pneumatic_unload.fit.uncertainty.misfit_ratio`): about 1 where the model
        misses by less than the noise; NaN when not measured.
    pressure_offset, pressure_offset_std : float
        The transducer's zero offset fitted (a reading = pressure + offset) and its 1-sigma
        [Pa]; 0 and NaN when it was not fitted (the record settles at the given p_atm).
    offset_source : str
        Why the offset was fitted or not, in words ('' when p_atm is fitted: the plateau's
        level is then the atmosphere's).
    unfitted_offset : dict
        The zero offset not fitted with p_atm given: its stated uncertainty ``input_std``
        [Pa] and what it does to ``b`` and ``m`` [-] along the fit's valley (NaN where not
        fitted); empty otherwise (:func:`~.offset_offer.unfitted_offset_lines`).
    model_form_std_m : float
        m's model-form 1-sigma [-]: the spread of the m of the laws fitted with m that fit
        about as well, weighted as C's (not in ``subsonic_index_std``); NaN when m is held.
    gas_temperature : dict
        The logged gas temperature fitted beside the pressure (empty when it was not):
        ``t10`` and ``t10_std`` [K] (the gas at the opening), ``sensor_time_constant`` and
        its ``_std`` [s], ``rms`` [K] of fitted minus measured readings, ``noise`` [K] of
        the channel, ``samples`` [-], ``weight`` [Pa/K] (see
        :class:`~pneumatic_unload.fit.trace.TemperatureChannel`).
    """

    conductance: float
    conductance_std: float
    critical_ratio: float
    critical_ratio_std: float
    t_start: float
    p10: float
    p_atm: float
    heat_scale: float
    heat_scale_std: float
    rms: float
    n: int
    success: bool
    inflation: float = 1.0
    heat_law: str = "natural"
    tau_heat: float = math.nan
    tau_heat_std: float = math.nan
    heat_exponent: float = math.nan
    heat_exponent_std: float = math.nan
    heat_turbulent: float = 1.0
    heat_turbulent_std: float = math.nan
    model_form_std: float = 0.0
    laws: dict[str, dict[str, float]] = dataclasses.field(default_factory=dict)
    wall_temperature: float = math.nan
    wall_temperature_std: float = math.nan
    whiteness_p: float = math.nan
    not_offered: dict[str, str] = dataclasses.field(default_factory=dict)
    wall_uncertainty: float = math.nan
    wall_source: str = ""
    wall_std: float = math.nan
    wall_std_b: float = math.nan
    wall_std_m: float = math.nan
    model_form_std_b: float = math.nan
    conductance_reproducibility: float = math.nan
    critical_ratio_reproducibility: float = math.nan
    subsonic_index: float = 0.5
    subsonic_index_std: float = math.nan
    subsonic_index_fitted: bool = False
    subsonic_std: float = 0.0
    subsonic_std_b: float = 0.0
    subsonic_source: str = ""
    ellipse_exponent: float = 2.0
    ellipse_exponent_std: float = math.nan
    shape_source: str = ""
    model_form_std_m: float = math.nan
    pressure_offset: float = 0.0
    pressure_offset_std: float = math.nan
    offset_source: str = ""
    unfitted_offset: dict[str, float] = dataclasses.field(default_factory=dict)
    gas_temperature: dict[str, float] = dataclasses.field(default_factory=dict)
    critical_ratio_on_bound: bool = False
    critical_ratio_source: str = ""
    misfit: float = math.nan

    def config(self, settings: EstimatorSettings) -> RigConfig:
        """The fitted model's configuration (valve opening at t = 0) [SI]."""
        t10 = self.gas_temperature.get("t10", math.nan)
        if math.isfinite(t10):  # fitted with the logged temperature
            settings = dataclasses.replace(settings, initial_temperature=float(t10))
        b = self.critical_ratio if math.isfinite(self.critical_ratio) else None
        cfg = rig_from_settings(settings, conductance=self.conductance, p10=self.p10,
                                p_atm=self.p_atm, critical_ratio=b,
                                heat_scale=self.heat_scale)
        if self.subsonic_index != cfg.subsonic_index:
            cfg = cfg.replace(subsonic_index=float(np.clip(self.subsonic_index, 0.1, 1.0)))
        if self.heat_law.startswith("natural") and self.heat_turbulent != 1.0:
            cfg = cfg.replace(heat_transfer_turbulent_ratio=float(
                np.clip(self.heat_turbulent, 0.0, 10.0)))
        if math.isfinite(self.wall_temperature):
            cfg = cfg.replace(wall_temperature=float(self.wall_temperature))
        if self.pressure_offset != 0.0:
            cfg = cfg.replace(effects=(*cfg.effects, "sensor_offset"),
                              sensor_offset=float(self.pressure_offset))
        if self.heat_law.startswith(("fixed", "density")) and math.isfinite(self.tau_heat):
            g = settings.gas
            h_a = self.p10 * settings.volume / ((g.gamma - 1.0) * settings.initial_temperature
                                                * self.tau_heat)
            cfg = cfg.replace(heat_transfer_mode="fixed",
                              heat_transfer_coefficient=float(np.clip(h_a, 0.0, 1e4)))
            if self.heat_law.startswith("density"):
                cfg = cfg.replace(heat_transfer_mode="density", heat_transfer_exponent=float(
                    np.clip(self.heat_exponent, -2.0, 4.0)))
        return cfg
