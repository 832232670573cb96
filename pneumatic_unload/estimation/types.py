"""Types of the estimator: statuses, settings, results, diagnostics and its error (SI units).

Everything here is plain data: :class:`EstimatorSettings` (tank, gas and detection settings),
:class:`UnloadResult` (one analysed unload), :class:`Diagnostic` (a state change or an input
problem) and :class:`EstimationError` (input that cannot be analysed). SI units: s, Pa
absolute, K, m^3, m^3/(s Pa).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pneumatic_unload import physics
from pneumatic_unload.physics import AIR, T_N

#: Array of float64 samples (times [s], pressures [Pa] or signal units).
FloatArray = NDArray[np.float64]

#: Statuses of an :class:`UnloadResult` (same order as the message's STATUS_* constants).
STATUSES = ("ok", "aborted_sse", "aborted", "not_choked", "bad_data")


class EstimationError(ValueError):
    """Input that cannot be analysed at all (too few samples, wrong shapes...)."""


@dataclass(frozen=True)
class EstimatorSettings:
    """Settings of the unloading-time estimator.

    Attributes
    ----------
    volume : float
        Tank volume V [m^3].
    initial_temperature : float
        Initial gas temperature T10 [K].
    atmosphere : float or None
        Atmospheric pressure [Pa absolute]; None: from the final plateau (auto).
    length_diameter_ratio : float
        Tank L/D [-] (natural-convection model of the model-based C).
    wall_temperature : float or None
        Wall temperature [K]; None: equal to T10.
    heat_model : str
        'natural' (natural-convection wall heat transfer) or 'adiabatic' for the model-based C.
    critical_ratio : float
        b [-] assumed by the model-based inversion at the crossing (the curve fit refines it).
    signal_gain : float
        Pressure per unit of input signal [Pa per unit] (1 for an input in Pa).
    signal_offset : float
        Pressure at zero input [Pa] (0 for an input in Pa absolute).
    trigger_sigma : float
        Drop below the plateau that triggers detection, in noise standard deviations [-].
    min_plateau : int
        Samples of pre-step plateau needed before a trigger is accepted [-].
    max_gap_factor : float
        A stamp step larger than this many nominal periods is a gap [-].
    curve_fit : bool
        Run the full-curve least-squares fit (C, b) when the unload ends.
    gas_constant, gamma : float
        Gas properties [J/(kg K)], [-].
    """

    volume: float = 5e-3
    initial_temperature: float = T_N
    atmosphere: float | None = 101325.0
    length_diameter_ratio: float = 2.0
    wall_temperature: float | None = None
    heat_model: str = "natural"
    critical_ratio: float = 0.5
    signal_gain: float = 1.0
    signal_offset: float = 0.0
    trigger_sigma: float = 8.0
    min_plateau: int = 32
    max_gap_factor: float = 5.0
    curve_fit: bool = True
    gas_constant: float = AIR.gas_constant
    gamma: float = AIR.gamma

    def __post_init__(self) -> None:
        """Validate (raises :class:`EstimationError`)."""
        checks = [
            (self.volume > 0, "volume must be > 0 m^3"),
            (self.initial_temperature > 0, "initial_temperature must be > 0 K"),
            (self.atmosphere is None or self.atmosphere > 0, "atmosphere must be > 0 Pa"),
            (self.heat_model in ("natural", "adiabatic"),
             "heat_model must be 'natural' or 'adiabatic'"),
            (0.0 <= self.critical_ratio < 1.0, "critical_ratio must be in [0, 1)"),
            (self.signal_gain != 0 and math.isfinite(self.signal_gain),
             "signal_gain must be finite and non-zero"),
            (self.trigger_sigma > 0, "trigger_sigma must be > 0"),
            (self.min_plateau >= 4, "min_plateau must be >= 4 samples"),
        ]
        for ok, msg in checks:
            if not ok:
                raise EstimationError(msg)

    @property
    def gas(self) -> physics.Gas:
        """Gas properties."""
        return physics.Gas(gas_constant=self.gas_constant, gamma=self.gamma)


@dataclass
class UnloadResult:
    """One unload analysed by the unloading-time method (all SI; NaN when unknown).

    ``conductance`` is the paper's eq 39 value, always reported as it is;
    ``conductance_model`` removes its known bias by inverting the discharge model at the
    measured crossing (``final=False``), or comes from the full-curve fit once the unload has
    ended (``final=True``).
    """

    index: int
    status: str
    status_text: str
    t_start: float
    t_cross: float
    tau_exp: float
    tau_exp_std: float
    p10: float
    p_atm: float
    p_star: float
    initial_temperature: float
    volume: float
    conductance: float
    conductance_model: float
    conductance_model_std: float
    critical_ratio: float = math.nan
    critical_ratio_std: float = math.nan
    conductance_isentropic: float = math.nan
    quality: float = 0.0
    method: str = ""
    final: bool = False
    noise_std: float = math.nan
    i_start: int = -1
    i_cross: int = -1
    i_complete: int = -1
    t_complete: float = math.nan
    t_end: float = math.nan
    extra: dict[str, Any] = field(default_factory=dict)
    #: Start instant of the fitted discharge model [s] (final results; NaN otherwise).
    t_start_model: float = math.nan
    #: tau_exp of the fitted model, its p* crossing from its start [s]: uses the whole curve,
    #: so it is less noisy than ``tau_exp`` (the paper's measurement, which it never replaces).
    tau_exp_model: float = math.nan

    @property
    def bias(self) -> float:
        """Relative difference conductance/conductance_model - 1 [-]."""
        return self.conductance / self.conductance_model - 1.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (NaN mapped to None) with the CLI's key names."""
        d = asdict(self)
        out: dict[str, Any] = {}
        for k, v in d.items():
            if isinstance(v, float) and not math.isfinite(v):
                v = None
            out[k] = v
        return out


@dataclass(frozen=True)
class Diagnostic:
    """A state change or an input problem, for /diagnostics and logs.

    Attributes
    ----------
    level : str
        'ok', 'warn' or 'error'.
    state : str
        Estimator state after the event.
    message : str
        What happened, specifically.
    t : float
        Sample time [s] (NaN when the sample had no valid time).
    """

    level: str
    state: str
    message: str
    t: float
